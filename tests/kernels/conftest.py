"""A small body on the lattice with its stencils, for kernel tests."""

import numpy as np
import pytest

from softgrains.geometry import Disk, seed_points
from softgrains.grid.lattice import Lattice
from softgrains.grid.shape_functions import stencil_width
from softgrains.grid.stencils import body_stencils


def make_small_body(kind: int, radius: float = 0.3, h: float = 0.1):
    lat = Lattice.covering([0.0, 0.0], [1.0, 1.0], h)
    x, v0 = seed_points(Disk(np.array([0.5, 0.5]), radius), lat.domain_lower, h, 2)
    st = body_stencils(lat, kind, x)
    return lat, x, v0, st.box, st.nodes, st.N, st.dN, stencil_width(kind)


@pytest.fixture
def small_body():
    """Factory: small_body(kind) -> (lattice, x, v0, box, nodes, N, dN, s)."""
    return make_small_body

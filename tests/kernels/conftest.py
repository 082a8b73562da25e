"""A small body on the lattice with its stencils, for kernel tests."""

import numpy as np
import pytest

from softgrains.geometry import Disk, seed_points
from softgrains.grid.lattice import Lattice, NodeBox
from softgrains.grid.shape_functions import compute_stencils, stencil_width
from softgrains.grid.transfers import local_node_indices


def make_small_body(kind: int, radius: float = 0.3, h: float = 0.1):
    lat = Lattice.covering([0.0, 0.0], [1.0, 1.0], h)
    x, v0 = seed_points(Disk(np.array([0.5, 0.5]), radius), lat.domain_lower, h, 2)
    s = stencil_width(kind)
    n = len(x)
    base = np.empty((n, 2), dtype=np.int64)
    N = np.empty((n, s * s))
    dN = np.empty((n, s * s, 2))
    compute_stencils(x, lat.node_origin, lat.h, kind, base, N, dN)
    box = NodeBox.of_stencils(base, s)
    nodes = np.empty((n, s * s), dtype=np.int64)
    local_node_indices(base, box.lower, box.strides(), s, nodes)
    return lat, x, v0, box, nodes, N, dN, s


@pytest.fixture
def small_body():
    """Factory: small_body(kind) -> (lattice, x, v0, box, nodes, N, dN, s)."""
    return make_small_body

"""A body's stencils for one step: its node box and, per point, the local node indices,
N_I(x_p) and ∇N_I(x_p) (ALGORITHM.md §2). Shared by the implicit step and contact detection."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softgrains.errors import SimulationError
from softgrains.grid.clamps import reflect_ghost_nodes
from softgrains.grid.lattice import Lattice, NodeBox
from softgrains.grid.shape_functions import compute_stencils, stencil_width
from softgrains.grid.transfers import local_node_indices
from softgrains.threads import threads_for


@dataclass(frozen=True)
class BodyStencils:
    box: NodeBox
    nodes: np.ndarray  # (n, s^d) local node index in the box
    N: np.ndarray  # (n, s^d)
    dN: np.ndarray  # (n, s^d, d)


def body_stencils(lattice: Lattice, shape_kind: int, x: np.ndarray, body: str = "",
                  step: int = 0, clamps: np.ndarray | None = None) -> BodyStencils:
    """Stencils of points x; a point whose stencil leaves the lattice is a SimulationError.
    ``clamps``: the body's clamped faces (clamps.clamp_faces), whose ghost nodes the
    points' shape functions reflect (clamps.reflect_ghost_nodes)."""
    n, d = x.shape
    s = stencil_width(shape_kind)
    base = np.empty((n, d), dtype=np.int64)
    N = np.empty((n, s**d))
    dN = np.empty((n, s**d, d))
    with threads_for(n):
        compute_stencils(x, lattice.node_origin, lattice.h, shape_kind, base, N, dN)
    out = (base < 0) | (base + s > lattice.n_nodes)
    if out.any():
        p = int(np.argwhere(out.any(axis=1))[0, 0])
        raise SimulationError(
            f"step {step}: point {p} of body '{body}' at {x[p].tolist()} left the grid "
            f"[{lattice.domain_lower.tolist()}, {lattice.domain_upper.tolist()}]; enlarge "
            "[grid] size/origin or check the loading.", kind="grid", step=step, body=body,
            point=p)
    if clamps is not None and clamps.size:
        if reflect_ghost_nodes(x, lattice.node_origin, lattice.h, base, s, clamps, N, dN) < 0:
            raise AssertionError("a clamped face's ghost node has its mirror outside a stencil")
    box = NodeBox.of_stencils(base, s)
    nodes = np.empty((n, s**d), dtype=np.int64)
    with threads_for(n):
        local_node_indices(base, box.lower, box.strides(), s, nodes)
    return BodyStencils(box, nodes, N, dN)

"""Contact nodes and their normals from the bodies' own nodal fields (ALGORITHM.md §4).

Every body b has, on its node box of the common lattice,
    m_I^b = Σ_{p∈b} N_I(x_p) m_p,     g_I^b = Σ_{p∈b} m_p ∇N_I(x_p)   (outward from b).
A contact node is a lattice node where two bodies α < β both carry mass above a threshold
(a fraction of the body's heaviest point); one contact per body pair at a node, so three
bodies at a node give three contacts. The unit normal points from β into α:
    n = (g^β − g^α) / ‖g^β − g^α‖         ("difference", the default),
or from one body's gradient alone: n = −g^α/‖g^α‖ ("alpha") or g^β/‖g^β‖ ("beta").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from softgrains.geometry import Disk, Rectangle
from softgrains.grid.lattice import Lattice, NodeBox
from softgrains.grid.stencils import BodyStencils

CONTACT_MASS_FRACTION = 1e-4


@dataclass(frozen=True)
class NodalField:
    """One body's nodal mass and mass gradient on its node box (local node order)."""

    body: int
    box: NodeBox
    mass: np.ndarray  # (n_box,)
    gradient: np.ndarray  # (n_box, d)
    threshold: float


@dataclass(frozen=True)
class ContactNodes:
    """One row per (node, body pair): global node index, α, β, unit normal from β into α,
    and the local node index of that node in α's and in β's box. (A surface contact names
    the node nearest to its point or points, and its site.)"""

    node: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    normal: np.ndarray
    local_alpha: np.ndarray
    local_beta: np.ndarray
    # surface contacts (surfaces.py, patches.py): 2p (α's point p) or 2p + 1 (β's point p)
    # between grains, −2 for a patch against a wall; −1 at a node; None when every contact
    # is at a node
    site: np.ndarray | None = None
    position: np.ndarray | None = None  # (n, d) where each contact acts (None: its node)

    def __len__(self) -> int:
        return self.node.size


@njit(cache=True)
def _mass_and_gradient(nodes, N, dN, mass, m_I, g_I):
    n, ns = nodes.shape
    d = dN.shape[2]
    m_I[:] = 0.0
    g_I[:, :] = 0.0
    for p in range(n):
        for k in range(ns):
            I = nodes[p, k]
            m_I[I] += N[p, k] * mass[p]
            for j in range(d):
                g_I[I, j] += mass[p] * dN[p, k, j]


def nodal_field(body: int, stencils: BodyStencils, mass: np.ndarray) -> NodalField:
    """m_I and g_I of one body from its points' stencils and masses."""
    n_box = stencils.box.size
    m_I = np.empty(n_box)
    g_I = np.empty((n_box, stencils.dN.shape[2]))
    _mass_and_gradient(stencils.nodes, stencils.N, stencils.dN, mass, m_I, g_I)
    return NodalField(body, stencils.box, m_I, g_I, CONTACT_MASS_FRACTION * float(mass.max()))


def global_node_index(lattice: Lattice, box: NodeBox) -> np.ndarray:
    """Index on the common lattice (axis 0 fastest) of every node of a box, in local order."""
    d = lattice.dim
    local = np.arange(box.size)
    index = np.zeros(box.size, dtype=np.int64)
    stride = 1
    for j in range(d):
        index += (box.lower[j] + local % box.shape[j]) * stride
        local //= box.shape[j]
        stride *= int(lattice.n_nodes[j])
    return index


def node_position(lattice: Lattice, index: np.ndarray) -> np.ndarray:
    """Positions (n, d) of lattice nodes given by their global index."""
    pos = np.empty((index.size, lattice.dim))
    rem = index.copy()
    for j in range(lattice.dim):
        pos[:, j] = lattice.node_origin[j] + lattice.h * (rem % lattice.n_nodes[j])
        rem //= lattice.n_nodes[j]
    return pos


def wall_face_normal(shape, x: np.ndarray, hint: np.ndarray | None = None,
                     reach: float = 0.0) -> np.ndarray | None:
    """Outward unit normal of a rigid wall's shape at each point x.

    Rectangle: the face facing the other body. With ``hint`` (a direction from the wall
    towards the other body: minus that body's outward mass gradient), of the faces that x
    lies outside of or within ``reach`` behind (else of all faces), the one whose normal is
    closest to the hint, the nearer on a tie; without a usable hint, the nearest face. (At a
    corner node the nearest face may be a side the grain cannot touch: the top wall's end
    against a side wall, which gave the grain two opposite normals at one node and an
    unbounded pair of self-balancing impulses.) Disk: radial. Other shapes: None (the caller
    keeps the mass-gradient normal).
    """
    if isinstance(shape, Rectangle):
        lo, hi = np.asarray(shape.lower, float), np.asarray(shape.upper, float)
        d = x.shape[1]
        dist = np.concatenate([np.abs(x - lo), np.abs(x - hi)], axis=1)  # (n, 2d)
        face = np.argmin(dist, axis=1)
        if hint is not None:
            outside = np.concatenate([lo - x, x - hi], axis=1)  # signed distance out of face
            length = np.linalg.norm(hint, axis=1, keepdims=True)
            usable = np.isfinite(length[:, 0]) & (length[:, 0] > 0.0)
            unit = np.where(usable[:, None], hint / np.where(usable, length[:, 0], 1.0)[:, None],
                            0.0)
            dots = np.concatenate([-unit, unit], axis=1)  # n_face · hint, in [−1, 1]
            # faces the node is outside of (or within reach behind) first, then the best
            # match; the distance breaks ties
            scale = float(np.max(dist)) if dist.size else 1.0
            score = dots - 3.0 * (outside < -reach) - 1e-6 * dist / max(scale, 1e-300)
            face = np.where(usable, np.argmax(score, axis=1), face)
        normal = np.zeros_like(x)
        normal[np.arange(len(x)), face % d] = np.where(face < d, -1.0, 1.0)
        return normal
    if isinstance(shape, Disk):
        r = x - np.asarray(shape.center, float)
        return r / np.maximum(np.linalg.norm(r, axis=1, keepdims=True), 1e-300)
    return None


NORMALS = ("difference", "alpha", "beta")


@njit(cache=True)
def _pairs_within(starts, counts):
    """Every pair (a, b), a < b, of entries within each group of ``counts[g]`` entries from
    ``starts[g]``, group after group, in order of a, then b."""
    total = 0
    for g in range(starts.size):
        total += counts[g] * (counts[g] - 1) // 2
    a = np.empty(total, np.int64)
    b = np.empty(total, np.int64)
    at = 0
    for g in range(starts.size):
        for i in range(starts[g], starts[g] + counts[g]):
            for j in range(i + 1, starts[g] + counts[g]):
                a[at] = i
                b[at] = j
                at += 1
    return a, b


def find_contact_nodes(lattice: Lattice, fields: list[NodalField],
                       walls: dict | None = None, normal_kind: str = "difference"
                       ) -> ContactNodes:
    """All (node, α, β) with both bodies' mass above their thresholds, and their normals.

    ``walls`` maps the body index of a rigid (kinematic) body to its Shape: against a wall the
    wall is made β and the normal is its exact face normal (pointing out of the wall into α,
    ALGORITHM.md §4), not the mass-gradient estimate.
    """
    ids, bodies, locals_ = [], [], []
    for k, f in enumerate(fields):
        heavy = np.flatnonzero(f.mass > f.threshold)
        ids.append(global_node_index(lattice, f.box)[heavy])
        bodies.append(np.full(heavy.size, k))
        locals_.append(heavy)
    d = lattice.dim
    empty = ContactNodes(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64),
                         np.zeros((0, d)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    if not ids:
        return empty
    ids, bodies, locals_ = (np.concatenate(a) for a in (ids, bodies, locals_))
    order = np.lexsort((bodies, ids))
    ids, bodies, locals_ = ids[order], bodies[order], locals_[order]
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    counts = np.diff(np.r_[starts, ids.size])
    a, b = _pairs_within(starts[counts > 1], counts[counts > 1])
    if a.size == 0:
        return empty
    ka, kb = bodies[a], bodies[b]
    # every field's gradients in one array (field k's from offset[k])
    gradients = np.concatenate([f.gradient for f in fields])
    offset = np.cumsum([0] + [f.gradient.shape[0] for f in fields[:-1]])
    g_a, g_b = gradients[offset[ka] + locals_[a]], gradients[offset[kb] + locals_[b]]
    if normal_kind == "alpha":  # α's own outward gradient, reversed
        diff = -g_a
    elif normal_kind == "beta":  # β's own outward gradient
        diff = g_b
    else:
        diff = g_b - g_a
    length = np.linalg.norm(diff, axis=1)
    # no normal where the two gradients cancel (e.g. deep overlap): no contact there
    scale = np.maximum(np.linalg.norm(g_a, axis=1), np.linalg.norm(g_b, axis=1))
    keep = length > 1e-12 * scale
    a, b, ka, kb = a[keep], b[keep], ka[keep], kb[keep]
    normal = diff[keep] / length[keep, None]
    body_of = np.array([f.body for f in fields], dtype=np.int64)
    alpha, beta = body_of[ka], body_of[kb]
    local_a, local_b = locals_[a], locals_[b]
    grad_a, grad_b = g_a[keep], g_b[keep]
    for wall, shape in (walls or {}).items():
        swap = alpha == wall  # make the wall β
        alpha[swap], beta[swap] = beta[swap], wall
        local_a[swap], local_b[swap] = local_b[swap], local_a[swap].copy()
        grad_a[swap], grad_b[swap] = grad_b[swap], grad_a[swap].copy()
        normal[swap] *= -1.0
        at_wall = beta == wall
        # the face the grain lies against: the one facing −g^α (α's outward gradient); a
        # node with α's mass lies within the stencil support (≤ 1.5 h) of α's points
        exact = wall_face_normal(shape, node_position(lattice, ids[a][at_wall]),
                                 hint=-grad_a[at_wall], reach=2.0 * lattice.h)
        if exact is not None:
            normal[at_wall] = exact
    return ContactNodes(ids[a], alpha, beta, normal, local_a, local_b)

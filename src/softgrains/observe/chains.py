"""The contact force network (issue #13, item 3): one force per pair of bodies in contact.

The contact records (observe/contacts.contact_records: per contact node, the bodies α and
β, f_n, the status) are summed per pair of bodies over their nodes that press (f_n > 0):

    F_ab = Σ_{I ∈ ab} f_n,I,     x_ab = Σ f_n,I x_I / F_ab   (the pair's contact point),
    slip share = Σ_{I ∈ ab, slipping} f_n,I / F_ab,

forces per unit depth in 2D. A pair is drawn from centre to centre of its grains (to the
contact point for a wall), the grain centre being its points' volume-weighted mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softgrains.contact.local_law import SLIP


@dataclass(frozen=True)
class PairForces:
    """The pairs of one frame: body indices (k,) each, summed normal force F_ab (k,),
    contact point (k, d) and the share of F_ab carried by frictional slipping nodes (k,)."""

    alpha: np.ndarray
    beta: np.ndarray
    force: np.ndarray
    point: np.ndarray
    slip_share: np.ndarray


def pair_forces(alpha: np.ndarray, beta: np.ndarray, fn: np.ndarray, status: np.ndarray,
                position: np.ndarray, ft: np.ndarray | None = None) -> PairForces:
    """Sum per-node contact records into pair forces (see the module docstring); a pair
    is unordered (α, β and β, α are one pair). A pair presses when one of its nodes has
    f_n > 0 (the criterion of the coordination number, observe/compaction.py). A node
    counts as slipping when its status is slip and, if ``ft`` is given, it carries a
    tangential force (|f_t| > 10⁻⁹ f_n): without friction every node "slips"."""
    alpha, beta = np.asarray(alpha, np.int64), np.asarray(beta, np.int64)
    fn = np.asarray(fn, float)
    pressing = fn > 0.0
    low = np.minimum(alpha, beta)[pressing]
    high = np.maximum(alpha, beta)[pressing]
    f = fn[pressing]
    x = np.asarray(position, float)[pressing]
    slipping = np.asarray(status) == SLIP
    if ft is not None:
        slipping &= np.abs(np.asarray(ft, float)) > 1e-9 * np.abs(fn)
    slipping = slipping[pressing]
    d = x.shape[1] if x.ndim == 2 else 2
    if f.size == 0:
        none = np.zeros(0, np.int64)
        return PairForces(none, none, np.zeros(0), np.zeros((0, d)), np.zeros(0))
    pairs, which = np.unique(np.column_stack([low, high]), axis=0, return_inverse=True)
    which = which.ravel()
    force = np.bincount(which, f)
    point = np.column_stack([np.bincount(which, f * x[:, k]) for k in range(d)]) / force[:, None]
    share = np.bincount(which, f * slipping) / force
    return PairForces(pairs[:, 0], pairs[:, 1], force, point, share)


def body_centres(positions: np.ndarray, volume: np.ndarray, body: np.ndarray
                 ) -> dict[int, np.ndarray]:
    """Volume-weighted mean position of each body's points."""
    body = np.asarray(body, np.int64)
    weight = np.bincount(body, volume)
    sums = np.column_stack([np.bincount(body, volume * positions[:, k])
                            for k in range(positions.shape[1])])
    return {int(b): sums[b] / weight[b] for b in np.flatnonzero(weight > 0.0)}


def chain_segments(pairs: PairForces, centres: dict[int, np.ndarray], walls: set[int]
                   ) -> np.ndarray:
    """(k, 2, d) segment per pair: grain centre to grain centre, or grain centre to the
    contact point for a pair with a wall (a wall's centre is not where it pushes)."""
    segments = []
    for a, b, point in zip(pairs.alpha, pairs.beta, pairs.point, strict=True):
        a, b = int(a), int(b)
        if a in walls and b in walls:
            start = end = point
        elif a in walls:
            start, end = point, centres[b]
        elif b in walls:
            start, end = centres[a], point
        else:
            start, end = centres[a], centres[b]
        segments.append([start, end])
    d = pairs.point.shape[1]
    return np.asarray(segments, float).reshape(-1, 2, d)


def force_distribution(forces: np.ndarray, bins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P(f/⟨f⟩): the probability density of the forces normalised by their mean (pass
    forces already divided by their own frame's mean to pool frames: then ⟨f⟩ = 1), on
    ``bins`` (edges in units of ⟨f⟩), normalised by all the forces (those outside the
    bins included), so that it integrates to the share inside; returns (bin centres,
    density)."""
    forces = np.asarray(forces, float)
    if forces.size == 0:
        return 0.5 * (bins[1:] + bins[:-1]), np.zeros(len(bins) - 1)
    counts, _ = np.histogram(forces / forces.mean(), bins=bins)
    return 0.5 * (bins[1:] + bins[:-1]), counts / (forces.size * np.diff(bins))


@dataclass(frozen=True)
class ChainLines:
    """The force network as line cells for ParaView: segment end points (2k, d), the lines
    (k, 2) into them, and per line the pair's bodies, force and slip share."""

    points: np.ndarray
    lines: np.ndarray
    data: dict[str, np.ndarray]


def chain_lines(model, state, records: dict[str, np.ndarray]) -> ChainLines:
    """The chains of the current state from the contact records of a snapshot."""
    pairs = pair_forces(records["alpha"], records["beta"], records["fn"], records["status"],
                        records["position"], records["ft"])
    centres = body_centres(state.x, state.vol, model.body_id)
    walls = {b.index for b in model.bodies if not b.deformable}
    segments = chain_segments(pairs, centres, walls)
    return ChainLines(segments.reshape(-1, model.dim),
                      np.arange(2 * len(segments)).reshape(-1, 2),
                      {"alpha": pairs.alpha.astype(np.int32), "beta": pairs.beta.astype(np.int32),
                       "force": pairs.force, "slip_share": pairs.slip_share})

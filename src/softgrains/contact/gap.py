"""Boundary gap at contact nodes (ALGORITHM.md §4).

Mass overlap flags a contact node about one cell before the surfaces touch. At each contact
node X with normal n (from β into α), the boundaries of the two bodies along n are estimated
from their material points in a column through the node along n (within the stencil reach of
X and at most δ from the line X + s n, in the spirit of Nairn's separation check), each point
standing for a cell of side δ = h/n_pc, whose half-extent along n is e = ½δ‖n‖₁ for the
lattice's axis-aligned squares and e = ½δ for ring cells (aligned with the radius, i.e. with
n where two round bodies meet):
    s_α = min_{p∈α in column} (x_p·n) − e_α,     s_β = max_{p∈β in column} (x_p·n) + e_β,
    g = s_α − s_β  (< 0: an estimated overlap).
The column, not the whole ball around X, is what makes the gap right beside a curved
boundary: over a ball of radius r the minimum takes the surface at a lateral offset up to r,
x r / R lower at a distance x from the apex of a disk of radius R (a Hertz contact then
spread over the whole band where the bodies share nodes). A body with no point in the column
falls back to the ball. The contact law acts on w̃_n = w_n + g̃/Δt with
    g̃ = g if g ≥ 0,   g̃ = 0 if −t ≤ g < 0,   g̃ = r (g + t) if g < −t
(``effective_gaps``; r = contact.overlap_removal, t = contact.overlap_tolerance × h):
the bodies may close a gap, not cross it; an estimated overlap is clipped (r = 0) or, beyond
the tolerance t, removed by the fraction r per step (ALGORITHM.md §5: never in one step, so
that the correction cannot inject energy). The tolerance keeps the removal from acting on
the estimate's own scatter (a point entering or leaving the column moves g by a fraction of
δ from one step to the next).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from softgrains.contact.detection import ContactNodes, node_position
from softgrains.grid.lattice import Lattice


def boundary_gaps(lattice: Lattice, contacts: ContactNodes, points: dict[int, np.ndarray],
                  spacing: float, reach: float,
                  round_bodies: set[int] | frozenset = frozenset()) -> np.ndarray:
    """g per contact (signed); ``points`` maps body index → its point positions (start of
    step).

    ``reach``: radius around the node where points count (the stencil's reach);
    ``spacing``: the points' spacing δ, also the half-width of the column along n;
    ``round_bodies``: ring-seeded bodies, whose cells are aligned with the radius (along
    the contact normal): their half-extent along n is ½δ, not the lattice square's ½δ‖n‖₁.
    """
    gaps = np.zeros(len(contacts))
    if len(contacts) == 0:
        return gaps
    X = node_position(lattice, contacts.node)
    # each body's points near its own contact nodes only (not every body at every node)
    near_alpha, near_beta = [None] * len(contacts), [None] * len(contacts)
    for b in np.union1d(contacts.alpha, contacts.beta):
        tree = cKDTree(points[b])
        for side, near in ((contacts.alpha, near_alpha), (contacts.beta, near_beta)):
            mine = np.flatnonzero(side == b)
            if mine.size:
                for c, found in zip(mine, tree.query_ball_point(X[mine], reach), strict=True):
                    near[c] = found
    for c in range(len(contacts)):
        n = contacts.normal[c]
        square = 0.5 * spacing * np.abs(n).sum()
        xa = _column(points[contacts.alpha[c]], near_alpha[c], X[c], n, spacing)
        xb = _column(points[contacts.beta[c]], near_beta[c], X[c], n, spacing)
        if xa is None or xb is None:
            continue
        alpha, beta = contacts.alpha[c], contacts.beta[c]
        s_alpha = (xa @ n).min() - (0.5 * spacing if alpha in round_bodies else square)
        s_beta = (xb @ n).max() + (0.5 * spacing if beta in round_bodies else square)
        gaps[c] = s_alpha - s_beta
    return gaps


def effective_gaps(gaps: np.ndarray, removal: float, tolerance: float = 0.0) -> np.ndarray:
    """g̃: a gap as it is; an overlap (g < 0) clipped to 0 within the tolerance t ≥ 0 and,
    beyond it, its excess scaled by the removal fraction r ∈ [0, 1]."""
    excess = np.fmin(gaps + tolerance, 0.0)  # NaN → 0
    return np.where(gaps >= 0.0, gaps, removal * excess)


def _column(x: np.ndarray, near: list[int], node: np.ndarray, n: np.ndarray,
            width: float) -> np.ndarray | None:
    """Positions of the points in ``near`` whose distance to the line node + s n is at most
    ``width`` (all of ``near`` if none is; None if ``near`` is empty)."""
    if not near:
        return None
    xs = x[near]
    r = xs - node
    lateral = r - np.outer(r @ n, n)
    inside = np.einsum("ij,ij->i", lateral, lateral) <= width * width
    return xs[inside] if inside.any() else xs

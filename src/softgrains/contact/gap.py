"""Boundary gap at contact nodes (ALGORITHM.md §4).

Mass overlap flags a contact node about one cell before the surfaces touch. At each contact
node X with normal n (from β into α), the boundaries of the two bodies along n are estimated
from their material points near the node (within the stencil reach, in the spirit of Nairn's
separation check), each point standing for a square cell of side δ = h/n_pc:
    s_α = min_{p∈α near X} (x_p·n) − ½δ‖n‖₁,     s_β = max_{p∈β near X} (x_p·n) + ½δ‖n‖₁,
    g = max(0, s_α − s_β).
An estimated overlap (s_α < s_β) is clipped to g = 0 (never removed in one step). The
contact law then acts on w̃_n = w_n + g/Δt: the bodies may close the gap, not cross it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from softgrains.contact.detection import ContactNodes, node_position
from softgrains.grid.lattice import Lattice


def boundary_gaps(lattice: Lattice, contacts: ContactNodes, points: dict[int, np.ndarray],
                  spacing: float, reach: float) -> np.ndarray:
    """g ≥ 0 per contact; ``points`` maps body index → its point positions (start of step).

    ``reach``: radius around the node where points count (the stencil's reach).
    """
    gaps = np.zeros(len(contacts))
    if len(contacts) == 0:
        return gaps
    X = node_position(lattice, contacts.node)
    trees = {b: cKDTree(x) for b, x in points.items()}
    near = {b: trees[b].query_ball_point(X, reach) for b in trees}
    for c in range(len(contacts)):
        n = contacts.normal[c]
        half = 0.5 * spacing * np.abs(n).sum()
        pa = near[contacts.alpha[c]][c]
        pb = near[contacts.beta[c]][c]
        if not pa or not pb:
            continue
        s_alpha = (points[contacts.alpha[c]][pa] @ n).min() - half
        s_beta = (points[contacts.beta[c]][pb] @ n).max() + half
        gaps[c] = max(0.0, s_alpha - s_beta)
    return gaps

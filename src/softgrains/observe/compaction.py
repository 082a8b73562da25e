"""Observables of a sample compressed in a box (ALGORITHM.md §9).

With the inner box W × g (g: gap between the inner faces of the bottom and top walls),
A_box = W g, and the contact forces f_b each wall received over the step (compression
positive):
    φ = Σ_grains Σ_p V_p / A_box
    σ_yy = f_top,y / W,   σ_yy^bottom = −f_bottom,y / W,   σ_xx = (f_right,x − f_left,x) / (2 g)
(with friction on the side walls they carry part of the load: σ_yy^bottom < σ_yy, and the
averaged σ_yy is close to their mean rather than to the top wall's)
    σ^avg = −(1/A_box) Σ_grains Σ_p V_p σ_p        (Cauchy stress, tension positive)
φ_covered and the overlap fraction: the box area covered by grains (an overlap once) and the
area where two grains overlap, over A_box, from a raster of the points' cells (coverage.py).
Coordination over body pairs with at least one contact node with P_n > 0:
    Z = 2 N_gg / N_g,   Z_w = (2 N_gg + N_gw) / N_g,
rattlers: grains with fewer than 2 force-bearing contacts (grain or wall); Z* = 2 N_gg* / N_g*
over the other grains and the pairs between them.
"""

from __future__ import annotations

import numpy as np

from softgrains.observe.coverage import coverage

COMPACTION_COLUMNS = [
    "phase", "phi", "phi_covered", "overlap_fraction", "stress_yy", "stress_yy_bottom",
    "stress_xx", "stress_yy_avg", "stress_xx_avg", "stress_mean_avg", "wall_gap",
    "coordination", "coordination_walls", "coordination_no_rattlers", "rattler_fraction",
    "top_wall_velocity",
]


def inner_box(model, state, walls: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """Lower-left and upper-right corners of the box between the walls' inner faces (their
    current positions)."""
    def face(name: str, upper: bool) -> np.ndarray:
        body = model.bodies[walls[name]]
        corner = body.shape.upper if upper else body.shape.lower
        return np.asarray(corner, float) + state.body_offset[body.index]
    lower = np.array([face("wall_left", True)[0], face("wall_bottom", True)[1]])
    upper = np.array([face("wall_right", False)[0], face("wall_top", False)[1]])
    return lower, upper


def wall_gap(model, state, walls: dict[str, int]) -> float:
    """Gap between the inner faces of the bottom and top walls."""
    lower, upper = inner_box(model, state, walls)
    return float(upper[1] - lower[1])


def packing_coverage(model, state, walls: dict[str, int], grains: np.ndarray
                     ) -> dict[str, float]:
    """φ_covered and the overlap fraction of the grains' points (indices ``grains``)."""
    lower, upper = inner_box(model, state, walls)
    phi, overlap = coverage(state.x[grains], state.F[grains], model.reference_cells[grains],
                            model.body_id[grains], lower, upper)
    return {"phi_covered": phi, "overlap_fraction": overlap}


def box_stresses(model, state, walls: dict[str, int], grains: np.ndarray, width: float,
                 forces: np.ndarray) -> dict[str, float]:
    """φ, wall stresses and volume-averaged stress; ``grains``: their point indices."""
    gap = wall_gap(model, state, walls)
    area = width * gap
    vol = state.vol[grains]
    mean_sigma = -(vol[:, None, None] * state.sigma[grains]).sum(axis=0) / area
    f_top, f_bottom = forces[walls["wall_top"]], forces[walls["wall_bottom"]]
    f_left, f_right = forces[walls["wall_left"]], forces[walls["wall_right"]]
    return {
        "phi": float(vol.sum() / area),
        "stress_yy": float(f_top[1] / width),
        "stress_yy_bottom": float(-f_bottom[1] / width),
        "stress_xx": float((f_right[0] - f_left[0]) / (2.0 * gap)),
        "stress_yy_avg": float(mean_sigma[1, 1]),
        "stress_xx_avg": float(mean_sigma[0, 0]),
        "stress_mean_avg": float(0.5 * (mean_sigma[0, 0] + mean_sigma[1, 1])),
        "wall_gap": gap,
    }


def phi_at_stress_ratios(stress_ratio: np.ndarray, phi: np.ndarray, levels) -> np.ndarray:
    """φ where the compaction's σ_yy/σ0 (``stress_ratio``, in step order) first reaches each
    level: linear between the two rows about the crossing (the first row if it is already
    there), nan where it never does (C9's φ(σ) compared between runs)."""
    found = np.full(len(levels), np.nan)
    for j, level in enumerate(levels):
        above = np.flatnonzero(stress_ratio >= level)
        if not above.size:
            continue
        k = above[0]
        if k == 0:
            found[j] = phi[0]
            continue
        t = (level - stress_ratio[k - 1]) / (stress_ratio[k] - stress_ratio[k - 1])
        found[j] = phi[k - 1] + t * (phi[k] - phi[k - 1])
    return found


def coordination(contacts, is_grain: np.ndarray) -> dict[str, float]:
    """Z, Z_w, Z* and the rattler fraction from a step's ContactState."""
    return coordination_and_rattlers(contacts, is_grain)[0]


def bearing_pairs(contacts) -> set[tuple[int, int]]:
    """The body pairs (α, β) with at least one contact of normal impulse P·n > 0."""
    if contacts is None or len(contacts.nodes) == 0:
        return set()
    bearing = np.einsum("ij,ij->i", contacts.impulse, contacts.nodes.normal) > 0.0
    return {(int(a), int(b)) for a, b in zip(contacts.nodes.alpha[bearing],
                                             contacts.nodes.beta[bearing], strict=True)}


def coordination_and_rattlers(contacts, is_grain: np.ndarray) -> tuple[dict, np.ndarray]:
    """:func:`coordination` and the rattler mask over bodies."""
    n_grains = int(is_grain.sum())
    empty = {"coordination": 0.0, "coordination_walls": 0.0,
             "coordination_no_rattlers": 0.0, "rattler_fraction": 1.0 if n_grains else 0.0}
    if contacts is None or len(contacts.nodes) == 0 or n_grains == 0:
        return empty, is_grain.copy()
    pairs = bearing_pairs(contacts)
    gg = [(a, b) for a, b in pairs if is_grain[a] and is_grain[b]]
    gw = [(a, b) for a, b in pairs if is_grain[a] != is_grain[b]]
    count = np.zeros(is_grain.size, np.int64)
    for a, b in pairs:
        count[a] += 1
        count[b] += 1
    rattler = is_grain & (count < 2)
    kept = n_grains - int(rattler.sum())
    gg_kept = sum(1 for a, b in gg if not rattler[a] and not rattler[b])
    return {
        "coordination": 2.0 * len(gg) / n_grains,
        "coordination_walls": (2.0 * len(gg) + len(gw)) / n_grains,
        "coordination_no_rattlers": 2.0 * gg_kept / kept if kept else 0.0,
        "rattler_fraction": float(rattler.sum()) / n_grains,
    }, rattler

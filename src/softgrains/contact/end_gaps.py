"""The gaps of the point contacts in the configuration at the end of the step (issue #11).

The coupling loop holds each point contact's end-of-step gap through its linearisation,
    g_lin = g + Δt[(1 − θ) w_n^n + θ w_n^{n+1}],
with g, the normal and the rows taken at the start of the step. Over one step the true
gap differs from it at second order in the motion: the kernel surface of the other
grain curves and moves with its points, the normal turns, the cell's extent changes with
F. Those errors are 0.02–0.1 h at a few contacts a step in the dense compaction, and an
overlap that is not removed (removal off) keeps them: they add up, a ratchet (session 15,
``benchmarks/wall_gap_audit.py``). This module evaluates the gaps at the points' end
positions, with the same geometry as surfaces.py:

    x_p⁺ = x_p + Σ_I N_I(x_p) u_I,  F_p⁺ = (I + Σ_I u_I ⊗ ∇N_I(x_p)) F_p,  V_p⁺ = det(…) V_p,
    wall: g⁺ = d_wall⁺(x_p⁺) − e_p⁺ (the wall moved by Δt v_wall),
    grain pair: g⁺ = (d_T⁺(x_p⁺) − e_p⁺)/λ⁺ (T's kernel surface from T's moved points),

with u the bodies' current displacement (what G2P would apply); coupling.py corrects the
constraint by the difference g⁺ − g_lin and solves again.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from numba import njit

from softgrains.contact.surfaces import (
    KernelSurface,
    SurfaceContacts,
    edge_gap,
    shape_distance,
    surface_gaps,
)
from softgrains.geometry.shapes import translated


@njit(cache=True)
def _moved(x, F, vol, nodes, N, dN, active_row, u, x_out, F_out, vol_out):
    """x⁺ = x + Σ_k N_k u_k, G = I + Σ_k u_k ⊗ ∇N_k, F⁺ = G F, V⁺ = det(G) V per point
    (u_k the displacement at the stencil's active rows, 0 at inactive ones)."""
    n, ns = N.shape
    d = x.shape[1]
    G = np.empty((d, d))
    for p in range(n):
        for i in range(d):
            x_out[p, i] = x[p, i]
            for j in range(d):
                G[i, j] = 1.0 if i == j else 0.0
        for k in range(ns):
            row = active_row[nodes[p, k]]
            if row < 0:
                continue
            for i in range(d):
                x_out[p, i] += N[p, k] * u[row, i]
                for j in range(d):
                    G[i, j] += u[row, i] * dN[p, k, j]
        for i in range(d):
            for j in range(d):
                total = 0.0
                for m in range(d):
                    total += G[i, m] * F[p, m, j]
                F_out[p, i, j] = total
        if d == 2:
            det = G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0]
        else:
            det = (G[0, 0] * (G[1, 1] * G[2, 2] - G[1, 2] * G[2, 1])
                   - G[0, 1] * (G[1, 0] * G[2, 2] - G[1, 2] * G[2, 0])
                   + G[0, 2] * (G[1, 0] * G[2, 1] - G[1, 1] * G[2, 0]))
        vol_out[p] = vol[p] * det


def moved_points(step) -> SimpleNamespace:
    """A body's points as the step's current displacement u would leave them: x⁺, F⁺, V⁺
    (the G2P update of x, F and V, without the velocities)."""
    pts = step.pts
    x, F, vol = np.empty_like(pts.x), np.empty_like(pts.F), np.empty_like(pts.vol)
    _moved(pts.x, pts.F, pts.vol, step.nodes, step.N, step.dN, step.active_row, step.u,
           x, F, vol)
    return SimpleNamespace(x=x, F=F, vol=vol)


def end_gaps(sc: SurfaceContacts, steps: dict, walls: dict, spacing: float,
             dt: float) -> np.ndarray:
    """Each point contact's gap at the end of the step (see the module docstring); NaN
    where the point has left the other body's kernel reach."""
    moved = {b: moved_points(steps[b]) for b in set(sc.alpha.tolist()) | set(sc.beta.tolist())
             if b in steps}
    gap = np.full(len(sc.gap), np.nan)
    own = np.where(sc.owner_is_alpha, sc.alpha, sc.beta)
    other = np.where(sc.owner_is_alpha, sc.beta, sc.alpha)
    d = sc.position.shape[1]
    for t in sorted(set(other.tolist())):  # each surface once, over all points against it
        which = np.flatnonzero(other == t)
        x, F = np.empty((which.size, d)), np.empty((which.size, d, d))
        for o in set(own[which].tolist()):
            mine = own[which] == o
            x[mine] = moved[o].x[sc.point[which[mine]]]
            F[mine] = moved[o].F[sc.point[which[mine]]]
        if t in steps:  # T's kernel surface, from its moved points
            surface = KernelSurface(SimpleNamespace(pts=moved[t], stepper=steps[t].stepper))
            c, grad = surface.field(x)
            gap[which] = surface_gaps(c, grad, F, surface.radius, spacing)[2]
        else:  # a kinematic wall, moved by Δt v
            velocity, shape = walls[t]
            distance, n_out = shape_distance(translated(shape, dt * np.asarray(velocity)), x)
            gap[which] = edge_gap(distance, n_out, F, spacing, True)[0]
    return gap

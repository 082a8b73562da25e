"""Frictionless contact problems solved by a primal-dual interior point method.

Without friction (μ = 0 at every contact) the problem of problem.py reduces to its normal
components, x_c = P_c·n_c (P_t = 0) and y_c = w̃_n,c = w_n,c + b_c: the linear
complementarity problem

    y = M x + c,   x ≥ 0,   y ≥ 0,   x_c y_c = 0      (M = W_nn, PSD; c = q_n + b),

the optimality conditions of the convex QP min ½ xᵀM x + cᵀx over x ≥ 0. Where contact
sites outnumber the velocity modes they sample (the points of a flat face against a wall)
M is singular, and so are the active-set systems of the semismooth Newton, which then
stalls (a loaded site separating at 1e-4 of the velocity scale while the impulses are
exact to 3e-7: docs/dev-notes.md, #11 next step 1). The interior point follows the central
path x_c y_c = τ → 0 instead (Mehrotra's predictor–corrector, Wright 1997, "Primal-Dual
Interior-Point Methods", ch. 8 for LCPs): each iteration solves

    (M + X⁻¹Y) Δx = X⁻¹ s + r,   Δy = M Δx − r,   r = y − M x − c,
    s = σ τ e − X Y e (− ΔX_aff ΔY_aff e, the corrector's second-order term),

whose matrix is positive definite at every interior iterate however singular M is, and
it needs a number of iterations that hardly depends on M's conditioning. Each iterate is
measured as the impulses x_c where x_c > ρ_c y_c and 0 elsewhere (what the natural map's
local solve would keep), on the shared residual (problem.residual_norm).
Dimension-generic (only the normal components enter).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from softgrains.contact.problem import (
    ContactProblem,
    impulse_scale,
    normal_masses,
    residual_norm,
    to_global,
    to_local,
    velocity_scale,
)

ITERATIONS = 60  # each one sparse LU of the n × n matrix M + X⁻¹Y
STAGNATION = 10  # ... it stops after this many iterations without a better residual
BOUNDARY_FRACTION = 0.99  # the step goes this fraction of the way to x = 0 or y = 0


@dataclass
class InteriorPointResult:
    """The best impulses (n, d) found, its residual, the iterations (factorizations) and
    the residual after each."""

    impulse: np.ndarray
    residual: float
    iterations: int
    history: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class _Complementarity:
    """The LCP y = M x + c on the contacts some body can move (``movable``)."""

    M: sp.csc_matrix
    c: np.ndarray
    movable: np.ndarray


def _complementarity(problem: ContactProblem) -> _Complementarity:
    d = problem.dim
    frames = problem.frames()
    W = problem.delassus(frames).tocsr()[0::d, 0::d]  # the normal components, W_nn
    movable = W.diagonal() > 0.0
    c = to_local(frames, problem.free_velocity())[:, 0] + problem.bias
    return _Complementarity(W[movable][:, movable].tocsc(), c[movable], movable)


def interior_point(problem: ContactProblem, tolerance: float, floor: float = 0.0
                   ) -> InteriorPointResult:
    """Solve a frictionless problem (every μ = 0) to ``tolerance`` on the shared residual
    (with its impulse ``floor``), from the start x = the impulse scale, y = the velocity
    scale; stops after ITERATIONS, or STAGNATION without a better residual. Returns the
    best iterate (P = 0 where the problem has no scale: nothing approaches)."""
    if np.any(problem.mu > 0.0):
        raise ValueError("the interior point solves frictionless problems only (μ = 0)")
    n, d = problem.n_contacts, problem.dim
    lcp = _complementarity(problem)
    rho = normal_masses(problem)[lcp.movable]
    frames = problem.frames()

    def impulses(x, y):
        local = np.zeros((n, d))
        local[lcp.movable, 0] = np.where(x > rho * y, x, 0.0)
        return to_global(frames, local)

    P = np.zeros((n, d))
    best = InteriorPointResult(P, residual_norm(problem, P, floor=floor), 0)
    x0, y0 = impulse_scale(problem), velocity_scale(problem)
    if not (x0 > 0.0 and y0 > 0.0) or lcp.c.size == 0 or best.residual <= tolerance:
        return best
    x, y = np.full(lcp.c.size, x0), np.full(lcp.c.size, y0)
    best_at = 0
    for k in range(1, ITERATIONS + 1):
        step = _step(lcp, x, y)
        if step is None:
            break
        x, y = step
        P = impulses(x, y)
        residual = residual_norm(problem, P, floor=floor)
        best.history.append(residual)
        best.iterations = k
        if residual < best.residual:
            best.impulse, best.residual, best_at = P, residual, k
        if best.residual <= tolerance or k - best_at >= STAGNATION:
            break
    return best


def _step(lcp: _Complementarity, x: np.ndarray, y: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray] | None:
    """One predictor–corrector step from the interior iterate (x, y) > 0 (None where its
    matrix could not be factorised or the step is not finite)."""
    r = y - lcp.M @ x - lcp.c
    tau = float(x @ y) / x.size
    try:
        lu = spla.splu((lcp.M + sp.diags(y / x)).tocsc())
    except RuntimeError:  # (exactly singular: not for an interior iterate of a PSD M)
        return None

    def direction(s):
        dx = lu.solve(s / x + r)
        return dx, lcp.M @ dx - r

    dx_aff, dy_aff = direction(-x * y)
    alpha = min(1.0, _step_length(x, y, dx_aff, dy_aff))
    tau_aff = float((x + alpha * dx_aff) @ (y + alpha * dy_aff)) / x.size
    sigma = (tau_aff / tau) ** 3
    dx, dy = direction(sigma * tau - x * y - dx_aff * dy_aff)
    alpha = min(1.0, BOUNDARY_FRACTION * _step_length(x, y, dx, dy))
    x, y = x + alpha * dx, y + alpha * dy
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and alpha > 0.0):
        return None
    return x, y


def _step_length(x: np.ndarray, y: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> float:
    """The largest α with x + α dx ≥ 0 and y + α dy ≥ 0 (inf: none is bounded)."""
    alpha = np.inf
    for value, change in ((x, dx), (y, dy)):
        falling = change < 0.0
        if falling.any():
            alpha = min(alpha, float(np.min(-value[falling] / change[falling])))
    return alpha

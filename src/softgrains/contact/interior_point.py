"""Contact problems that are convex QPs, solved by a primal-dual interior point method.

Without friction (μ = 0 at every contact) the problem of problem.py reduces to its normal
components, x_c = P_c·n_c (P_t = 0) and y_c = w̃_n,c = w_n,c + b_c: the linear
complementarity problem

    y = M x + c,   x ≥ 0,   y ≥ 0,   x_c y_c = 0      (M = W_nn, PSD; c = q_n + b),

the optimality conditions of the convex QP min ½ xᵀM x + cᵀx over x ≥ 0. With a fixed
friction bound s_c (Tresca: ‖P_t‖ ≤ s_c, the subproblems of solvers' Tresca fixed point)
it is, in 2D, the QP min ½ rᵀW r + gᵀr over the box r_n ≥ 0, −s ≤ r_t ≤ s, in the
contacts' frames (g = q + b on the normals); in 3D the tangential set is a disk, not a
box, and this module does not solve it. Where contact sites outnumber the velocity modes
they sample (the points of a flat face against a wall) W is singular, and so are the
active-set systems of the semismooth Newton, which then stalls (a loaded site separating
at 1e-4 of the velocity scale while the impulses are exact to 3e-7: docs/dev-notes.md,
#11 next step 1). The interior point follows the central path (slack × multiplier = τ →
0, Mehrotra's predictor–corrector; Wright 1997, "Primal-Dual Interior-Point Methods",
ch. 8, 11) instead: with the slacks S_l = r − l, S_u = u − r of the bounds and their
multipliers z_l, z_u ≥ 0, each iteration solves

    (W + Z_l S_l⁻¹ + Z_u S_u⁻¹) Δr = −(W r + g − z_l + z_u) + S_l⁻¹ k_l − S_u⁻¹ k_u,
    Δz_l = S_l⁻¹ (k_l − Z_l Δr),   Δz_u = S_u⁻¹ (k_u + Z_u Δr),

k = σ τ e − S z (the corrector also − ΔS_aff Δz_aff), whose matrix is positive definite at
every interior iterate however singular W is; it needs a number of iterations that hardly
depends on W's conditioning (the frictionless case is the one without upper bounds, the
multipliers z_l being the velocities y). Each iterate is measured as its impulses with
the normal components x_c set to 0 where x_c ≤ ρ_c y_c (what the natural map's local
solve would keep), on the problem's own natural-map residual (Coulomb with μ = 0, as
problem.residual_norm; or Tresca's, as the semismooth Newton's of that law).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from softgrains.contact.alart_curnier import linearise
from softgrains.contact.problem import (
    ContactProblem,
    impulse_scale,
    natural_map_residual,
    normal_masses,
    relative_error,
    to_global,
    to_local,
    velocity_scale,
)

ITERATIONS = 60  # each one sparse LU of the matrix W + Z S⁻¹ on the free components
STAGNATION = 10  # ... it stops after this many iterations without a better residual
BOUNDARY_FRACTION = 0.99  # the step goes this fraction of the way to a bound
# a tangential component whose friction bound is below this fraction of the impulse scale
# is held at 0 (its box would be narrower than the round-off of the impulses; it leaves a
# residual up to ~this fraction: tolerances stay above it)
NARROWEST_BOX = 1e-10


@dataclass
class InteriorPointResult:
    """The best impulses (n, d) found, its residual, the iterations (factorizations) and
    the residual after each."""

    impulse: np.ndarray
    residual: float
    iterations: int
    history: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class _BoxQP:
    """min ½ rᵀW r + gᵀr over lower ≤ r ≤ upper on the ``free`` components of the
    contacts' flat local impulses (the others held at 0); every free component has a
    finite lower bound, those in ``boxed`` an upper one too."""

    W: sp.csc_matrix
    g: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    boxed: np.ndarray
    free: np.ndarray


def delassus_nonzeros(problem: ContactProblem) -> int:
    """d² Σ_s m_s² over the bodies s (m_s: the contacts touching s): W's nonzeros, a pair
    of contacts sharing both their bodies counted twice (within 10% on the dense
    compaction's problems). An iteration's LU grows with it, without assembling W."""
    _, slot, _, _ = problem.touches()
    per_body = np.bincount(slot).astype(np.int64)
    return problem.dim ** 2 * int(np.sum(per_body ** 2))


def _local_delassus(problem: ContactProblem) -> tuple[sp.csr_matrix, np.ndarray]:
    """W in the contacts' frames and g = q + b on the normals (flat local components),
    assembled once per problem (the Tresca fixed point poses many QPs on it)."""
    frames = problem.frames()
    g = to_local(frames, problem.free_velocity()).ravel()
    g[0::problem.dim] += problem.bias
    return problem.delassus(frames).tocsr(), g


def _box_qp(problem: ContactProblem, bound: np.ndarray) -> _BoxQP:
    """The QP of the problem with friction bound ``bound`` per contact (0: frictionless)."""
    d = problem.dim
    W, g = problem._cached("local_delassus", lambda: _local_delassus(problem))
    movable = W.diagonal()[0::d] > 0.0  # (W_cc,nn = 0: no body can move there)
    keep = np.zeros((problem.n_contacts, d), bool)
    keep[:, 0] = movable
    keep[:, 1:] = (movable & (bound > NARROWEST_BOX * impulse_scale(problem)))[:, None]
    free = np.flatnonzero(keep.ravel())
    lower = np.repeat(-bound, d).reshape(-1, d)
    lower[:, 0] = 0.0
    upper = np.repeat(bound, d).reshape(-1, d)
    upper[:, 0] = np.inf
    lower, upper = lower.ravel()[free], upper.ravel()[free]
    return _BoxQP(W[free][:, free].tocsc(), g[free], lower, upper, np.isfinite(upper), free)


def interior_point(problem: ContactProblem, tolerance: float, floor: float = 0.0,
                   bound: np.ndarray | None = None) -> InteriorPointResult:
    """Solve a frictionless problem (``bound`` None: every μ must be 0) or, in 2D, the
    Tresca problem of the friction bound ``bound`` (n,) to ``tolerance`` on its
    natural-map residual (with the impulse ``floor``), from the start r_n = the impulse
    scale, r_t = 0, multipliers = the velocity scale; stops after ITERATIONS, or
    STAGNATION without a better residual. Returns the best iterate (P = 0 where the
    problem has no scale: nothing approaches)."""
    n, d = problem.n_contacts, problem.dim
    frictionless = bound is None
    if frictionless:
        if np.any(problem.mu > 0.0):
            raise ValueError("without a friction bound the interior point solves "
                             "frictionless problems only (μ = 0)")
        bound = np.zeros(n)
    elif d != 2:
        raise ValueError("the interior point solves Tresca problems in 2D only (in 3D the "
                         "friction set is a disk, not a box)")
    qp = _box_qp(problem, np.asarray(bound, float))
    frames, rho = problem.frames(), normal_masses(problem)
    normal = qp.free % d == 0  # the free normal components, of the contacts:
    pressed = qp.free[normal] // d
    movable = np.zeros(n, bool)
    movable[pressed] = True

    def measure(r: np.ndarray) -> tuple[float, float, np.ndarray]:
        """The residual of r with its normals snapped (w̃_n = (W r + g)_n), the same over
        the contacts some body can move (what the iterations can change: their progress),
        and its P."""
        gap_rate = (qp.W @ r + qp.g)[normal]
        local = np.zeros(n * d)
        local[qp.free] = r
        local = local.reshape(n, d)
        local[pressed, 0] = np.where(r[normal] > rho[pressed] * gap_rate, r[normal], 0.0)
        P = to_global(frames, local)
        w = problem.velocities(P)
        if frictionless:  # the Coulomb residual every solver reports (also where no body
            phi = natural_map_residual(problem, P, w)  # can move a closing contact)
            reported = relative_error(problem, phi, P, w, floor)
            phi[~movable] = 0.0
            return reported, relative_error(problem, phi, P, w, floor), P
        phi = linearise(local, to_local(frames, w), problem.bias, problem.mu, rho, movable,
                        bound).phi  # (the Tresca residual, as the Newton's of that law,
        residual = relative_error(problem, phi, P, w, floor)  # zero where nothing moves)
        return residual, residual, P

    residual, progress, P = measure(np.zeros(qp.free.size))
    best, best_progress = InteriorPointResult(P, residual, 0), progress
    x0, y0 = impulse_scale(problem), velocity_scale(problem)
    if not (x0 > 0.0 and y0 > 0.0) or qp.free.size == 0 or progress <= tolerance:
        return best
    r = np.where(qp.boxed, 0.0, x0)  # (a box's middle)
    z_l, z_u = np.full(r.size, y0), np.where(qp.boxed, y0, 0.0)
    best_at = 0
    for k in range(1, ITERATIONS + 1):
        step = _step(qp, r, z_l, z_u)
        if step is None:
            break
        r, z_l, z_u = step
        residual, progress, P = measure(r)
        best.history.append(residual)
        best.iterations = k
        if progress < best_progress:  # (judged where the iterations act: a closing
            best.impulse, best.residual = P, residual  # contact no body can move holds
            best_progress, best_at = progress, k  # the reported residual)
        if best_progress <= tolerance or k - best_at >= STAGNATION:
            break
    return best


def _step(qp: _BoxQP, r: np.ndarray, z_l: np.ndarray, z_u: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """One predictor–corrector step from the interior iterate (None where its matrix could
    not be factorised, or the step is not finite or leaves no room to the bounds)."""
    boxed = qp.boxed
    s_l = r - qp.lower
    s_u = np.where(boxed, qp.upper - r, 1.0)
    if not (np.all(s_l > 0.0) and np.all(s_u > 0.0)):
        return None  # (the slacks' round-off: the bounds are reached)
    z_u_boxed = np.where(boxed, z_u, 0.0)
    pairs = np.concatenate((s_l * z_l, (s_u * z_u)[boxed]))
    tau = float(pairs.mean())
    dual = qp.W @ r + qp.g - z_l + z_u_boxed
    try:
        lu = spla.splu((qp.W + sp.diags(z_l / s_l + z_u_boxed / s_u)).tocsc())
    except RuntimeError:  # (exactly singular: not for an interior iterate of a PSD W)
        return None

    def direction(k_l, k_u):
        k_u = np.where(boxed, k_u, 0.0)
        dr = lu.solve(-dual + k_l / s_l - k_u / s_u)
        return dr, (k_l - z_l * dr) / s_l, np.where(boxed, (k_u + z_u * dr) / s_u, 0.0)

    aff = direction(-s_l * z_l, -s_u * z_u)
    alpha = min(1.0, _step_length(s_l, s_u, z_l, z_u, boxed, *aff))
    dr, dz_l, dz_u = aff
    tau_aff = float(np.concatenate(((s_l + alpha * dr) * (z_l + alpha * dz_l),
                                    ((s_u - alpha * dr) * (z_u + alpha * dz_u))[boxed])).mean())
    sigma = (tau_aff / tau) ** 3
    dr, dz_l, dz_u = direction(sigma * tau - s_l * z_l - dr * dz_l,
                               sigma * tau - s_u * z_u + dr * dz_u)
    alpha = min(1.0, BOUNDARY_FRACTION * _step_length(s_l, s_u, z_l, z_u, boxed,
                                                      dr, dz_l, dz_u))
    r, z_l, z_u = r + alpha * dr, z_l + alpha * dz_l, z_u + alpha * dz_u
    if not (alpha > 0.0 and np.all(np.isfinite(r)) and np.all(np.isfinite(z_l))
            and np.all(np.isfinite(z_u))):
        return None
    return r, z_l, z_u


def _step_length(s_l, s_u, z_l, z_u, boxed, dr, dz_l, dz_u) -> float:
    """The largest α with every slack and multiplier ≥ 0 after the step (inf: none is
    bounded); the upper slacks and multipliers count only where ``boxed``."""
    alpha = np.inf
    for value, change in ((s_l, dr), (s_u[boxed], -dr[boxed]), (z_l, dz_l),
                          (z_u[boxed], dz_u[boxed])):
        falling = change < 0.0
        if falling.any():
            alpha = min(alpha, float(np.min(-value[falling] / change[falling])))
    return alpha

"""Solvers of the frictional contact problem (problem.py) behind one interface.

    result = solve(problem, P0, ContactSolverOptions(method=..., tolerance=...))

Every solver stops on the shared natural-map residual (problem.residual_norm):
max_c ‖Φ_c‖ ≤ tolerance · max(max_c ‖P_c‖, the impulse scale of the free velocities).

- ``newton`` (default): semismooth Newton on the Alart–Curnier function, in each contact's
  frame (r = (r_n, r_t), w̃_n = w_n + b, ρ_c = 1/(n·W_cc n)):
      λ_n = r_n − ρ w̃_n,   Φ_n = r_n − max(0, λ_n)
      λ_t = r_t − ρ w_t,    Φ_t = r_t − proj_{‖·‖ ≤ μ max(0, λ_n)}(λ_t)
  with w = q + W r: the generalized Jacobian J = (I − G) + G ρ W (G: the derivative of the
  projections, block-diagonal) is solved with a sparse LU (kept, and updated by rows
  while G changes in few: newton_matrix.NewtonMatrix) and the step damped by a
  backtracking line search on ½‖Φ‖². Its convergence does not depend on the conditioning
  of W (a free grain between walls at Δt c/h ~ 10³ gives cond(W) ~ 10⁶, where Gauss–Seidel
  needs ~10⁶ sweeps); frictionless problems are solved in a finite number of steps (an
  active-set method; with redundant contacts — more sites than the velocity modes they
  sample, W singular — that can take 20–40 iterations whose best residual stalls for ten
  while the merit still falls: it stops only when ½‖Φ‖² has not fallen by 1% in
  STAGNATION_ITERATIONS). With friction it can stall or cycle (no global convergence for
  the non-associated Coulomb law): where ``options.tresca`` allows it (a symmetric PSD W)
  it gets FRICTIONAL_NEWTON_ITERATIONS, then the **Tresca fixed point** from its best
  iterate (or from its start, where that was better): the friction bound s = μ P_n held,
  the Tresca problem (monotone for a symmetric PSD W) solved by the same Newton, s
  updated with Anderson mixing; then the **proximal point** loop (W + εI, well posed where
  redundant sites make W singular), then (2D) the Tresca fixed point again with its
  Tresca problems solved by the **interior point** (interior_point.py: box QPs; session
  51), then up to NSGS_FALLBACK_SWEEPS Gauss–Seidel sweeps from the best iterate (on an
  indefinite W the sweeps come before the proximal point, as they all did before session
  26). Without friction on a PSD W the first fallback is the **interior point** (the
  convex QP's primal-dual path, whose systems stay definite where redundant sites make W
  singular and stall the Newton's active sets), then the sweeps, then the proximal
  point; the interior point only up to INTERIOR_POINT_NONZEROS. Every Newton starts from
  WARMUP_SWEEPS Gauss–Seidel sweeps where they improve the initial guess, and takes at
  least one iteration (a start within the tolerance is polished: its active set makes
  the solution exact, so a resting contact's warm start does not carry its error from
  step to step; ``nsgs`` has no such polish). The result's
  ``fallback_gain`` says what the fallbacks gained over the stalled Newton.
  Dimension-generic (the 3D cone's projection is exact).
- ``nsgs``: nonlinear Gauss–Seidel over contacts with the exact local solution
  (gauss_seidel.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from softgrains.contact.alart_curnier import linearise
from softgrains.contact.delassus import BlockRows, product
from softgrains.contact.gauss_seidel import gauss_seidel
from softgrains.contact.interior_point import delassus_nonzeros, interior_point
from softgrains.contact.local_law import OPEN, SLIP, STICK
from softgrains.contact.newton_matrix import NewtonMatrix
from softgrains.contact.problem import (
    ContactProblem,
    deformation_masses,
    normal_masses,
    relative_error,
    residual_norm,
    row_norms,
    to_global,
    to_local,
)

METHODS = ("newton", "nsgs")
LINE_SEARCH_HALVINGS = 12
# A line search that finds no decrease takes its shortest trial anyway in the Coulomb
# Newton (it has no global convergence; in the quasi-static D10 squeeze 2018 such steps
# raised the merit by a median 4e3 and up to 1e19, and stopping at them instead failed that
# test, the frictional squeeze's and the Hertz example: the loop stalls). In the
# fallbacks' Tresca and proximal-point Newtons, on problems that are monotone, it is taken
# only where it raises the merit by at most this factor: a near-singular J's step 1e5
# times the impulses raised it 1e11-fold on a sliding block's redundant wall sites (the
# B7 incline test at μ 0.2, session 32) and every stage after it failed; stopped there,
# the Tresca fixed point converges in 19 iterations
MERIT_INCREASE_TAKEN = 1e4
NSGS_FALLBACK_SWEEPS = 500  # Gauss–Seidel sweeps after a Newton solve that did not converge
STAGNATION_ITERATIONS = 30  # Newton stops when its merit has not decreased in this many
STAGNATION_DECREASE = 0.99  # ... iterations by at least this factor
# with friction (and a PSD W) the Coulomb Newton gets this many iterations before the
# Tresca fixed point (the solves of a dense compaction's later coupling iterations take 1-8)
FRICTIONAL_NEWTON_ITERATIONS = 15
# a stalled Newton is tried again on the contacts' deformation scale where some contact's
# deformation mass is this many times its normal mass (problem.deformation_masses)
RIGID_DOMINATED = 2.0
TRESCA_ITERATIONS = 60  # friction-bound updates of the Tresca fixed point (a stalled Newton)
TRESCA_TOLERANCE_FRACTION = 0.1  # each Tresca problem to this fraction of the tolerance
TRESCA_STAGNATION = 8  # ... and it stops after this many updates without a better residual
TRESCA_MIXING_DEPTH = 5  # bound updates the Anderson mixing remembers
ANDERSON_RCOND = 1e-10  # its least squares ignore directions below this relative size
PROXIMAL_ITERATIONS = 100  # outer iterations of the proximal-point fallback (a stalled Newton)
PROXIMAL_WEIGHT = 1e-3  # ε = this × the mean of W's diagonal (local frames)
PROXIMAL_STAGNATION = 15  # ... it stops after this many outer iterations without a new best
PROXIMAL_FAILED_INNER = 2  # ... or after this many regularised problems left unsolved
# Newton iterations (each a sparse LU) the fixed-point fallbacks of one solve may spend
# together: the Tresca fixed point of a dense frictional compaction step converges in
# 24–75 (session 24, 14 steps), the proximal point in 50–106 (session 14); a hopeless
# solve (a grain near inversion) took 957 + 100 (50 s) and ended worse than it started:
# the coupling loop does better moving on (a new iterate, another tangent, a shorter step)
FALLBACK_NEWTON_BUDGET = 200
# Gauss–Seidel sweeps before the Newton (session 26): a warm start far from the solution
# (the first solve of a dense compaction step, residual ~0.5 after the walls moved) cost
# the Coulomb Newton its 15 iterations without progress (line-search steps of 1e-4..0.5)
# and the Tresca fixed point 40-100 more; 20 sweeps (~30 ms on 2600 contacts) bring it to
# ~1e-2, from where the Newton meets the solve's tolerance in 2-15 iterations
WARMUP_SWEEPS = 20
# the interior point (a sparse LU of the whole problem each iteration) is tried on
# problems with up to this many nonzeros in W (interior_point.delassus_nonzeros, an
# estimate within 10% above the count): an iteration grew with them, 12–19 / 46–75 ms at
# 0.16 / 0.65 M estimated (the dense frictional example's 632 contacts at D/h 10, 1264 at
# D/h 20; session 51, beside one or two runs): ~0.25 s here, at most
# INTERIOR_POINT_BUDGET of them a solve. The 1000-grain front (43 000 contacts, ~10 M;
# its first solves fail every step, docs/dev-notes.md #14 item 2) keeps the stages it had
INTERIOR_POINT_NONZEROS = 2_000_000
# the interior-point iterations the Tresca fixed point on it may spend in one solve,
# beside FALLBACK_NEWTON_BUDGET (checked after each Tresca problem: up to ITERATIONS more);
# the frictional squeeze's 36 saved failures took 12-51, two 90 and 102 (session 51)
INTERIOR_POINT_BUDGET = 100
SWEEP_CHUNK = 10  # Gauss–Seidel sweeps between two evaluations of the residual
# the last fallback's sweeps (with friction) stop early after FALLBACK_PATIENCE evaluations
# none of which made progress (a residual below FALLBACK_PROGRESS × the last one that did),
# and return their best iterate (session 27:
# a dense frictional step near 245 σ0, 1867 contacts, two solves whose proximal point
# stopped at 7.2e-5 / 7.8e-5: their 500 sweeps from there, 0.5 s each, ended at 1.3e-4 /
# 1.2e-4)
FALLBACK_PATIENCE = 10
FALLBACK_PROGRESS = 0.95


@dataclass(frozen=True)
class ContactSolverOptions:
    """``method``: newton | nsgs; ``tolerance``: on the relative natural-map residual;
    ``max_iterations``: Newton iterations or Gauss–Seidel sweeps (with friction, ``tresca``
    and ``fallbacks`` the Coulomb Newton stops at FRICTIONAL_NEWTON_ITERATIONS, then the
    Tresca fixed point); ``floor``: an impulse below which the relative residual is
    measured against the floor instead; ``tresca``: whether a stalled Newton goes on with
    the Tresca fixed point (its Tresca problems are monotone only for a symmetric PSD W:
    not with an exact tangent under compression); ``fallbacks``: whether a stalled Newton
    goes on with any fallback at all (the caller can instead change an indefinite W);
    ``acceptable``: a residual the caller accepts although above ``tolerance`` (the coupling
    loop's own tolerance, while it asks each solve for a tenth of it): a stalled Newton or
    fallback that reaches it is returned (not converged) instead of going on to the next
    fallback; ``warmup``: Gauss–Seidel sweeps before the Newton (its start is the better of
    P0 and theirs; 0: none)."""

    method: str = "newton"
    tolerance: float = 1e-6
    max_iterations: int = 50
    floor: float = 0.0
    tresca: bool = True  # the Tresca fixed point as the first fallback (needs W symmetric PSD)
    fallbacks: bool = True  # after a stalled Newton (they presume a monotone problem)
    acceptable: float = 0.0
    warmup: int = WARMUP_SWEEPS
    # the Newtons' ρ_c: the contacts' deformation masses instead of their normal masses
    # (problem.deformation_masses; solve() tries it where the first solve stalls)
    deformation_scale: bool = False

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"contact solver method {self.method!r}: one of {METHODS}")


@dataclass
class ContactResult:
    """Impulses (n, d) on α, per-contact status, iterations (Newton iterations, or sweeps
    of the ``nsgs`` method and of a fallback, or interior-point iterations), residual,
    convergence; ``warmup``: the
    Gauss–Seidel sweeps before the Newton."""

    impulse: np.ndarray
    status: np.ndarray
    iterations: int
    residual: float
    converged: bool
    history: list[float] = field(default_factory=list)
    warmup: int = 0
    # where the fallbacks ran: the residual they ended at over the stalled Newton's
    # (1: they gained nothing); None where they did not run
    fallback_gain: float | None = None


def solve(problem: ContactProblem, P0: np.ndarray | None = None,
          options: ContactSolverOptions = ContactSolverOptions()) -> ContactResult:
    """Solve the contact problem from the initial guess P0 (default 0)."""
    P = np.zeros((problem.n_contacts, problem.dim)) if P0 is None else np.array(P0, float)
    if problem.n_contacts == 0:
        return ContactResult(P, np.zeros(0, np.int64), 0, 0.0, True)
    if options.method == "nsgs":
        return _nsgs(problem, P, options)
    # The Newton takes at least one iteration (polish), even from a start within the
    # tolerance: its active set makes the solution exact, where the warm-up sweeps or the
    # last step's impulses leave a complementarity error of the tolerance's size, e.g. an
    # energy gain of 1e-8 of a colliding disk's kinetic energy; and since a resting
    # contact's warm start is accepted step after step with an error of the same sign, a
    # frictionless disk resting on a slab crept into it by 7e-4 h per 1000 steps, spinning
    # slowly (session 52, benchmarks/long_rest_creep.py; with the polish: none measurable,
    # and the dense compaction's steps cost the same)
    warmup = _warmup(problem, P, options)
    if warmup is not None:
        P = warmup.impulse
    result = _newton_then_fallbacks(problem, P, options)
    if warmup is not None:
        result = replace(result, warmup=warmup.iterations,
                         history=warmup.history + result.history)
    if (_accepted(result, options) or not options.fallbacks or options.deformation_scale
            or not _rigid_dominated(problem)):
        return result
    # all of it again on the contacts' deformation scale (session 49: on every contact
    # problem of quasi-static squeezes of a free disk between frictional plates, the
    # stalled solves fell from 6 to 0 of 124 at D/h 10, from 3 to 1 of 177 at D/h 20, with
    # 6% and 14% more Newton iterations; with that scale alone 17 of the latter stalled)
    again = _newton_then_fallbacks(problem, P, replace(options, deformation_scale=True))
    gains = [g for g in (result.fallback_gain, again.fallback_gain) if g is not None]
    return replace(_better(result, again), fallback_gain=min(gains) if gains else None)


def _accepted(result: ContactResult, options: ContactSolverOptions) -> bool:
    """Converged, or at the residual the caller accepts (session 25: near 300 σ0 the
    frictional Newton stopped at its 15 iterations 2-6e-5 from the solution where the loop
    asked 1e-5 and accepts 5e-5, and the fallbacks then took 1-3 s a solve, 5-9 solves a
    step)."""
    return result.converged or result.residual <= options.acceptable


def _newton_then_fallbacks(problem: ContactProblem, P: np.ndarray,
                           options: ContactSolverOptions) -> ContactResult:
    """The semismooth Newton from P (at least one iteration: polished), and where it
    stalls the fallbacks."""
    frictional = options.tresca and options.fallbacks and bool(np.any(problem.mu > 0.0))
    result = _newton(problem, P, replace(options, max_iterations=min(
        options.max_iterations, FRICTIONAL_NEWTON_ITERATIONS)) if frictional else options,
        polish=True)
    if _accepted(result, options) or not options.fallbacks:
        return result
    final = _fallbacks(problem, P, result, options, frictional)
    return replace(final, fallback_gain=final.residual / result.residual)


def _rigid_dominated(problem: ContactProblem) -> bool:
    """Whether some contact's deformation mass exceeds its normal mass by more than
    RIGID_DOMINATED: its bodies' rigid modes of inertia alone carry most of its W_cc (a
    quasi-static step of a free body; in the dense frictional compaction ~25%)."""
    ratio = deformation_masses(problem) / normal_masses(problem)
    return bool(ratio.max(initial=0.0) > RIGID_DOMINATED)


def _fallbacks(problem: ContactProblem, P: np.ndarray, result: ContactResult,
               options: ContactSolverOptions, frictional: bool) -> ContactResult:
    """The fallbacks of a stalled Newton (``result``, started from P): with friction the
    Tresca fixed point, the proximal point, the Tresca fixed point on the interior point
    (2D), then patient Gauss–Seidel sweeps; without, the interior point (on a PSD W), the
    sweeps, then the proximal point. Returns the best iterate of all."""
    start = P  # where the fixed-point fallbacks start
    if frictional:
        # the Alart–Curnier Newton has no global convergence with Coulomb friction (dense
        # frictional compaction steps: 50 iterations wandering, then cycling at 0.05-0.4):
        # the Tresca problems are monotone on a PSD W. From the Coulomb Newton's best
        # iterate where it improved on the start (session 37: after the warm-up sweeps it
        # usually has, e.g. 0.40 -> 7e-3; on 86 saved dense frictional problems the
        # fallbacks' Newton iterations fell 2599 -> 2156, on seed 3's slow step 299 of the
        # README case 590 -> 302; before the warm-up existed it was no better a start)
        start = result.impulse if result.residual < residual_norm(
            problem, P, floor=options.floor) else P
        tresca = _tresca_fixed_point(problem, start, options, FALLBACK_NEWTON_BUDGET)
        result = _better(result, tresca)
        if result.converged or result.residual <= options.acceptable:
            return result
        budget = FALLBACK_NEWTON_BUDGET - tresca.iterations
    else:
        budget = FALLBACK_NEWTON_BUDGET
    # a (nearly) singular W — contact sites that outnumber the velocity modes they sample,
    # e.g. the points of a flat face against a wall — stalls the Newton: the proximal point
    # method solves a sequence of regularised problems W + εI, each well posed (from the
    # Tresca fixed point's start with friction, else from the initial guess: before the
    # warm-up sweeps existed, from a Newton's best iterate, where it may have been
    # cycling, the regularised Newton was seen to stall too); and Gauss–Seidel from the
    # best iterate (cheap sweeps; seen to converge in 540 sweeps on a frictional
    # compaction step whose Newton stalled at 3e-2). After a Tresca fixed point the
    # proximal point comes first (session 26: in a dense frictional step near 300 σ0,
    # 1620 contacts, four solves ran 500 sweeps each, 0.5–1.1 s, for 4.5–5.3e-4, and the
    # proximal point after them met the loop's tolerance anyway); without friction, where
    # no case was measured against it, the order stays as it was
    def proximal(best: ContactResult) -> ContactResult:
        if budget <= 0:
            return best
        return _better(best, _proximal_point(problem, start, options, budget))

    def sweeps(best: ContactResult) -> ContactResult:  # (the last stage with friction:
        # patient; without, where they come first, as they were: not measured)
        return _better(best, _sweeps(problem, best.impulse, options, NSGS_FALLBACK_SWEEPS,
                                     _Patience() if frictional else None))

    def interior(best: ContactResult) -> ContactResult:
        # (frictionless on a PSD W: an exact method for the convex QP, whose iterations
        # do not stall on a singular W as the Newton's active sets do; session 51)
        return _better(best, _interior_point(problem, options.tolerance, options.floor))

    def tresca_interior(best: ContactResult) -> ContactResult:
        # (2D: the Tresca problems are box QPs, solved by the interior point, whose systems
        # stay definite where redundant sites stall the Tresca Newton and the proximal
        # point ran out of budget; session 51: on the frictional quasi-static squeeze at
        # D/h 20 and 0.05 h a step, failed solves 26 -> 0, retried steps 3 -> 0. After the
        # proximal point, not before: on the frictional example it finished none of the
        # solves the proximal point finished, and the fallbacks took 3.0 s of a 60-s run
        # where it ran first, 1.1 s after, 0.55 s without it. Its own budget (the
        # Newton's is spent by then); from the fallbacks' start: from the best iterate so
        # far it was no better on 36 saved squeeze problems)
        return _better(best, _tresca_fixed_point(problem, start, options,
                                                 INTERIOR_POINT_BUDGET, interior=True))

    if frictional:
        stages = ((proximal, tresca_interior, sweeps)
                  if _tresca_interior_applies(problem, options) else (proximal, sweeps))
    elif _interior_point_applies(problem, options):
        stages = (interior, sweeps, proximal)
    else:
        stages = (sweeps, proximal)
    for stage in stages:
        result = stage(result)
        if result.converged or result.residual <= options.acceptable:
            break
    return result


def _interior_point(problem: ContactProblem, tolerance: float, floor: float,
                    bound: np.ndarray | None = None) -> ContactResult:
    """interior_point.py's solve of the frictionless problem (or of the Tresca problem of
    the friction ``bound``) as a ContactResult."""
    found = interior_point(problem, tolerance, floor, bound)
    return ContactResult(found.impulse, contact_status(problem, found.impulse),
                         found.iterations, found.residual, found.residual <= tolerance,
                         found.history)


def _interior_point_applies(problem: ContactProblem, options: ContactSolverOptions) -> bool:
    """Whether the problem is the convex QP the interior point solves: no friction, W
    PSD (``options.tresca``: the coupling loop's word for a symmetric PSD W); and
    :func:`_interior_point_worth_it`."""
    return (options.tresca and not np.any(problem.mu > 0.0)
            and _interior_point_worth_it(problem, options))


def _tresca_interior_applies(problem: ContactProblem, options: ContactSolverOptions) -> bool:
    """Whether the interior point solves the problem's Tresca problems: in 2D, where the
    friction set is an interval (a box QP; in 3D a disk); and
    :func:`_interior_point_worth_it`."""
    return problem.dim == 2 and _interior_point_worth_it(problem, options)


def _interior_point_worth_it(problem: ContactProblem, options: ContactSolverOptions) -> bool:
    """Small enough (INTERIOR_POINT_NONZEROS), and not the deformation-scale retry: ρ_c
    does not enter the interior point's systems (frictionless, the retry would get the
    first try's result again; with friction only its start would differ: a cost
    choice)."""
    return (not options.deformation_scale
            and delassus_nonzeros(problem) <= INTERIOR_POINT_NONZEROS)


def _sweeps(problem: ContactProblem, P: np.ndarray, options: ContactSolverOptions,
            count: int, patience: _Patience | None = None) -> ContactResult:
    """``count`` Gauss–Seidel sweeps from P (a copy) to ``options``' tolerance and floor
    (with ``patience``: fewer once they stop making progress, and their best iterate)."""
    return _nsgs(problem, P.copy(), ContactSolverOptions(
        "nsgs", options.tolerance, count, options.floor), patience)


@dataclass(frozen=True)
class _Patience:
    """Sweeps stop after ``evaluations`` residual evaluations in a row none of which is
    below ``progress`` × the residual of the last one that was (at first: the start's)."""

    evaluations: int = FALLBACK_PATIENCE
    progress: float = FALLBACK_PROGRESS


def _warmup(problem: ContactProblem, P: np.ndarray, options: ContactSolverOptions
            ) -> ContactResult | None:
    """``options.warmup`` Gauss–Seidel sweeps from P: their result where it is better than
    P (a lower residual), else None (e.g. diverging sweeps on an indefinite W)."""
    if options.warmup <= 0:
        return None
    sweeps = _sweeps(problem, P, options, options.warmup)
    start = residual_norm(problem, P, floor=options.floor)
    return sweeps if sweeps.residual < start else None


def _better(first: ContactResult, second: ContactResult) -> ContactResult:
    """The result with the smaller residual, with the iterations and history of both."""
    best = second if second.residual < first.residual else first
    return ContactResult(best.impulse, best.status, first.iterations + second.iterations,
                         best.residual, best.converged, first.history + second.history,
                         first.warmup + second.warmup)


def contact_status(problem: ContactProblem, P: np.ndarray) -> np.ndarray:
    """OPEN (no impulse), STICK (strictly inside the cone) or SLIP (on its boundary)."""
    r = to_local(problem.frames(), P)
    norm_t = row_norms(r[:, 1:])
    scale = max(float(np.abs(r).max()), 1e-300)
    status = np.where(norm_t < problem.mu * r[:, 0] * (1.0 - 1e-9), STICK, SLIP)
    return np.where(r[:, 0] <= 1e-14 * scale, OPEN, status).astype(np.int64)


# -- nonlinear Gauss–Seidel ---------------------------------------------------------------
def _nsgs(problem: ContactProblem, P: np.ndarray, options: ContactSolverOptions,
          patience: _Patience | None = None) -> ContactResult:
    """Sweeps from P (updated in place) until the tolerance or ``options.max_iterations``;
    with ``patience`` also until they stop making progress, returning their best iterate
    (else the last)."""
    V = problem.row_velocities(P)
    Q = np.zeros_like(V)
    status = np.zeros(problem.n_contacts, np.int64)
    history = []
    sweeps = 0
    residual = residual_norm(problem, P, floor=options.floor)
    best, best_P, anchor, idle = residual, P.copy() if patience else None, residual, 0
    while sweeps < options.max_iterations and residual > options.tolerance:
        n, _ = gauss_seidel(problem.a_slot, problem.a_col, problem.b_slot, problem.b_col,
                            problem.wall_va, problem.wall_vb, problem.normal, problem.bias,
                            problem.mu, problem.k_off, problem.w_off, problem.k_size, problem.W,
                            V, Q, P, status, 0.0, 0.0,
                            min(SWEEP_CHUNK, options.max_iterations - sweeps))
        sweeps += n
        with np.errstate(over="ignore", invalid="ignore"):
            residual = residual_norm(problem, P, problem.relative_velocities(V), options.floor)
        history.append(residual)
        if not np.isfinite(residual):  # diverged (an indefinite W): the caller keeps a
            residual = np.inf  # better one
            break
        if patience is None:
            continue
        if residual < patience.progress * anchor:  # progress: 5% below the last anchor
            anchor, idle = residual, 0
        else:
            idle += 1
        if residual < best:
            best, best_P = residual, P.copy()
        if idle >= patience.evaluations:
            break
    if patience is not None and best < residual:
        P, residual = best_P, best
    if residual == np.inf:
        return ContactResult(P, status, sweeps, np.inf, False, history)
    return ContactResult(P, contact_status(problem, P), sweeps, residual,
                         residual <= options.tolerance, history)


# -- semismooth Newton (Alart–Curnier: alart_curnier.py) ---------------------------------
@dataclass(frozen=True)
class _LocalOperator:
    """The problem in its contacts' frames: w = q + W r (flat, (contact, component))."""

    frames: np.ndarray
    blocks: BlockRows  # W by d × d block rows, built when asked for (delassus.py)
    q: np.ndarray
    rho: np.ndarray
    movable: np.ndarray  # contacts some body can move at (W_cc,nn > 0)


def _local_operator(problem: ContactProblem, deformation_scale: bool = False
                    ) -> _LocalOperator:
    """The operator with ρ_c = 1/W_cc,nn (normal_masses), or with ``deformation_scale``
    the contacts' deformation masses (problem.deformation_masses)."""
    def compute():
        frames = problem.frames()
        Wcc_nn = np.einsum("ci,cij,cj->c", problem.normal, problem.diagonal_blocks(),
                           problem.normal)
        blocks = problem.block_rows(frames)
        rho = deformation_masses(problem) if deformation_scale else normal_masses(problem)
        return _LocalOperator(frames, blocks, to_local(frames, problem.free_velocity()).ravel(),
                              rho, Wcc_nn > 0.0)
    return problem._cached(("local_operator", deformation_scale), compute)


@dataclass(frozen=True)
class _Proximal:
    """The proximal term of one outer iteration: w = q + W r + ε (r − r_k)."""

    epsilon: float
    centre: np.ndarray  # r_k, flat local impulses


def _newton(problem: ContactProblem, P: np.ndarray, options: ContactSolverOptions,
            threshold: np.ndarray | None = None, proximal: _Proximal | None = None,
            polish: bool = False) -> ContactResult:
    """Semismooth Newton on the Alart–Curnier function from P (Coulomb; with ``threshold``
    the Tresca problem of that fixed friction bound; with ``proximal`` the regularised
    problem w = q + (W + εI) r − ε r_k; in both cases the residual is its own Φ). With
    ``polish``, at least one iteration even from a P within the tolerance (one step on
    the start's active set makes the solution exact)."""
    n, d = problem.n_contacts, problem.dim
    deformation_scale = options.deformation_scale
    op = _local_operator(problem, deformation_scale)
    frames, movable, rho = op.frames, op.movable, op.rho
    q, shift = op.q, 0.0
    if proximal is not None:
        shift = proximal.epsilon
        q = q - shift * proximal.centre
    own_residual = threshold is not None or proximal is not None
    # how much a line search without a decrease may raise the merit with its shortest
    # trial, taken anyway: without bound in the Coulomb problem, bounded in the fallbacks'
    # Tresca and regularised problems (MERIT_INCREASE_TAKEN)
    increase_taken = MERIT_INCREASE_TAKEN if own_residual else np.inf
    # one per problem and shift: the Tresca and proximal-point fallbacks' many solves update
    # the same factorization
    jacobian = problem._cached(("newton_matrix", shift, deformation_scale),
                               lambda: NewtonMatrix(op.blocks, rho, shift))
    mu, bias = problem.mu, problem.bias
    r = to_local(frames, P).ravel()
    r[np.repeat(~movable, d)] = 0.0

    def evaluate(r, u=None):
        u = (q + product(op.blocks, r, shift)).reshape(n, d) if u is None else u
        return u, linearise(r.reshape(n, d), u, bias, mu, rho, movable, threshold)

    def measure(r, u, lin):
        P, w = to_global(frames, r.reshape(n, d)), to_global(frames, u)
        if own_residual:
            # (its own Φ, on the deformation scale too, where it weighs a velocity error by
            # ρ_c, up to 6e4 times the normal mass: stricter. Measured on the normal masses
            # instead, the retries at the frictional example's step 77 (seed 6, session 49)
            # returned iterates on which the loop took 11 iterations instead of 3)
            return relative_error(problem, lin.phi, P, w, options.floor)
        return residual_norm(problem, P, w, options.floor)

    u, lin = evaluate(r)
    merit = 0.5 * float(np.sum(lin.phi ** 2))
    history = []
    iterations = 0
    residual = measure(r, u, lin)
    history.append(residual)
    best = (residual, r, iterations)
    progress = (merit, iterations)  # the merit at its last real decrease
    while (((residual > options.tolerance and best[0] > options.tolerance)
            or (polish and iterations == 0))
           and iterations < options.max_iterations
           and iterations - progress[1] < STAGNATION_ITERATIONS):
        iterations += 1
        # J dr = −Φ, J = I − G + G ρ (W + shift I) (newton_matrix.py)
        dr = jacobian.solve(lin.G, -lin.phi.ravel())
        with np.errstate(over="ignore", invalid="ignore"):
            # w is affine in r: the trials need no product
            du = product(op.blocks, dr, shift).reshape(n, d)
        step, decreased = 1.0, False
        for _ in range(LINE_SEARCH_HALVINGS):
            r_try = r + step * dr
            with np.errstate(over="ignore", invalid="ignore"):  # a near-singular J's step
                u_try, lin_try = evaluate(r_try, u + step * du)
                merit_try = 0.5 * float(np.sum(lin_try.phi ** 2))
            if merit_try <= (1.0 - 1e-4 * step) * merit:  # False when not finite
                decreased = True
                break
            step *= 0.5
        if not decreased and not merit_try <= increase_taken * merit:
            break  # (also where not finite) the best iterate stands
        r = r_try  # its velocities without the trial's round-off (W dr may be huge along
        u, lin = evaluate(r)  # W's null directions)
        merit = 0.5 * float(np.sum(lin.phi ** 2))
        residual = measure(r, u, lin)
        history.append(residual)
        if residual < best[0]:
            best = (residual, r, iterations)
        if merit < STAGNATION_DECREASE * progress[0]:
            progress = (merit, iterations)
    # an indefinite W (a body's exact tangent under compression) can make the active set
    # cycle near the solution: the best iterate is returned
    residual, r = best[0], best[1]
    P = to_global(frames, r.reshape(n, d))
    return ContactResult(P, contact_status(problem, P), iterations, residual,
                         residual <= options.tolerance, history)


def _friction_bound(problem: ContactProblem, P: np.ndarray) -> np.ndarray:
    """s = μ max(0, P_n) per contact: the Tresca bound of Coulomb's law at impulses P."""
    return problem.mu * np.maximum(np.einsum("ci,ci->c", P, problem.normal), 0.0)


def _tresca_fixed_point(problem: ContactProblem, P: np.ndarray,
                        options: ContactSolverOptions, budget: int,
                        interior: bool = False) -> ContactResult:
    """Coulomb friction as a sequence of Tresca problems: the friction bound s of the
    current impulses held fixed, the problem (then monotone for a symmetric PSD W) solved
    by the semismooth Newton, s updated towards μ P_n(s) by Anderson mixing, until the
    Coulomb residual meets the tolerance (a fixed point s = μ P_n(s) solves the Coulomb
    problem). The plain update s ← μ P_n(s) was seen to cycle between two bounds on dense
    frictional compaction steps (residual 6e-2 ↔ 1e-1 for 40 updates); with the mixing the
    same problems reach 1e-5 in 12-15 updates. With ``interior`` (2D) the interior point
    solves each Tresca problem (a box QP) from its own start instead of the Newton from
    the last impulses. Starts from P; stops after ``budget`` Newton (or interior-point)
    iterations; returns its best iterate."""
    inner = replace(options, tolerance=TRESCA_TOLERANCE_FRACTION * options.tolerance)
    mixing = _AndersonMixing(TRESCA_MIXING_DEPTH)
    bound = None  # the friction bound of the last Tresca problem

    def tresca(P):
        nonlocal bound
        target = _friction_bound(problem, P)
        bound = target if bound is None else np.maximum(
            mixing.next(bound, target - bound), 0.0)
        if interior:
            return _interior_point(problem, inner.tolerance, inner.floor, bound)
        return _newton(problem, P, inner, threshold=bound)

    best = ContactResult(P, contact_status(problem, P), 0,
                         residual_norm(problem, P, floor=options.floor), False)
    return _fixed_point(problem, P, best, options, tresca, TRESCA_ITERATIONS,
                        TRESCA_STAGNATION, budget)


class _AndersonMixing:
    """Anderson acceleration of a fixed-point iteration x ↦ g(x) (type II, Walker & Ni
    2011): from the residuals f_j = g(x_j) − x_j of the last ``depth`` + 1 iterates,
        γ = argmin ‖f_k − ΔF γ‖,   x_{k+1} = x_k + f_k − (ΔX + ΔF) γ
    (ΔX, ΔF: differences of consecutive iterates and residuals); the first update is the
    plain one, x + f."""

    def __init__(self, depth: int):
        self.depth = depth
        self.x: list[np.ndarray] = []
        self.f: list[np.ndarray] = []

    def next(self, x: np.ndarray, f: np.ndarray) -> np.ndarray:
        self.x = (self.x + [x.copy()])[-(self.depth + 1):]
        self.f = (self.f + [f.copy()])[-(self.depth + 1):]
        if len(self.f) < 2:
            return x + f
        dX = np.diff(np.array(self.x), axis=0).T
        dF = np.diff(np.array(self.f), axis=0).T
        gamma = np.linalg.lstsq(dF, f, rcond=ANDERSON_RCOND)[0]
        return x + f - (dX + dF) @ gamma


def _proximal_point(problem: ContactProblem, P: np.ndarray,
                    options: ContactSolverOptions, budget: int) -> ContactResult:
    """The proximal point method: r_{k+1} solves the problem with w = q + W r + ε (r − r_k)
    (W + εI is positive definite for a PSD W, and well conditioned where W is singular:
    redundant contact sites), by the semismooth Newton; a fixed point r_{k+1} = r_k solves
    the original problem. ε = PROXIMAL_WEIGHT × mean diag W: small enough that each outer
    iteration moves far, large enough to fix the null directions. Measured on three
    problems of per-point wall contacts (2026-12-03; one is tests/contact/data/
    per_point_wall_sites.npz): 1e-6 in 50–106 Newton iterations in all (about 10–30 outer
    ones), where the Newton and 500 Gauss–Seidel sweeps stopped at 1e-4. Starts from P;
    stops after ``budget`` Newton iterations; returns its best iterate."""
    op = _local_operator(problem)
    epsilon = PROXIMAL_WEIGHT * float(np.einsum("cii->", problem.diagonal_blocks())
                                      ) / (problem.n_contacts * problem.dim)
    best = ContactResult(P, contact_status(problem, P), 0,
                         residual_norm(problem, P, floor=options.floor), False)
    if not epsilon > 0.0:
        return best
    inner = replace(options, tolerance=TRESCA_TOLERANCE_FRACTION * options.tolerance)

    def regularised(P):
        centre = to_local(op.frames, P).ravel()
        return _newton(problem, P, inner, proximal=_Proximal(epsilon, centre))

    # with friction the regularised Newton can cycle too: stop after a few such failures
    return _fixed_point(problem, P, best, options, regularised, PROXIMAL_ITERATIONS,
                        PROXIMAL_STAGNATION, budget, PROXIMAL_FAILED_INNER)


def _fixed_point(problem: ContactProblem, P: np.ndarray, best: ContactResult,
                 options: ContactSolverOptions, update, max_updates: int, stagnation: int,
                 budget: int, failures: int | None = None) -> ContactResult:
    """P ← update(P).impulse until the problem's residual meets the tolerance, or
    ``stagnation`` updates pass without a better residual than ``best``'s, or ``failures``
    updates are left unconverged (None: no limit), or the updates have spent ``budget``
    Newton iterations; returns the best iterate."""
    iterations, history, best_at, failed = 0, [], 0, 0
    for k in range(1, max_updates + 1):
        step = update(P)
        iterations += step.iterations
        failed += not step.converged
        if not np.all(np.isfinite(step.impulse)) or (failures is not None
                                                      and failed >= failures):
            break
        P = step.impulse
        residual = residual_norm(problem, P, floor=options.floor)
        history.append(residual)
        if residual < best.residual:
            best = ContactResult(P, step.status, iterations, residual,
                                 residual <= options.tolerance)
            best_at = k
        if (residual <= options.tolerance or k - best_at >= stagnation
                or iterations >= budget):
            break
    return replace(best, iterations=iterations, history=history)

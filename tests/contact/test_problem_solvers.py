"""The contact problem as data and its solvers, on small hand-made problems with known
solutions (CONTACT-SOLVER.md: tests at the problem level)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from softgrains.contact import solvers
from softgrains.contact.delassus import product
from softgrains.contact.local_law import OPEN, SLIP, STICK
from softgrains.contact.problem import (
    ContactProblem,
    contact_frames,
    natural_map_residual,
    project_to_cone,
    residual_norm,
)
from softgrains.contact.solvers import ContactSolverOptions, solve

METHODS = ["newton", "nsgs"]


def one_body_problem(W, q, normal, mu=0.0, bias=None):
    """n contacts between one deformable body (α, rows 0..n−1, compliance W (n d × n d))
    and a fixed wall: w = q + W P."""
    normal = np.atleast_2d(np.asarray(normal, float))
    n, d = normal.shape
    q = np.asarray(q, float).reshape(n, d)
    W = np.asarray(W, float)
    return ContactProblem(
        normal=normal, bias=np.zeros(n) if bias is None else np.asarray(bias, float),
        mu=np.full(n, float(mu)) if np.ndim(mu) == 0 else np.asarray(mu, float),
        a_slot=np.zeros(n, np.int64), a_col=np.arange(n, dtype=np.int64),
        b_slot=-np.ones(n, np.int64), b_col=np.zeros(n, np.int64),
        wall_va=np.zeros((n, d)), wall_vb=np.zeros((n, d)),
        k_off=np.zeros(1, np.int64), k_size=np.array([n], np.int64),
        w_off=np.zeros(1, np.int64), W=W.ravel().copy(), V_free=q.copy())


def _solve(problem, method, tolerance=1e-10, max_iterations=2000):
    return solve(problem, None, ContactSolverOptions(method=method, tolerance=tolerance,
                                                     max_iterations=max_iterations))


@pytest.mark.parametrize("method", METHODS)
def test_single_frictionless_contact_stops_the_approach(method):
    W = np.diag([0.5, 0.25])
    p = one_body_problem(W, [0.3, -2.0], [[0.0, 1.0]])
    res = _solve(p, method)
    assert res.converged
    assert res.impulse == pytest.approx(np.array([[0.0, 8.0]]), abs=1e-12)  # 2 / 0.25
    assert p.velocities(res.impulse)[0] == pytest.approx([0.3, 0.0], abs=1e-12)
    assert res.status[0] in (STICK, SLIP)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("q, expected", [([-1.0, -1.0], [1 / 3, 1 / 3]),
                                         ([-1.0, 1.0], [0.5, 0.0]),
                                         ([1.0, 1.0], [0.0, 0.0])])
def test_two_coupled_frictionless_contacts_solve_the_lcp(method, q, expected):
    """Normal compliance [[2, 1], [1, 2]]: the LCP w = q + W P ≥ 0, P ≥ 0, P·w = 0 has the
    solutions given (both closed, the second one open, both open)."""
    W = np.zeros((4, 4))
    W[np.ix_([1, 3], [1, 3])] = [[2.0, 1.0], [1.0, 2.0]]
    W[0, 0] = W[2, 2] = 1.0
    p = one_body_problem(W, [0.0, q[0], 0.0, q[1]], [[0.0, 1.0], [0.0, 1.0]])
    res = _solve(p, method)
    assert res.converged
    assert res.impulse[:, 1] == pytest.approx(expected, abs=1e-9)
    assert res.status[np.asarray(expected) == 0.0] == pytest.approx(OPEN)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("mu, expected_t, expected_status", [(1.0, -0.5, STICK),
                                                             (0.3, -0.3, SLIP)])
def test_friction_sticks_inside_the_cone_and_slips_on_it(method, mu, expected_t,
                                                         expected_status):
    n = np.array([[0.6, 0.8]])
    t = np.array([-0.8, 0.6])
    q = -1.0 * n[0] + 0.5 * t
    res = _solve(one_body_problem(np.eye(2), q, n, mu=mu), method)
    assert res.converged
    P = res.impulse[0]
    assert P @ n[0] == pytest.approx(1.0, abs=1e-9)
    assert P @ t == pytest.approx(expected_t, abs=1e-9)
    assert res.status[0] == expected_status


def test_coupled_normal_and_tangential_compliance_slip():
    """A full 2×2 block (normal–tangential coupling 0.5) in slip: with P = P_n (n − μ t),
    w_n = q_n + (W_nn − μ W_nt) P_n = 0 gives P_n = 1/(1 − 0.3·0.5) for q_n = −1."""
    W = np.array([[1.0, 0.5], [0.5, 1.0]])  # frame = axes: n = (1, 0), t = (0, 1)
    res = _solve(one_body_problem(W, [-1.0, 2.0], [[1.0, 0.0]], mu=0.3), "newton")
    pn = 1.0 / (1.0 - 0.3 * 0.5)
    assert res.impulse[0] == pytest.approx([pn, -0.3 * pn], rel=1e-10)
    assert res.status[0] == SLIP


def test_gap_bias_lets_the_bodies_close_the_gap_but_not_cross_it():
    p = one_body_problem(np.eye(2), [0.0, -3.0], [[0.0, 1.0]], bias=[1.0])
    res = _solve(p, "newton")
    assert p.velocities(res.impulse)[0, 1] + 1.0 == pytest.approx(0.0, abs=1e-12)
    p = one_body_problem(np.eye(2), [0.0, -0.5], [[0.0, 1.0]], bias=[1.0])
    assert np.all(_solve(p, "newton").impulse == 0.0)


@pytest.mark.parametrize("method", METHODS)
def test_three_dimensional_cone(method):
    """d = 3, W = I: slip along the trial tangential impulse with ‖P_t‖ = μ P_n."""
    n = np.array([[0.0, 0.0, 1.0]])
    q = np.array([0.6, 0.8, -1.0])
    res = _solve(one_body_problem(np.eye(3), q, n, mu=0.5), method)
    assert res.impulse[0] == pytest.approx([-0.3, -0.4, 1.0], abs=1e-9)
    assert res.status[0] == SLIP
    frames = contact_frames(np.array([[0.0, 0.6, 0.8], [1.0, 0.0, 0.0]]))
    assert np.einsum("cij,ckj->cik", frames, frames) == pytest.approx(np.stack([np.eye(3)] * 2))


def test_cone_projection():
    mu = np.array([0.5, 0.5, 0.5])
    r = np.array([[1.0, 0.2], [-1.0, 0.1], [1.0, 4.0]])
    proj = project_to_cone(r, mu)
    assert proj[0] == pytest.approx(r[0])  # inside
    assert proj[1] == pytest.approx([0.0, 0.0])  # polar cone → apex
    assert abs(proj[2, 1]) == pytest.approx(0.5 * proj[2, 0])  # on the boundary
    assert (r[2] - proj[2]) @ proj[2] == pytest.approx(0.0, abs=1e-12)  # orthogonal


def test_natural_map_residual_vanishes_only_at_the_solution():
    p = one_body_problem(np.eye(2), [0.0, -2.0], [[0.0, 1.0]], mu=0.2)
    assert residual_norm(p, np.array([[0.0, 2.0]])) == pytest.approx(0.0, abs=1e-14)
    assert residual_norm(p, np.array([[0.0, 1.0]])) > 0.1
    assert np.abs(natural_map_residual(p, np.array([[0.5, 2.0]]))).max() > 0.1  # outside K


def _ill_conditioned_problem(n=12, condition=1e6, seed=0):
    """n frictionless contacts of a body whose normal compliance has eigenvalues from
    1/condition to 1 (a free grain between walls at Δt c/h ~ 10³: rigid modes against
    local deformation), all pressed."""
    rng = np.random.default_rng(seed)
    Qm, _ = np.linalg.qr(rng.standard_normal((n, n)))
    Wn = Qm @ np.diag(np.geomspace(1.0 / condition, 1.0, n)) @ Qm.T
    W = np.zeros((2 * n, 2 * n))
    W[1::2, 1::2] = Wn
    W[0::2, 0::2] = np.eye(n)
    P_true = rng.uniform(0.5, 2.0, n)
    q = np.zeros((n, 2))
    q[:, 1] = -Wn @ P_true  # all contacts closed: w_n = 0 at P_true
    return one_body_problem(W, q, np.tile([0.0, 1.0], (n, 1))), P_true


def test_newton_solves_an_ill_conditioned_problem_that_gauss_seidel_cannot():
    """cond(W) = 10⁶: Newton in a few iterations; 2000 Gauss–Seidel sweeps leave a large
    error (the failure of issue 11 item 1: plates passing into a quasi-statically loaded
    disk while the impulse change per sweep looked small)."""
    p, P_true = _ill_conditioned_problem()
    newton = _solve(p, "newton", tolerance=1e-10)
    assert newton.converged and newton.iterations <= 10  # measured: 6
    assert newton.impulse[:, 1] == pytest.approx(P_true, rel=1e-6)
    nsgs = _solve(p, "nsgs", tolerance=1e-10, max_iterations=2000)
    assert not nsgs.converged
    assert np.abs(nsgs.impulse[:, 1] - P_true).max() > 1e-2 * P_true.max()


@pytest.mark.parametrize("seed", range(5))
def test_newton_and_gauss_seidel_agree_on_random_frictional_problems(seed):
    """Well-conditioned random SPD compliances, two bodies and a wall, μ = 0.4: both solvers
    reach the same impulses, and both satisfy the natural map."""
    rng = np.random.default_rng(seed)
    n = 6
    A = rng.standard_normal((2 * n, 2 * n))
    W = A @ A.T / (2 * n) + np.eye(2 * n)
    normal = rng.standard_normal((n, 2))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    q = rng.standard_normal((n, 2))
    p = one_body_problem(W, q, normal, mu=0.4)
    a = _solve(p, "newton", tolerance=1e-10)
    b = _solve(p, "nsgs", tolerance=1e-10, max_iterations=20000)
    assert a.converged and b.converged
    assert a.impulse == pytest.approx(b.impulse, abs=1e-7)


def test_a_problem_saved_to_a_file_replays_identically(tmp_path):
    p, _ = _ill_conditioned_problem(n=5, condition=1e3)
    p.mu[:] = 0.3
    path = tmp_path / "hard_step.npz"
    p.save(path)
    loaded = ContactProblem.load(path)
    assert _solve(loaded, "newton").impulse == pytest.approx(_solve(p, "newton").impulse,
                                                             abs=0.0)


def test_arrays_saved_beside_a_problem_leave_it_unchanged(tmp_path):
    """ContactProblem.save(path, **extra): a warm start (and solver options) stored beside
    the problem for the replay benchmark; load ignores them; a name of the problem's own
    arrays is refused."""
    p, _ = _ill_conditioned_problem(n=5, condition=1e3)
    path = tmp_path / "with_start.npz"
    start = np.full((p.n_contacts, p.dim), 0.25)
    p.save(path, warm_start=start, option_tolerance=np.asarray(1e-7))
    with np.load(path) as data:
        np.testing.assert_array_equal(data["warm_start"], start)
        assert data["option_tolerance"].item() == 1e-7
    loaded = ContactProblem.load(path)
    assert _solve(loaded, "newton").impulse == pytest.approx(_solve(p, "newton").impulse,
                                                             abs=0.0)
    with pytest.raises(ValueError, match="named like the problem"):
        p.save(tmp_path / "clash.npz", W=np.zeros(3))


DATA = Path(__file__).parent / "data"


def test_a_hard_problem_saved_from_a_real_run_is_solved_by_every_solver():
    """frictional_compaction_step28.npz: 292 contacts of the frictional compaction example
    (μ = 0.5, D/h 10) in its pre-compaction, saved by a run whose coupled loop failed there
    (2026-12-01). cond(W) ~ 10⁷. Measured: the Alart–Curnier Newton alone stalls at a
    residual of 3e-2 after 15 iterations; Gauss–Seidel converges in 540 sweeps; the default
    then (Newton, then Gauss–Seidel from its best iterate) in 15 + 80; since session 18
    Newton, then the Tresca fixed point."""
    problem = ContactProblem.load(DATA / "frictional_compaction_step28.npz")
    default = _solve(problem, "newton", tolerance=1e-6, max_iterations=50)
    nsgs = _solve(problem, "nsgs", tolerance=1e-6, max_iterations=5000)
    assert default.converged and nsgs.converged
    for result in (default, nsgs):
        assert residual_norm(problem, result.impulse) <= 1e-6
    scale = np.abs(nsgs.impulse).max()
    assert np.abs(default.impulse - nsgs.impulse).max() <= 1e-3 * scale


@pytest.mark.parametrize("mu", [0.0, 0.5, 1.0])
def test_redundant_surface_sites_at_a_quasi_static_step_are_solved(mu):
    """surface_sites_quasi_static.npz: 91 contacts of two frictional disks (μ = 0.5, D/h 20,
    B-splines) squeezed between plates at Δt c/h = 3000, point-to-surface contacts between
    the disks (benchmarks/grain_contact_stack.py, step 0, fourth coupling iteration;
    2026-12-02). The sites outnumber the velocity modes they sample: the Delassus matrix
    has eigenvalues from 1e-11 to 2. Measured before the fix (from zero, as here): the
    Newton, stopped after 6 iterations without a new best residual, left 0.044 / 0.25 /
    0.71 at μ = 0 / 0.5 / 1 and the 500 Gauss–Seidel sweeps after it 1.7e-2 / 4.7e-2 /
    4.9e-2; frictionless it needs 26 iterations; with friction it cycles (no global
    convergence), and the Tresca fixed point (the friction bound μ P_n held, updated)
    converges."""
    problem = ContactProblem.load(DATA / "surface_sites_quasi_static.npz")
    problem.mu = np.full_like(problem.mu, mu)
    eigenvalues = np.linalg.eigvalsh(problem.delassus().toarray())
    assert eigenvalues[0] < 1e-9 * eigenvalues[-1]  # (nearly) singular: redundant sites
    result = _solve(problem, "newton", tolerance=1e-5, max_iterations=50)
    assert result.converged
    assert residual_norm(problem, result.impulse) <= 1e-5
    pn = np.einsum("ci,ci->c", result.impulse, problem.normal)
    pt = np.linalg.norm(result.impulse - pn[:, None] * problem.normal, axis=1)
    # within the cone up to the solve's tolerance on the natural map
    assert pn.min() >= 0.0 and np.all(pt <= mu * pn + 1e-5 * pn.max())
    w = problem.velocities(result.impulse)
    gap_rate = np.einsum("ci,ci->c", w, problem.normal) + problem.bias
    scale = np.abs(problem.free_velocity()).max()
    assert gap_rate.min() >= -1e-4 * scale  # no contact closes past its gap


def _assert_signorini_coulomb(problem, P, cone, closing):
    """P_n ≥ 0, ‖P_t‖ ≤ μ P_n + cone × max P_n, and no contact closes faster than
    closing × the largest free velocity (w_n + b ≥ −that)."""
    pn = np.einsum("ci,ci->c", P, problem.normal)
    pt = np.linalg.norm(P - pn[:, None] * problem.normal, axis=1)
    assert pn.min() >= 0.0 and np.all(pt <= problem.mu * pn + cone * pn.max())
    gap_rate = np.einsum("ci,ci->c", problem.velocities(P), problem.normal) + problem.bias
    assert gap_rate.min() >= -closing * np.abs(problem.free_velocity()).max()


@pytest.mark.parametrize("tresca", [False, True])
def test_per_point_wall_sites_with_a_nearly_singular_W_are_solved(tresca, monkeypatch):
    """per_point_wall_sites.npz: 106 contacts of a disk sliding on a grain (μ = 1 on its 94
    point contacts against the kinematic floor, one site per boundary point, the force at the
    cell edge; μ = 0 between the grains), a coupling iteration whose solve stopped at 1e-4
    (tests/contact/test_relations.py's sliding disk with per-point wall sites, 2026-12-02).
    The sites outnumber the modes they sample: W's eigenvalues go from 9e-8 to 1.8.
    Measured (from zero): the Newton stalls at 9e-2, 500 Gauss–Seidel sweeps from there
    reach 5e-5; the proximal point loop (W + εI) converges. ``tresca``: the coupling loop
    allows the Tresca fallback only on a PSD W; it comes first, then the proximal loop
    and, only if that fails, the Gauss–Seidel sweeps (session 26: 500 sweeps cost 0.5–1.1 s
    on 1620 contacts of a dense compaction step and did not finish the solves the
    proximal point then finished); without it the sweeps come before the proximal loop."""
    problem = ContactProblem.load(DATA / "per_point_wall_sites.npz")
    eigenvalues = np.linalg.eigvalsh(problem.delassus().toarray())
    assert eigenvalues[0] < 1e-7 * eigenvalues[-1]
    options = ContactSolverOptions(tolerance=1e-6, max_iterations=50, tresca=tresca)
    sweeps = []
    nsgs = solvers._nsgs
    monkeypatch.setattr(solvers, "_nsgs", lambda problem, P, opts, patience=None: sweeps.append(
        opts.max_iterations) or nsgs(problem, P, opts, patience))
    result = solve(problem, None, options)
    assert result.converged and residual_norm(problem, result.impulse) <= 1e-6
    _assert_signorini_coulomb(problem, result.impulse, 1e-6, 1e-5)
    # with the Tresca fixed point, the proximal point came first and the sweeps never ran
    assert (solvers.NSGS_FALLBACK_SWEEPS in sweeps) == (not tresca)
    if not tresca:  # what the fallback is for: without it the solve stops short
        monkeypatch.setattr(solvers, "PROXIMAL_ITERATIONS", 0)
        assert not solve(problem, None, options).converged


def test_a_dense_frictional_cluster_is_solved_by_the_tresca_fixed_point():
    """dense_frictional_cluster.npz: 234 contacts among 8 grains and the walls of the
    frictional compaction example at 307 σ0 (μ = 0.5, D/h 10, 1691 contacts in all; the
    first solve of a step, from the previous step's impulses, stored as ``warm_start``):
    the contacts of 8 neighbouring grains, the impulses of the others at their solution
    (to 1e-9) folded into the free velocities; W and V_free rounded to single precision
    to keep the file small (2026-12-03). W is PSD, cond ~ 3e9. Measured: the Coulomb
    Newton wanders, then cycles at 0.14 after 47 iterations; 500 Gauss–Seidel sweeps stop
    at 2e-3; the chain before session 18 (then the proximal loop and the plain Tresca
    fixed point) took 677 iterations. The Tresca fixed point with Anderson mixing: 69."""
    path = DATA / "dense_frictional_cluster.npz"
    problem = ContactProblem.load(path)
    with np.load(path) as data:
        start = data["warm_start"]
    options = ContactSolverOptions(tolerance=1e-6, max_iterations=50)
    newton = solvers._newton(problem, start, options)
    assert not newton.converged and newton.residual > 1e-2  # what the fallback is for
    result = solve(problem, start, options)
    assert result.converged and residual_norm(problem, result.impulse) <= 1e-6
    assert result.iterations <= 100  # Newton iterations and sweeps in all
    _assert_signorini_coulomb(problem, result.impulse, 1e-6, 1e-5)


def test_the_fallbacks_of_a_solve_stop_at_their_newton_budget(monkeypatch):
    """The fixed-point fallbacks of one solve (Tresca, then the proximal point, then
    Gauss–Seidel) spend at most FALLBACK_NEWTON_BUDGET Newton iterations together, each a sparse
    LU (session 24: a dense frictional compaction step with a grain near inversion spent
    957 + 100 of them, 50 s, in a solve that ended worse than it started, against 24–75 for
    the Tresca fixed points that converge). The dense cluster, without warm-up sweeps and
    with one Coulomb Newton iteration before the fallbacks, needs 58 Tresca iterations (with
    the defaults the fixed point from the Coulomb Newton's 15th iterate takes 2): with the
    budget cut to 30 the Tresca fixed point stops unconverged after its update that passes
    30, Gauss–Seidel runs its sweeps and the proximal point is not started."""
    path = DATA / "dense_frictional_cluster.npz"
    problem = ContactProblem.load(path)
    with np.load(path) as data:
        start = data["warm_start"]
    options = ContactSolverOptions(tolerance=1e-6, max_iterations=50, warmup=0)
    monkeypatch.setattr(solvers, "FRICTIONAL_NEWTON_ITERATIONS", 1)
    monkeypatch.setattr(solvers, "FALLBACK_NEWTON_BUDGET", 30)
    proximal = []
    monkeypatch.setattr(solvers, "_proximal_point", lambda *a: proximal.append(a))
    result = solve(problem, start, options)
    assert not result.converged and not proximal
    newton = solvers.FRICTIONAL_NEWTON_ITERATIONS
    assert result.iterations <= newton + 30 + options.max_iterations + solvers.NSGS_FALLBACK_SWEEPS


def test_the_tresca_fixed_point_starts_from_the_coulomb_newtons_best_iterate(monkeypatch):
    """After the warm-up sweeps the Coulomb Newton's best iterate is usually much nearer the
    solution than the sweeps' impulses, and the Tresca fixed point converges faster from it
    (session 37: on 86 saved dense frictional problems the fallbacks' Newton iterations
    2599 → 2156; seed 3's slow step 299 of the README case 590 → 302). The dense cluster
    at 1e-6: the fixed point started from the Newton's iterate takes at most a third of
    the Newton iterations it takes from the sweeps' impulses, and the solve passes it that
    start and reports what the fallbacks gained."""
    path = DATA / "dense_frictional_cluster.npz"
    problem = ContactProblem.load(path)
    with np.load(path) as data:
        start = data["warm_start"]
    options = ContactSolverOptions(tolerance=1e-6)
    starts = []
    tresca = solvers._tresca_fixed_point

    def spy(problem, P, *args):
        starts.append(residual_norm(problem, P))
        return tresca(problem, P, *args)

    monkeypatch.setattr(solvers, "_tresca_fixed_point", spy)
    result = solve(problem, start, options)
    assert result.converged and result.fallback_gain is not None
    assert result.fallback_gain < 0.1  # the fixed point converged where the Newton stalled
    sweeps = solvers._warmup(problem, np.array(start, float), options)
    newton = solvers._newton(problem, sweeps.impulse, replace(
        options, max_iterations=solvers.FRICTIONAL_NEWTON_ITERATIONS), polish=True)
    assert not newton.converged and newton.residual < 0.1 * sweeps.residual
    assert starts == [pytest.approx(newton.residual)]
    budget = solvers.FALLBACK_NEWTON_BUDGET
    from_newton = tresca(problem, newton.impulse, options, budget)
    from_sweeps = tresca(problem, sweeps.impulse, options, budget)
    assert from_newton.converged and from_sweeps.converged
    assert 3 * from_newton.iterations <= from_sweeps.iterations


def test_a_stalled_newton_the_caller_accepts_skips_the_fallbacks(monkeypatch):
    """``acceptable``: the coupling loop asks each solve for a tenth of its own tolerance
    and accepts half of it (coupling.ACCEPTABLE_FRACTION); a stalled Newton (or fallback)
    within that is returned, not converged, instead of going on. Session 25 (frictional
    main job near 300 σ0, 2940 contacts, replayed from /tmp): the Coulomb Newton stopped
    at its 15 iterations 2–6e-5 from the solution where 1e-5 was asked, and the fallbacks
    took 0.9–2.4 s a solve for 9.98e-6–2.3e-5; accepted, 0.35 s; steps 279 / 282 took 12.2
    / 6.2 s instead of 18 / 36 s (the loop's iterations the same or fewer). Here the dense
    cluster, whose Newton cycles at 0.14: accepted at 0.2 the Tresca fixed point is not
    started; at 0 (the default) it is, and converges. (A Gauss–Seidel fallback stopped
    when its residual did not halve in 100 sweeps was tried and not kept: the D11 sliding
    block's loop then stalled at 1.44e-4 against its 1e-4 and was retried at Δt/2.)"""
    path = DATA / "dense_frictional_cluster.npz"
    problem = ContactProblem.load(path)
    with np.load(path) as data:
        start = data["warm_start"]
    calls = []
    tresca = solvers._tresca_fixed_point
    monkeypatch.setattr(solvers, "_tresca_fixed_point",
                        lambda *a: calls.append(1) or tresca(*a))
    accepted = solve(problem, start, ContactSolverOptions(tolerance=1e-6, acceptable=0.2))
    assert not calls and not accepted.converged
    assert accepted.residual <= 0.2
    assert accepted.iterations <= solvers.FRICTIONAL_NEWTON_ITERATIONS
    solved = solve(problem, start, ContactSolverOptions(tolerance=1e-6))
    assert calls and solved.converged


def test_gauss_seidel_sweeps_bring_a_far_warm_start_near_for_the_newton():
    """``warmup``: WARMUP_SWEEPS Gauss–Seidel sweeps before the Newton (session 26). The
    first solve of a dense compaction step starts from the previous step's impulses, far
    from the solution once the walls have moved (relative residual 0.2–0.9); the Newton
    then crawls (line-search steps of 1e-4–0.5) and, with friction, hands over to the
    Tresca fixed point. Measured on the two saved compaction problems (2026-12-04):
    step28 53 → 2 Newton iterations to 1e-6; the dense cluster 43 → 6 to the loose
    tolerance 5e-3 of a step's first solve (coupling.FORCING), 69 → 56 to 1e-6; since
    session 37 (the Tresca fixed point from the Coulomb Newton's best iterate) 32 → 2,
    35 → 6 and 43 → 17. At 1e-6 the same solution: the sweeps only move the start."""
    for name, tolerance, with_at_most in (
            ("frictional_compaction_step28", 1e-6, 5),
            ("dense_frictional_cluster", 5e-3, 10)):
        path = DATA / f"{name}.npz"
        problem = ContactProblem.load(path)
        with np.load(path) as data:
            start = data["warm_start"] if "warm_start" in data else None
        plain = solve(problem, start, ContactSolverOptions(tolerance=tolerance, warmup=0))
        warm = solve(problem, start, ContactSolverOptions(tolerance=tolerance))
        assert plain.converged and warm.converged
        assert warm.warmup == solvers.WARMUP_SWEEPS and plain.warmup == 0
        assert warm.iterations <= with_at_most and plain.iterations > 4 * warm.iterations
        assert residual_norm(problem, warm.impulse) <= tolerance
        if tolerance <= 1e-6:
            scale = np.abs(plain.impulse).max()
            assert np.abs(warm.impulse - plain.impulse).max() <= 1e-3 * scale


def test_a_warm_up_within_the_tolerance_is_made_exact_by_a_newton_step():
    """Sweeps that already meet the tolerance leave a complementarity error of its size
    (a colliding disk then gained 1e-8 of its kinetic energy: tests/contact/
    test_coupling.py); one Newton step on their active set makes the solution exact, and
    a solve never returns the sweeps alone."""
    n = 20  # a chain of frictionless contacts, each coupled to its neighbours
    W = np.eye(2 * n)
    for c in range(n - 1):
        W[2 * c, 2 * c + 2] = W[2 * c + 2, 2 * c] = 0.45
    normal = np.tile([1.0, 0.0], (n, 1))
    problem = one_body_problem(W, -normal, normal)
    sweeps = solvers._nsgs(problem, np.zeros((n, 2)), ContactSolverOptions(
        "nsgs", 5e-2, solvers.WARMUP_SWEEPS))
    assert sweeps.converged and sweeps.residual > 1e-6  # within 5e-2, not exact
    result = solve(problem, None, ContactSolverOptions(tolerance=5e-2))
    assert result.iterations >= 1 and result.warmup > 0
    assert residual_norm(problem, result.impulse) <= 1e-12


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_a_warm_start_within_the_tolerance_is_made_exact(mu):
    """A start already within the tolerance that the warm-up sweeps do not improve (the
    last step's impulses on a resting contact) is polished by a Newton step too: accepted
    as it was, its error kept its sign step after step, and a resting disk crept into a
    slab (session 52, test_relations.py)."""
    n = 20
    W = np.eye(2 * n)
    for c in range(n - 1):
        W[2 * c, 2 * c + 2] = W[2 * c + 2, 2 * c] = 0.45
    normal = np.tile([1.0, 0.0], (n, 1))
    problem = one_body_problem(W, -normal + [0.0, 0.1], normal, mu=mu)
    exact = solve(problem, None, ContactSolverOptions(tolerance=1e-14)).impulse
    start = exact * (1.0 + 1e-4)  # within the tolerance, not exact
    options = ContactSolverOptions(tolerance=1e-2, warmup=0)
    assert 1e-8 < residual_norm(problem, start) <= options.tolerance
    result = solve(problem, start, options)
    assert result.iterations == 1 and residual_norm(problem, result.impulse) <= 1e-12


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_fallback_sweeps_stop_when_they_stop_making_progress(mu):
    """The last fallback's NSGS_FALLBACK_SWEEPS = 500 sweeps stop after FALLBACK_PATIENCE
    residual evaluations without a 5% better best and return their best iterate (session
    27: after a stalled proximal point at 7.2e-5 a dense step's 500 sweeps took 0.5 s and
    ended at 1.3e-4). On the redundant quasi-static sites (W's eigenvalues 1e-11..2)
    Gauss–Seidel creeps: the patient sweeps stop before 200, and the full 500 are no
    solution either (measured: 130 / 140 sweeps at 4.9e-2 / 3.9e-2, the 500 at 3.1e-2 /
    4.7e-2, μ = 0 / 0.5)."""
    problem = ContactProblem.load(DATA / "surface_sites_quasi_static.npz")
    problem.mu = np.full_like(problem.mu, mu)
    options = ContactSolverOptions(tolerance=1e-5)
    start = np.zeros((problem.n_contacts, 2))
    plain = solvers._sweeps(problem, start, options, solvers.NSGS_FALLBACK_SWEEPS)
    patient = solvers._sweeps(problem, start, options, solvers.NSGS_FALLBACK_SWEEPS,
                              solvers._Patience())
    assert plain.iterations == solvers.NSGS_FALLBACK_SWEEPS and patient.iterations < 200
    assert patient.residual == min(patient.history)  # its best iterate
    assert residual_norm(problem, patient.impulse) == pytest.approx(patient.residual,
                                                                    rel=1e-6)
    assert min(plain.residual, patient.residual) > 1e3 * options.tolerance
    assert plain.residual > 0.5 * patient.residual


def test_sweeps_that_make_the_start_worse_are_dropped():
    """On an indefinite W (an exact tangent under compression) the sweeps can diverge: the
    Newton then starts from P0 as without them."""
    W = np.array([[1.0, 0.0, 1.5, 0.0], [0.0, 1.0, 0.0, 0.0],
                  [1.5, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])  # eigenvalue −0.5
    problem = one_body_problem(W, [[0.0, -1.0], [0.0, -1.0]], [[1.0, 0.0], [1.0, 0.0]])
    assert solvers._warmup(problem, np.zeros((2, 2)), ContactSolverOptions()) is None


def test_anderson_mixing_ends_the_cycle_of_a_linear_fixed_point_iteration():
    """x ↦ g(x) = B x + c with B's eigenvalues −1 (the plain iteration cycles between two
    points for ever, as the Tresca bounds did on dense frictional steps), 0.9 (it creeps)
    and 0.5: Anderson mixing of depth ≥ 3 on a linear map is GMRES on (I − B) x = c
    (Walker & Ni 2011) and lands on the fixed point in at most 4 updates; with depth 2 it
    keeps a sliding window of 3 iterates."""
    rng = np.random.default_rng(3)
    V = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    B = V @ np.diag([-1.0, 0.9, 0.5]) @ V.T
    c = rng.normal(size=3)
    fixed = np.linalg.solve(np.eye(3) - B, c)
    plain = np.zeros(3)
    for _ in range(50):
        plain = B @ plain + c
    assert np.linalg.norm(B @ plain + c - plain) > 0.05 * np.linalg.norm(fixed)  # cycling
    mixing = solvers._AndersonMixing(depth=5)
    x = np.zeros(3)
    for _ in range(4):
        x = mixing.next(x, B @ x + c - x)
    np.testing.assert_allclose(x, fixed, rtol=1e-9)
    # a shorter window than the problem needs: it slides (depth + 1 iterates kept) and
    # still converges (measured: 3e-10 after 15 updates with depth 2)
    mixing = solvers._AndersonMixing(depth=2)
    x = np.zeros(3)
    for _ in range(15):
        x = mixing.next(x, B @ x + c - x)
    assert len(mixing.x) == len(mixing.f) == 3
    np.testing.assert_allclose(x, fixed, rtol=1e-6)


@pytest.mark.parametrize("d", [2, 3])
def test_the_newton_matrix_on_the_engaged_rows_is_the_generalized_jacobian(d):
    """newton_matrix.engaged_jacobian against J = I − G + G ρ (W + εI) written out densely:
    J_EE and J_EO dr_O for a random block-sparse W (two contacts not coupled), random G
    blocks on the engaged contacts, one contact with only some components engaged."""
    from scipy import sparse

    from softgrains.contact.newton_matrix import engaged_jacobian

    rng = np.random.default_rng(7)
    n = 5
    pattern = np.ones((n, n), bool)
    pattern[0, 3] = pattern[3, 0] = False
    blocks = sparse.bsr_matrix(np.kron(pattern, np.ones((d, d))) * rng.normal(
        size=(n * d, n * d)), blocksize=(d, d))
    G = rng.normal(size=(n, d, d))
    G[1] = 0.0  # an open contact
    G[2, 1:] = 0.0  # only its normal row engaged
    rho, dr, shift = rng.uniform(0.5, 2.0, n), rng.normal(size=n * d), 0.3
    dense = (np.eye(n * d) - sparse.block_diag(list(G)).toarray()
             + sparse.block_diag(list(G * rho[:, None, None])).toarray()
             @ (blocks.toarray() + shift * np.eye(n * d)))
    engaged = np.flatnonzero(np.any(G.reshape(n * d, d) != 0.0, axis=1))
    other = np.setdiff1d(np.arange(n * d), engaged)
    J_ee, coupling = engaged_jacobian(blocks, G, rho, engaged, dr, shift)
    np.testing.assert_allclose(J_ee.toarray(), dense[np.ix_(engaged, engaged)], atol=1e-12)
    np.testing.assert_allclose(coupling, dense[np.ix_(engaged, other)] @ dr[other],
                               atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("dissected", [False, True])
def test_newton_steps_by_row_updates_of_a_kept_factorization_solve_the_jacobian(
        d, dissected, monkeypatch):
    """newton_matrix.NewtonMatrix: a sequence of Newton matrices J = I − G + G ρ (W + εI)
    of one problem whose G changes in a few rows (contacts opening, closing, changing
    between stick and slip) is solved on one factorization by the Woodbury identity, to
    round-off against the dense solve; past UPDATE_ROWS changed rows it factorises anew;
    a singular J_EE gets the least-squares step of the engaged rows. With J_EE's rows in
    SuperLU's order and in nested-dissection order (a large problem's, ordering.py)."""
    from scipy import sparse

    from softgrains.contact import newton_matrix
    from softgrains.contact.newton_matrix import NewtonMatrix

    monkeypatch.setattr(newton_matrix, "DISSECTION_ROWS", 0 if dissected else 10**9)

    rng = np.random.default_rng(11)
    n = 12
    A = rng.normal(size=(n * d, n * d))
    blocks = sparse.bsr_matrix(A @ A.T / (n * d) + np.eye(n * d), blocksize=(d, d))
    rho, shift = rng.uniform(0.5, 2.0, n), 0.1

    def dense(G):
        return (np.eye(n * d) - sparse.block_diag(list(G)).toarray()
                + sparse.block_diag(list(G * rho[:, None, None])).toarray()
                @ (blocks.toarray() + shift * np.eye(n * d)))

    G = np.zeros((n, d, d))
    G[: n // 2] = np.eye(d)  # half the contacts sticking, the others open
    solver = NewtonMatrix(blocks, rho, shift)
    for change in range(6):
        if change == 1:
            assert solver.base.dissected == dissected
        b = rng.normal(size=n * d)
        dr = solver.solve(G, b)
        np.testing.assert_allclose(dense(G) @ dr, b, atol=1e-10 * np.abs(b).max())
        c = change  # the next matrix: one contact changes its status (open, stick, slip)
        G = G.copy()
        G[c] = [np.zeros((d, d)), np.eye(d), rng.normal(size=(d, d))][change % 3]
        if change % 3 == 1 and c < n // 2:
            G[c] = rng.normal(size=(d, d))
    assert solver.factorizations == 1 and solver.updates == 5
    # an update whose residual check fails is replaced by a factorization
    monkeypatch.setattr(newton_matrix, "UPDATE_RESIDUAL", 0.0)
    G = G.copy()
    G[n - 1] = np.eye(d)
    b = rng.normal(size=n * d)
    np.testing.assert_allclose(dense(G) @ solver.solve(G, b), b, atol=1e-10 * np.abs(b).max())
    assert solver.factorizations == 2 and solver.updates == 5
    monkeypatch.setattr(newton_matrix, "UPDATE_RESIDUAL", 1e-9)
    monkeypatch.setattr(newton_matrix, "UPDATE_ROWS", d)  # more rows changed: factorised
    G[: n // 2] = 0.0
    G[n // 2:] = np.eye(d)
    b = rng.normal(size=n * d)
    np.testing.assert_allclose(dense(G) @ solver.solve(G, b), b, atol=1e-10 * np.abs(b).max())
    assert solver.factorizations == 3
    # a singular J_EE: two identical contacts (W's rows equal), both sticking
    twin = sparse.bsr_matrix(np.kron(np.ones((2, 2)), np.eye(d)), blocksize=(d, d))
    G2 = np.broadcast_to(np.eye(d), (2, d, d)).copy()
    b = np.r_[np.ones(d), np.ones(d)]
    dr = NewtonMatrix(twin, np.ones(2)).solve(G2, b)  # consistent: W dr = b
    assert np.all(np.isfinite(dr))
    np.testing.assert_allclose(twin.toarray() @ dr, b, atol=1e-6)


@pytest.mark.parametrize("d", [2, 3])
def test_assembled_delassus_is_the_map_from_impulses_to_velocities(d):
    """W (delassus.py, in global axes and in the contact frames) against its definition,
    the columns w(e_j) − w(0) of the problem's own velocity map: three bodies, two contacts
    between the same two bodies (their coupling summed over both), one body touched from
    both sides, one contact against a wall."""
    rng = np.random.default_rng(4)
    #            α slot, col   β slot, col
    touches = [((0, 0), (1, 0)), ((0, 1), (1, 1)), ((2, 0), (1, 2)), ((2, 1), (-1, 0))]
    n = len(touches)
    k = np.array([2, 3, 2], np.int64)
    blocks = [(lambda a: a @ a.T)(rng.normal(size=(ki * d, ki * d))) for ki in k]
    normal = rng.normal(size=(n, d))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    problem = ContactProblem(
        normal=normal, bias=np.zeros(n), mu=np.zeros(n),
        a_slot=np.array([a[0] for a, _ in touches], np.int64),
        a_col=np.array([a[1] for a, _ in touches], np.int64),
        b_slot=np.array([b[0] for _, b in touches], np.int64),
        b_col=np.array([b[1] for _, b in touches], np.int64),
        wall_va=np.zeros((n, d)), wall_vb=rng.normal(size=(n, d)),
        k_off=np.r_[0, np.cumsum(k)[:-1]].astype(np.int64), k_size=k,
        w_off=np.r_[0, np.cumsum([b.size for b in blocks])[:-1]].astype(np.int64),
        W=np.concatenate([b.ravel() for b in blocks]), V_free=rng.normal(size=(k.sum(), d)))
    base = problem.velocities(np.zeros((n, d))).ravel()
    expected = np.column_stack([problem.velocities(np.eye(n * d)[j].reshape(n, d)).ravel()
                                - base for j in range(n * d)])
    np.testing.assert_allclose(problem.delassus().toarray(), expected, atol=1e-12 * abs(
        expected).max())
    R = problem.frames()
    T = np.zeros((n * d, n * d))
    for c in range(n):
        T[c * d:(c + 1) * d, c * d:(c + 1) * d] = R[c]
    np.testing.assert_allclose(problem.delassus(R).toarray(), T @ expected @ T.T,
                               atol=1e-12 * abs(expected).max())
    # its product, with a shift on the diagonal (the proximal point's W + εI)
    x = rng.normal(size=n * d)
    np.testing.assert_allclose(product(problem.delassus(R), x, 0.3),
                               (T @ expected @ T.T + 0.3 * np.eye(n * d)) @ x,
                               atol=1e-12 * abs(expected).max() * abs(x).max())
    # by block rows built when asked for, in any order: the same rows, only those
    lazy = problem.block_rows(R)
    assembled = problem.delassus(R)
    lazy.ensure(np.array([3, 1, 3]))
    assert lazy.built.tolist() == [False, True, False, True]
    lazy.ensure(np.array([0, 2]))
    for c in range(n):
        row = slice(assembled.indptr[c], assembled.indptr[c + 1])
        np.testing.assert_array_equal(lazy.indices[lazy.start[c]:lazy.end[c]],
                                      assembled.indices[row])
        np.testing.assert_array_equal(lazy.data[lazy.start[c]:lazy.end[c]],
                                      assembled.data[row])
    x[2 * d:3 * d] = 0.0  # a contact without impulse: its row is not read
    fresh = problem.block_rows(R)
    np.testing.assert_allclose(product(fresh, x), T @ expected @ T.T @ x,
                               atol=1e-12 * abs(expected).max() * abs(x).max())
    assert not fresh.built[2] and fresh.built[[0, 1, 3]].all()


@pytest.mark.parametrize("d", [2, 3])
def test_rows_with_a_nonzero_or_changed_entry_are_found_as_numpy_finds_them(d):
    """delassus.nonzero_rows / differing_rows (the impulses a product reads, a Newton
    matrix's engaged and changed rows) against np.any over the short axis, NaN included."""
    from softgrains.contact.delassus import differing_rows, nonzero_rows

    rng = np.random.default_rng(3)
    G = rng.normal(size=(500, d, d))
    G[rng.uniform(size=500) < 0.6] = 0.0  # open contacts: zero blocks
    G[7, 1, 0] = np.nan
    H = G.copy()
    H[::9, 0, d - 1] += 1.0
    rows = G.reshape(-1, d)
    np.testing.assert_array_equal(nonzero_rows(G, d), np.any(rows != 0.0, axis=1))
    np.testing.assert_array_equal(differing_rows(G, H, d),
                                  np.any(rows != H.reshape(-1, d), axis=1))
    # an array against itself: only the row holding the NaN differs (NaN ≠ NaN)
    assert np.flatnonzero(differing_rows(H, H, d)).tolist() == [7 * d + 1]


@pytest.mark.parametrize("d", [2, 3])
def test_contact_frames_rotate_to_local_components_and_back(d):
    """problem.to_local / to_global: x_local = R_c x, x = R_cᵀ x_local with the contact
    frames (rows n, t…; orthonormal): the normal component is n·x, the tangential ones
    keep |x_t|, and the round trip returns x (to round-off)."""
    from softgrains.contact.problem import to_global, to_local

    rng = np.random.default_rng(6)
    normal = rng.normal(size=(400, d))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    frames = contact_frames(normal)
    x = rng.normal(size=(400, d))
    local = to_local(frames, x)
    np.testing.assert_allclose(local, np.einsum("cij,cj->ci", frames, x), rtol=0, atol=1e-15)
    np.testing.assert_allclose(local[:, 0], np.einsum("ci,ci->c", normal, x), atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(local[:, 1:], axis=1), np.linalg.norm(
        x - local[:, :1] * normal, axis=1), atol=1e-14)
    np.testing.assert_allclose(to_global(frames, local), x, rtol=0, atol=1e-14)


@pytest.mark.parametrize("d", [2, 3])
def test_row_norms_equal_numpys_to_the_bit(d):
    """problem.row_norms (the residual measures' per-contact norms) is
    np.linalg.norm(x, axis=1) exactly, also on a strided view (the tangential components)."""
    from softgrains.contact.problem import row_norms

    x = np.random.default_rng(4).normal(size=(1000, d)) * np.logspace(-12, 12, 1000)[:, None]
    for view in (x, x[:, 1:], x[::3]):
        np.testing.assert_array_equal(row_norms(view), np.linalg.norm(view, axis=1))


@pytest.mark.parametrize("d", [2, 3])
def test_the_delassus_product_reads_the_rows_of_the_nonzero_impulses(d):
    """delassus.product of a symmetric block-sparse W (contacts sharing bodies) with
    impulses that are zero at most contacts, as in a large problem, equals the dense
    product, with and without a diagonal shift; a problem whose compliances are not
    symmetric is refused where it is made (every solver reads W's rows for its columns)."""
    from scipy import sparse

    rng = np.random.default_rng(8)
    n = 300
    pattern = sparse.random(n, n, density=0.03, random_state=5)
    pattern = ((pattern + pattern.T + sparse.identity(n)) != 0).toarray()
    A = np.kron(pattern, np.ones((d, d))) * rng.normal(size=(n * d, n * d))
    blocks = sparse.bsr_matrix(A + A.T, blocksize=(d, d))
    x = rng.normal(size=(n, d))
    x[rng.uniform(size=n) > 0.1] = 0.0  # one contact in ten carries an impulse
    for shift in (0.0, 0.7):
        expected = (blocks.toarray() + shift * np.eye(n * d)) @ x.ravel()
        np.testing.assert_allclose(product(blocks, x.ravel(), shift), expected, rtol=1e-13,
                                   atol=1e-13 * abs(expected).max())
    with pytest.raises(ValueError, match="symmetric"):
        one_body_problem(np.triu(np.ones((2 * d, 2 * d))), np.zeros(2 * d),
                         np.tile(np.eye(d)[0], (2, 1)))


def saved_problem(name: str | Path) -> tuple[ContactProblem, np.ndarray, ContactSolverOptions]:
    """A problem saved with its warm start and solver options (contact_problems_from_run;
    a file name (str) in tests/contact/data, or a Path)."""
    path = name if isinstance(name, Path) else DATA / name
    with np.load(path) as data:
        start = data["warm_start"]
        saved = {f: data[f"option_{f}"].item() for f in
                 ("tolerance", "max_iterations", "floor", "tresca", "fallbacks", "acceptable",
                  "warmup")}
    return ContactProblem.load(path), start, ContactSolverOptions(**saved)


def test_a_stalled_solve_is_tried_again_on_the_contacts_deformation_scale(monkeypatch):
    """rigid_dominated_squeeze.npz: 25 contacts of the quasi-static frictional squeeze (a
    free disk between μ = 0.5 plates, D/h 10, Δt c/h 3000, stress_form = "momentum"; a
    coupling iteration of step 5, session 49), with its warm start and the loop's options
    (tolerance 7e-3). The disk's rigid modes of inertia alone carry all but ~2e-5 of each
    W_cc (problem.rigid), so ρ_c = 1/W_cc,nn is its inertia, not the contacts' stiffness:
    on that scale the Newton and its fallbacks stall at 1.3e-2 after 247 iterations
    (measured). solve() then does it all again on the deformation scale
    (problem.deformation_masses, here 3e4–6e4 × the normal masses): 1.7e-9 (measured).
    Since session 51 the Tresca problems' interior point (2D, a fallback of the first try)
    solves it on the normal masses already, its systems not depending on ρ_c: it is held
    off here to test the retry, which is what a 3D problem has."""
    from softgrains.contact.problem import deformation_masses, normal_masses

    monkeypatch.setattr(solvers, "_tresca_interior_applies",
                        lambda problem, options: False)
    problem, start, options = saved_problem("rigid_dominated_squeeze.npz")
    ratio = deformation_masses(problem) / normal_masses(problem)
    assert ratio.min() > 1e3  # the rigid modes carry all but < 1e-3 of every W_cc
    result = solve(problem, start, options)
    assert result.converged and residual_norm(problem, result.impulse) <= options.tolerance
    _assert_signorini_coulomb(problem, result.impulse, 1e-6, 1e-2)
    monkeypatch.setattr(solvers, "_rigid_dominated", lambda problem: False)
    stalled = solve(ContactProblem.load(DATA / "rigid_dominated_squeeze.npz"), start, options)
    assert not stalled.converged and stalled.residual > options.tolerance


def test_the_deformation_masses_leave_out_the_rigid_modes_share():
    """problem.deformation_masses on a hand-made problem: one body, two contacts against a
    wall with normal e_y, W_s = G Gᵀ + D (G: one rigid mode, D the deformation's part, its
    normal components [[a, b], [b, c]]). ρ_c = max(1/W_cc,nn, 1/(|D_cc| + |D_cc'|)): for
    the first contact, whose W_cc the rigid mode dominates, 1/(a + |b|) (2000 × its normal
    mass); for the second, where the rigid share is smaller than |b|, the normal mass
    1/W_cc,nn. Without rigid modes they are the normal masses."""
    from softgrains.contact.problem import deformation_masses, normal_masses

    a, b, c = 1e-6, -4e-6, 1e-3
    D = np.zeros((4, 4))
    D[1, 1], D[1, 3], D[3, 1], D[3, 3] = a, b, b, c
    D[0, 0] = D[2, 2] = 1e-6  # tangential
    G = np.array([[0.0], [1e-1], [0.0], [1e-3]])  # (rows d, modes): y-components 0.1, 1e-3
    W = G @ G.T + D
    problem = one_body_problem(W, np.zeros(4), [[0.0, 1.0], [0.0, 1.0]])
    np.testing.assert_array_equal(deformation_masses(problem), normal_masses(problem))
    problem.rigid = G.reshape(2, 2, 1)
    problem._cache.clear()
    expected = [1.0 / (a + abs(b)), 1.0 / W[3, 3]]  # c + |b| > W_33: the normal mass
    np.testing.assert_allclose(deformation_masses(problem), expected, rtol=1e-9)
    assert solvers._rigid_dominated(problem)

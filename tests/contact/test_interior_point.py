"""The interior point method for the contact problems that are convex QPs
(contact/interior_point.py: frictionless, and Tresca's fixed friction bound in 2D), on
problems whose Delassus operator is singular: against the exact solutions of a rigid block
landing (and sliding) on redundant wall sites, against independent active-set solvers of
the same QPs (SciPy's NNLS and bounded least squares), and on the saved problems where
every other stage of the solve stalls."""

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import lsq_linear, nnls
from test_problem_solvers import one_body_problem, saved_problem

from softgrains.contact import solvers
from softgrains.contact.interior_point import interior_point
from softgrains.contact.problem import ContactProblem, residual_norm
from softgrains.contact.solvers import solve

BENCHMARK_DATA = Path(__file__).resolve().parents[2] / "benchmarks" / "data"
DATA = Path(__file__).resolve().parent / "data"


def _wall_problem(W: np.ndarray, V_free: np.ndarray) -> ContactProblem:
    """n contacts of one body (rows 0..n−1, compliance W (2n × 2n)) on a fixed wall below
    it (normals e_y), without friction."""
    return one_body_problem(W, V_free, np.tile([0.0, 1.0], (V_free.shape[0], 1)))


def _rigid_block(mass, inertia, sites, velocity, spin):
    """A rigid block (``mass``, ``inertia`` about its centre) whose flat face, at the
    centre's height, touches the wall at ``sites`` (x from the centre), moving down at
    ``velocity`` and spinning at ``spin``: W_s = G Gᵀ with G's columns the block's rigid
    modes (x, y translation, rotation) per unit mass, rank 3 whatever the sites' number."""
    n = sites.size
    G = np.zeros((n, 2, 3))
    G[:, 0, 0] = G[:, 1, 1] = 1.0 / np.sqrt(mass)
    G[:, 1, 2] = sites / np.sqrt(inertia)
    G = G.reshape(2 * n, 3)
    V_free = np.zeros((n, 2))
    V_free[:, 1] = -velocity + spin * sites
    return _wall_problem(G @ G.T, V_free)


@pytest.mark.parametrize("velocity, spin, spun", [(1.0, 0.3, False), (0.2, 1.0, True)])
def test_a_rigid_block_lands_on_redundant_wall_sites(velocity, spin, spun):
    """Five sites along the face (x = −2 … 2) and three rigid modes: W of rank 3 of 10.
    The block's velocity after the inelastic landing is the projection, in the kinetic
    metric (mass 1, inertia 1), of (v, ω) = (−velocity, spin) onto the admissible cone
    {v_y + ω x ≥ 0 at every site} = {v_y ≥ 2|ω|}. Falling fast and spinning slowly it
    stops (0, 0); its impulses are then not unique (any P ≥ 0 with ΣP = velocity,
    Σ P x = −spin): only their sums are checked. Spinning fast it rolls onto its left end:
    (0.2, 1) projects onto the ray (2, 1): (v, ω) = (0.24, 0.12), the one site at x = −2
    taking P = 0.44."""
    sites = np.linspace(-2.0, 2.0, 5)
    problem = _rigid_block(1.0, 1.0, sites, velocity, spin)
    result = interior_point(problem, 1e-10)
    assert result.residual <= 1e-10
    P = result.impulse[:, 1]
    assert P.min() >= 0.0 and np.all(result.impulse[:, 0] == 0.0)
    v_y = -velocity + P.sum()
    omega = spin + (P * sites).sum()
    if spun:
        assert (v_y, omega) == pytest.approx((0.24, 0.12), abs=1e-9)
        assert P == pytest.approx([0.44, 0, 0, 0, 0], abs=1e-9)
    else:
        assert (v_y, omega) == pytest.approx((0.0, 0.0), abs=1e-9)
    gap_rate = problem.velocities(result.impulse)[:, 1]
    assert gap_rate == pytest.approx(v_y + omega * sites, abs=1e-12)
    assert gap_rate.min() >= -1e-9


@pytest.mark.parametrize("velocity, sticks", [(0.3, True), (2.0, False)])
def test_a_rigid_block_slides_on_redundant_wall_sites_under_a_tresca_bound(velocity, sticks):
    """The block of the landing test (mass 2, inertia 1, five sites at the centre's
    height: a tangential impulse gives no torque), falling at 1 and moving sideways at
    ``velocity``, with the friction bound s = 0.2 at every site (Σ s = 1): it stops
    sideways where m |v_t| = 2 × 0.3 < Σ s (impulses not unique: their sum is −0.6), else
    it slides on at v_t − Σ s/m = 2 − 0.5 = 1.5 with every site at its bound, −0.2."""
    sites = np.linspace(-2.0, 2.0, 5)
    problem = _rigid_block(2.0, 1.0, sites, 1.0, 0.0)
    problem.V_free[:, 0] = velocity
    problem.mu = np.full(5, 0.5)  # (not read: the bound is held)
    bound = np.full(5, 0.2)
    result = interior_point(problem, 1e-10, bound=bound)
    assert result.residual <= 1e-10
    P = result.impulse
    assert np.all(np.abs(P[:, 0]) <= bound + 1e-12)
    v_t = velocity + P[:, 0].sum() / 2.0
    assert (-1.0 + P[:, 1].sum() / 2.0) == pytest.approx(0.0, abs=1e-9)  # landed
    if sticks:
        assert v_t == pytest.approx(0.0, abs=1e-9)
    else:
        assert v_t == pytest.approx(1.5, abs=1e-9)
        assert P[:, 0] == pytest.approx(np.full(5, -0.2), abs=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_tresca_interior_point_agrees_with_bounded_least_squares(seed):
    """A random 2D problem with W = AᵀA of rank 24 on 20 contacts (40 components), free
    velocities q = Aᵀb and friction bounds s: the Tresca problem is the optimality
    condition of min ½‖A r + b‖² over r_n ≥ 0, |r_t| ≤ s (in global components, A's
    columns (n, t) per contact being (y, x): the contacts' tangent is −x, and the box is
    the same for either sign), which SciPy's bounded least squares (BVLS, an active-set
    method) solves exactly. The velocities W r + q are unique: the two must agree."""
    rng = np.random.default_rng(seed)
    n, rank = 20, 24
    A = rng.normal(size=(rank, 2 * n))
    b = rng.normal(size=rank)
    bound = rng.uniform(0.0, 0.3, size=n)
    problem = _wall_problem(A.T @ A, (A.T @ b).reshape(n, 2)[:, ::-1].copy())
    # (A's (n, t) components per contact are the global (y, x): W and q reordered)
    perm = np.arange(2 * n).reshape(n, 2)[:, ::-1].ravel()
    problem.W = (A.T @ A)[np.ix_(perm, perm)].ravel().copy()
    problem.mu = np.full(n, 0.5)
    result = interior_point(problem, 1e-10, bound=bound)
    assert result.residual <= 1e-10
    lower = np.ravel(np.column_stack((np.zeros(n), -bound)))  # (r_n, r_t) per contact
    upper = np.ravel(np.column_stack((np.full(n, np.inf), bound)))
    reference = lsq_linear(A, -b, bounds=(lower, upper), method="bvls", tol=1e-14).x
    w_ref = (A.T @ (A @ reference + b)).reshape(n, 2)
    w = problem.velocities(result.impulse)  # global (x, y) = (t, n)
    assert w[:, 1] == pytest.approx(w_ref[:, 0], abs=1e-8 * np.abs(w_ref).max())
    assert w[:, 0] == pytest.approx(w_ref[:, 1], abs=1e-8 * np.abs(w_ref).max())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_interior_point_agrees_with_an_active_set_nnls_solver(seed):
    """A random frictionless problem with M = W_nn = AᵀA of rank 8 on 20 contacts and
    free normal velocities c = Aᵀb: the LCP is the optimality condition of
    min ½‖A x + b‖² over x ≥ 0, which SciPy's NNLS (Lawson–Hanson active set) solves
    exactly. The velocities y = M x + c are unique (x is not, M being singular): the two
    solvers' must agree."""
    rng = np.random.default_rng(seed)
    n, rank = 20, 8
    A = rng.normal(size=(rank, n))
    b = rng.normal(size=rank)
    W = np.zeros((2 * n, 2 * n))
    W[1::2, 1::2] = A.T @ A
    W[0::2, 0::2] = np.eye(n)  # the tangential components (no friction: no impulse)
    V_free = np.zeros((n, 2))
    V_free[:, 1] = A.T @ b
    problem = _wall_problem(W, V_free)
    result = interior_point(problem, 1e-10)
    assert result.residual <= 1e-10
    x_ref, _ = nnls(A, -b)
    y_ref = A.T @ (A @ x_ref + b)
    y = problem.velocities(result.impulse)[:, 1]
    assert y == pytest.approx(y_ref, abs=1e-8 * np.abs(V_free).max())
    assert result.iterations <= 30


@pytest.mark.parametrize("name", ["redundant_wall_sites_step.npz",
                                  "redundant_wall_sites_step_dt16.npz"])
def test_redundant_wall_sites_that_stall_every_other_stage_are_solved(name, monkeypatch):
    """The two saved frictionless problems of the quasi-static squeeze (D/h 20, plates
    closing 0.025 h a step, step 52 at Δt and at Δt/16, session 50; 67 / 70 wall sites, W
    of rank 46–49): with their warm starts and the coupling loop's options, the Newton, the
    sweeps and the proximal point stalled at 1.3e-3 / 1.1e-4 (1268 / 1090 Newton
    iterations, measured). The interior point, the first fallback of a stalled
    frictionless Newton since session 51, meets the tolerance in ~20 iterations."""
    path = BENCHMARK_DATA / name
    problem, start, options = saved_problem(path)
    result = solve(problem, start, options)
    assert result.converged
    assert residual_norm(problem, result.impulse, floor=options.floor) <= options.tolerance
    assert result.iterations <= 100  # Newton and interior-point iterations
    # without the interior point the solve stalls (what it is for)
    monkeypatch.setattr(solvers, "_interior_point_applies", lambda problem, options: False)
    stalled = solve(ContactProblem.load(path), start, options)
    assert not stalled.converged and stalled.residual > 10 * options.tolerance


def test_the_interior_point_refuses_friction():
    problem = _rigid_block(1.0, 1.0, np.linspace(-1.0, 1.0, 3), 1.0, 0.0)
    problem.mu = np.full(3, 0.5)
    with pytest.raises(ValueError, match="frictionless"):
        interior_point(problem, 1e-8)


def test_frictional_redundant_wall_sites_are_solved_by_the_tresca_interior_point(
        monkeypatch):
    """frictional_redundant_wall_sites.npz: 48 contacts of the quasi-static squeeze between
    μ = 0.5 plates (D/h 20, plates closing 0.05 h a step, Δt c/h 3000; a coupling
    iteration of step 8, session 51), with its warm start and the loop's options
    (tolerance 1.3e-5). The Coulomb Newton, the Tresca fixed point on the Newton, the
    proximal point and the sweeps stalled at 6.0e-4 after 446 Newton iterations, on the
    normal masses and on the deformation scale (measured); the Tresca fixed point whose
    Tresca problems the interior point solves (after the proximal point) meets it:
    3.3e-8 (measured)."""
    path = DATA / "frictional_redundant_wall_sites.npz"
    problem, start, options = saved_problem(path)
    assert problem.mu.min() > 0.0
    result = solve(problem, start, options)
    assert result.converged
    assert residual_norm(problem, result.impulse, floor=options.floor) <= options.tolerance
    monkeypatch.setattr(solvers, "_tresca_interior_applies",
                        lambda problem, options: False)
    stalled = solve(ContactProblem.load(path), start, options)
    assert not stalled.converged and stalled.residual > 10 * options.tolerance


def test_problems_above_the_size_limit_keep_the_stages_they_had(monkeypatch):
    """The interior point factorises the whole problem at each iteration: above
    solvers.INTERIOR_POINT_NONZEROS nonzeros in W it is not tried (the saved frictionless
    problem, one body, 67 contacts: 4 × 67² = 17 956, W's nonzeros exactly; then it
    stalls as before)."""
    from softgrains.contact.interior_point import delassus_nonzeros

    path = BENCHMARK_DATA / "redundant_wall_sites_step.npz"
    problem, start, options = saved_problem(path)
    assert delassus_nonzeros(problem) == problem.delassus().nnz == 17956
    monkeypatch.setattr(solvers, "INTERIOR_POINT_NONZEROS", 17955)
    assert not solve(ContactProblem.load(path), start, options).converged
    monkeypatch.setattr(solvers, "INTERIOR_POINT_NONZEROS", 17956)
    assert solve(ContactProblem.load(path), start, options).converged


def test_a_closing_contact_no_body_can_move_is_reported_not_hidden():
    """A contact between two kinematic sides closing at 1 (W_cc = 0: nothing can stop it)
    beside one on a body: the interior point reports the Coulomb residual every solver
    reports (problem.residual_norm), not a residual that leaves that contact out."""
    problem = ContactProblem(
        normal=np.array([[0.0, 1.0], [0.0, 1.0]]), bias=np.zeros(2), mu=np.zeros(2),
        a_slot=np.array([0, -1]), a_col=np.array([0, 0]),
        b_slot=np.array([-1, -1]), b_col=np.array([0, 0]),
        wall_va=np.array([[0.0, 0.0], [0.0, -1.0]]), wall_vb=np.zeros((2, 2)),
        k_off=np.zeros(1, np.int64), k_size=np.array([1], np.int64),
        w_off=np.zeros(1, np.int64), W=np.eye(2).ravel(), V_free=np.array([[0.0, -1.0]]))
    result = interior_point(problem, 1e-10)
    assert result.residual == pytest.approx(residual_norm(problem, result.impulse))
    assert result.residual > 0.1  # the closing contact
    assert result.impulse[0] == pytest.approx([0.0, 1.0], abs=1e-9)  # the body's is solved
    assert result.iterations < 10  # (stopped there, not after STAGNATION iterations)

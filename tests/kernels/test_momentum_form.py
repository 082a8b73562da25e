"""The momentum form of the internal forces (simulation.stress_form = "momentum", θ = 1):
Ŝ = V⁰ Fⁿ S Fⁿᵀ with the start nodes' gradients. Its force has no moment about the start
nodes for any displacement (the consistent form's has one under load), its tangent is the
force's derivative (not symmetric), and the Newton matrix built from it (rotations.py)
decouples a free body's rigid rotation and reaches the exact direction by defect
correction."""

import numpy as np
import pytest
import scipy.sparse as sp

from softgrains.integrator import banded, lapack
from softgrains.integrator.assembly import (
    block_pattern,
    dimension,
    gather_forces,
    gather_tangent,
    node_point_map,
    pair_codes,
    point_stresses,
)
from softgrains.integrator.banded import BandedDecoupled
from softgrains.integrator.linear_solvers import DenseCholesky
from softgrains.integrator.rotations import (
    CORRECTIONS,
    DecoupledSparse,
    RigidRotations,
    corrected_solve,
    decoupled_dense,
    rotation_stiffness,
    symmetric_factorization,
)
from softgrains.materials import lame_parameters


def _loaded_body(small_body, seed=3):
    """A small neo-Hookean disk pre-strained by random F^n (a loaded grain) and a random
    displacement u of its nodes: (forces f(u, momentum), tangent K(u, momentum), node
    positions, u, touched nodes, s, box)."""
    rng = np.random.default_rng(seed)
    lat, x, v0, box, nodes, N, dN, s = small_body(1)
    n = len(x)
    lam, mu = lame_parameters(1.0e6, 0.3)
    F_n = np.eye(2) - 0.1 * np.eye(2) + 0.05 * rng.standard_normal((n, 2, 2))  # compressed
    vol_n = v0 * np.linalg.det(F_n)
    laws, lams, mus = np.zeros(n, dtype=np.int64), np.full(n, lam), np.full(n, mu)
    touched = np.unique(nodes)
    active_row = np.full(box.size, -1, dtype=np.int64)
    active_row[touched] = np.arange(touched.size)
    ptr, entries = node_point_map(nodes, active_row, touched.size)
    Pv, Av = np.empty((n, 2, 2)), np.empty((n, 2, 2, 2, 2))
    u = np.zeros((box.size, 2))
    u[touched] = 0.02 * lat.h * rng.standard_normal((touched.size, 2))

    def force(u, momentum):
        point_stresses(nodes, dN, u, F_n, vol_n, laws, lams, mus, Pv, Av, False, 4, False,
                       momentum, dimension(2))
        f = np.empty((touched.size, 2))
        gather_forces(ptr, entries, dN, Pv, f)
        return f

    def tangent(u, momentum):
        point_stresses(nodes, dN, u, F_n, vol_n, laws, lams, mus, Pv, Av, True, 4, False,
                       momentum, dimension(2))
        indptr, indices, slot, _ = block_pattern(active_row, box.shape, s)
        data = np.empty((indices.size, 2, 2))
        gather_tangent(ptr, entries, dN, Av, slot, pair_codes(s, 2), data)
        return sp.bsr_matrix((data, indices, indptr), shape=(2 * touched.size,) * 2)

    positions = lat.node_positions(box)[touched]
    return force, tangent, positions, u, touched


def _moment(positions, f):
    return float(np.sum(positions[:, 0] * f[:, 1] - positions[:, 1] * f[:, 0]))


def test_the_momentum_form_has_no_moment_about_the_start_nodes(small_body):
    """Σ X_I × f_I = −Σ_p skew(Ŝ_p) = 0 for any u (to round-off), while the consistent
    form's −Σ_p V⁰ skew(P Fⁿᵀ) is of the order of the load times the step's strain."""
    force, _, positions, u, _ = _loaded_body(small_body)
    scale = float(np.abs(force(u, False)).sum() * np.abs(positions).max())
    assert abs(_moment(positions, force(u, True))) < 1e-13 * scale
    assert abs(_moment(positions, force(u, False))) > 1e-4 * scale
    # and both forms agree where the step does not deform (u = 0: Ŝ = V⁰ P Fⁿᵀ)
    zero = np.zeros_like(u)
    assert np.allclose(force(zero, True), force(zero, False), rtol=1e-12,
                       atol=1e-12 * np.abs(force(zero, False)).max())


def test_the_momentum_tangent_is_the_derivative_of_its_force(small_body):
    force, tangent, positions, u, touched = _loaded_body(small_body, seed=5)
    K = tangent(u, True).toarray()
    eps = 1e-7 * 0.1
    rng = np.random.default_rng(0)
    for c in rng.choice(K.shape[0], 12, replace=False):
        up, um = u.copy(), u.copy()
        up[touched[c // 2], c % 2] += eps
        um[touched[c // 2], c % 2] -= eps
        fd = -(force(up, True) - force(um, True)).ravel() / (2 * eps)
        assert np.allclose(fd, K[:, c], rtol=1e-5, atol=1e-6 * np.abs(K).max())
    # not symmetric once the step deforms (the consistent tangent is)
    assert np.abs(K - K.T).max() > 1e-4 * np.abs(K).max()
    # a rigid rotation of the start nodes is a left null vector: Kᵀρ = 0
    rho = np.stack([-positions[:, 1], positions[:, 0]], axis=1).ravel()
    assert np.abs(rho @ K).max() < 1e-10 * np.abs(K).max() * np.abs(rho).max()


@pytest.fixture
def newton_matrix(small_body):
    """(A = c_m M + θΔt K of the momentum form (BSR), its body's RigidRotations, c_m, M)."""
    force, tangent, positions, u, _ = _loaded_body(small_body, seed=7)
    K = tangent(u, True)
    m = np.full(positions.shape[0], 2.0)
    c_m = 1e-3 * np.abs(K).max() / m[0]  # a quasi-static step: the inertia is small
    A = sp.bsr_matrix(K + c_m * sp.diags(np.repeat(m, 2)), blocksize=(2, 2))
    rotations = RigidRotations.of(positions, m, lambda v: m[:, None] * v)
    return A, rotations, c_m, m


def test_the_decoupled_matrix_keeps_the_exact_rotation_row_and_the_inertia(newton_matrix):
    """A_s = PᵀĀP + Q c_m RᵀMR Qᵀ: symmetric, A_s ρ = c_m M ρ, and ρᵀA_s = ρᵀA (= c_m ρᵀM:
    the exact angular-momentum row); on the strains it is A's symmetric part."""
    A, rotations, c_m, m = newton_matrix
    A_s = decoupled_dense(A, rotations, c_m * rotations.inertia)
    rho = rotations.fields[:, 0]
    full = A.toarray()
    scale = np.abs(full).max() * np.abs(rho).max()
    assert np.allclose(A_s, A_s.T, atol=1e-13 * np.abs(full).max())
    assert np.allclose(A_s @ rho, c_m * np.repeat(m, 2) * rho, atol=1e-10 * scale)
    assert np.allclose(rho @ A_s, rho @ full, atol=1e-10 * scale)
    P = np.eye(full.shape[0]) - np.outer(rho, rotations.dual[:, 0])
    assert np.allclose(P.T @ A_s @ P, P.T @ (0.5 * (full + full.T)) @ P,
                       atol=1e-10 * np.abs(full).max())


def test_the_sparse_decoupled_solve_is_the_dense_one(newton_matrix):
    A, rotations, c_m, _ = newton_matrix
    block = c_m * rotations.inertia
    A_s = decoupled_dense(A, rotations, block)
    b = np.random.default_rng(1).standard_normal((A.shape[0], 3))
    assert np.allclose(DecoupledSparse(A, rotations, block).solve(b), np.linalg.solve(A_s, b),
                       rtol=1e-8, atol=1e-10 * np.abs(np.linalg.solve(A_s, b)).max())


def _banded(A, rotations, block):
    """banded.factorize of A's A_s: (info, BandedDecoupled)."""
    kd = banded.lower_bandwidth(A.indptr, A.indices, A.blocksize[0])
    factors = BandedDecoupled.workspace(A.shape[0], kd, rotations.fields.shape[1])
    info = banded.factorize(lapack.DPBTRF, lapack.DPBTRS, A.indptr, A.indices, A.data,
                            rotations.fields, rotations.dual, block, *factors)
    return info, BandedDecoupled(*factors)


def test_the_band_is_the_symmetric_parts(newton_matrix):
    """banded._symmetric_band_times: the lower band of Ā = ½(A + Aᵀ) of the (non-symmetric)
    momentum tangent, whose entries all lie within the lower bandwidth of A's pattern, and
    Ā R (the rotations), in one pass over A's blocks."""
    A, rotations = newton_matrix[:2]
    kd = banded.lower_bandwidth(A.indptr, A.indices, 2)
    full = A.toarray()
    rows, cols = np.nonzero(full)
    assert (rows - cols).max() <= kd <= (rows - cols).max() + 1  # (whole 2 × 2 blocks)
    assert kd < A.shape[0] // 3  # a band: rows of the node box, not the whole body
    ab = np.empty((kd + 1, A.shape[0]), order="F")
    AR = np.empty(rotations.fields.shape)
    banded._symmetric_band_times(A.indptr, A.indices, A.data, rotations.fields, ab, AR)
    symmetric = 0.5 * (full + full.T)
    expected = np.zeros_like(ab)
    for j in range(A.shape[0]):
        column = symmetric[j:j + kd + 1, j]
        expected[:column.size, j] = column
    np.testing.assert_allclose(ab, expected, rtol=0.0, atol=1e-15 * np.abs(full).max())
    exact = symmetric @ rotations.fields
    np.testing.assert_allclose(AR, exact, rtol=0.0, atol=1e-13 * np.abs(exact).max())


@pytest.mark.parametrize("inertia", [1e-3, 1.0])
def test_the_banded_solve_and_compliance_are_the_dense_ones(newton_matrix, inertia):
    """A_s⁻¹ as Ā's band Cholesky and the rank-2k Woodbury update (banded.py) is the dense
    A_s's inverse: solves of one and several right-hand sides and the compliance Bᵀ A_s⁻¹ B
    (exactly symmetric) to ~1e-12, at a quasi-static step's inertia and a dynamic one's
    (c_m = inertia × max|K| / m)."""
    A, rotations, c_m, m = newton_matrix
    A = (A + (inertia / 1e-3 - 1.0) * c_m * sp.diags(np.repeat(m, 2))).tobsr(blocksize=(2, 2))
    A.sort_indices()
    block = c_m * inertia / 1e-3 * rotations.inertia
    A_s = decoupled_dense(A, rotations, block)
    info, factorization = _banded(A, rotations, block)
    assert info == 0
    rng = np.random.default_rng(4)
    b = rng.standard_normal((A.shape[0], 3))
    exact = np.linalg.solve(A_s, b)
    scale = np.abs(exact).max()
    np.testing.assert_allclose(factorization.solve(b), exact, rtol=0.0, atol=1e-11 * scale)
    np.testing.assert_allclose(factorization.solve(b[:, 0]), exact[:, 0], rtol=0.0,
                               atol=1e-11 * scale)
    B = np.zeros((A.shape[0], 6))  # site columns: a few entries each, the last none
    B[rng.choice(A.shape[0], 12, replace=False), rng.integers(0, 5, 12)] = 1.0
    W = factorization.compliance(B, 2.0)  # (by rows from each column's first entry)
    expected = 2.0 * B.T @ np.linalg.solve(A_s, B)
    assert np.array_equal(W, W.T) and not W[5].any()
    np.testing.assert_allclose(W, expected, rtol=0.0, atol=1e-11 * np.abs(expected).max())


def test_an_indefinite_symmetric_part_is_refused(newton_matrix):
    """At a quasi-static step's inertia (c_m = 1e-6 max|K| / m) the loaded body's Ā is
    indefinite through the rotation's coupling to the strain alone, while A_s is positive
    definite: banded.factorize says so (LAPACK's info, late in the factorization), for
    the caller's dense A_s, which Cholesky factorises."""
    A, rotations, c_m, m = newton_matrix
    c_m *= 1e-3
    A = (A - 999.0 * c_m * sp.diags(np.repeat(m, 2))).tobsr(blocksize=(2, 2))
    A.sort_indices()
    full = A.toarray()
    assert np.linalg.eigvalsh(0.5 * (full + full.T)).min() < 0.0
    info, _ = _banded(A, rotations, c_m * rotations.inertia)
    assert info > A.shape[0] // 2
    A_s = decoupled_dense(A, rotations, c_m * rotations.inertia)
    assert isinstance(symmetric_factorization(A_s), DenseCholesky)


def test_the_band_and_its_update_in_three_dimensions():
    """banded.py with d = 3 and k = 3 rotations (a random banded SPD Ā of 3 × 3 blocks,
    rigid rotations of random node positions): solves and the compliance are the dense
    A_s's (rotations.decoupled_dense) to ~1e-11."""
    rng = np.random.default_rng(8)
    nodes, reach = 60, 5  # block bandwidth
    blocks = {}
    for r in range(nodes):
        for c in range(max(0, r - reach), min(nodes, r + reach + 1)):
            blocks[r, c] = rng.standard_normal((3, 3)) * (0.2 if r != c else 1.0)
    dense_A = np.zeros((3 * nodes, 3 * nodes))
    for (r, c), block in blocks.items():
        dense_A[3 * r:3 * r + 3, 3 * c:3 * c + 3] = block
    dense_A += 0.3 * (dense_A - dense_A.T)  # not symmetric, as the momentum tangent
    dense_A += 20.0 * np.eye(3 * nodes)
    A = sp.bsr_matrix(dense_A, blocksize=(3, 3))
    A.sort_indices()
    positions, m = rng.random((nodes, 3)), 1.0 + rng.random(nodes)
    rotations = RigidRotations.of(positions, m, lambda v: m[:, None] * v)
    block = 0.1 * rotations.inertia
    info, factorization = _banded(A, rotations, block)
    assert info == 0 and factorization.U.shape == (3 * nodes, 6)
    A_s = decoupled_dense(A, rotations, block)
    b = rng.standard_normal((3 * nodes, 2))
    exact = np.linalg.solve(A_s, b)
    np.testing.assert_allclose(factorization.solve(b), exact, rtol=0.0,
                               atol=1e-11 * np.abs(exact).max())
    B = np.zeros((3 * nodes, 4))
    B[rng.choice(3 * nodes, 10, replace=False), rng.integers(0, 4, 10)] = 1.0
    expected = B.T @ np.linalg.solve(A_s, B)
    np.testing.assert_allclose(factorization.compliance(B), expected, rtol=0.0,
                               atol=1e-11 * np.abs(expected).max())


@pytest.mark.parametrize("n, kd, d, expected", [
    (262, 55, 2, True),  # a grain at D/h 10
    (262, 100, 2, False),  # a band of 0.38 of the unknowns: dense
    (2946, 177, 2, True),  # a disk at D/h 40, above DENSE_LIMIT
    (5278, 817, 2, False),  # a 200 × 10-cell slab along the grid's fastest axis
    (3567, 908, 3, False),  # a sphere at D/h 10
    (1200, 300, 3, True),  # a small 3D body, within DENSE_LIMIT: the band beats dense
])
def test_the_band_is_taken_where_it_pays(n, kd, d, expected):
    """banded.band_pays: a band of at most BAND_FRACTION of the unknowns; above
    DENSE_LIMIT (1500), where SuperLU factorised A_s, only a band as narrow as a body as
    wide as it is tall on a 2D grid."""
    assert banded.band_pays(n, kd, d, 1500) == expected


def test_defect_correction_reaches_the_exact_direction(newton_matrix):
    """From A_s's factorization, the corrections reach A⁻¹b (A not symmetric) to their
    tolerance before their cap (each gains about the step's |ΔF − I|; measured on the
    frictionless example: 7.6e-3, then 2.1e-5, 2.8e-7 relative in the median)."""
    A, rotations, c_m, _ = newton_matrix
    factorization = symmetric_factorization(decoupled_dense(A, rotations,
                                                            c_m * rotations.inertia))
    b = np.random.default_rng(2).standard_normal(A.shape[0])
    exact = np.linalg.solve(A.toarray(), b)
    start = factorization.solve(b)
    x, taken = corrected_solve(A, factorization, b, start)
    assert np.linalg.norm(start - exact) > 1e-4 * np.linalg.norm(exact)
    assert np.linalg.norm(x - exact) < 1e-5 * np.linalg.norm(exact)
    assert taken < CORRECTIONS  # stopped by its tolerance, not by the cap


def test_the_stiffened_rotation_takes_the_virial_of_the_loads(newton_matrix):
    """rotation_stiffness: c_m RᵀMR + s|Σ_p tr Ŝ_p| in 2D (S_aᵀS_b = I), positive for a
    compressed body (whose Σ tr Ŝ < 0)."""
    _, rotations, c_m, _ = newton_matrix
    stresses = np.tile(np.array([[-2.0, 0.3], [0.3, -1.0]]), (5, 1, 1))
    block = rotation_stiffness(rotations, stresses, c_m, 0.5)
    assert block[0, 0] == pytest.approx(c_m * rotations.inertia[0, 0] + 0.5 * 15.0)


@pytest.mark.parametrize("settings, expected", [
    ({}, True),  # the default, stress_form = "auto", at θ = 1
    ({"stress_form": "consistent"}, False),
    ({"stress_form": "momentum"}, True),
    ({"theta": 0.5}, False),  # auto: the momentum form is the θ = 1 step's
    ({"integrator": "newmark", "mass_matrix": "lumped"}, False),
])
def test_the_default_stress_form_is_the_momentum_form_at_theta_one(settings, expected):
    """stress_form = "auto" (the default since session 50) takes the momentum form where
    the step is the θ-scheme with θ = 1, and the consistent form otherwise (an explicit
    "momentum" there is refused: tests/case/test_load.py)."""
    from softgrains import Simulation, load_case
    from softgrains.integrator.implicit import BodyStep

    sim = Simulation(load_case({
        "simulation": {"dt": 1e-3, "steps": 1, **settings},
        "grid": {"cell_size": 0.1, "origin": [0.0, 0.0], "size": [2.0, 2.0]},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "disk", "shape": "disk", "center": [1.0, 1.0], "radius": 0.5,
                    "material": "gel"}],
        "output": {"progress": False},
    }))
    step = BodyStep(sim.solver.steppers[0], sim.solver.body_points(sim.state, 0),
                    np.zeros(2), 1e-3, 0)
    assert step.momentum_form == expected


def _loaded_disk_step(seed=5, mass_matrix="lumped", cell_size=0.1):
    """A BodyStep of the momentum form for a neo-Hookean disk under gravity whose points
    start pre-strained by random F^n (a loaded grain, as in a dense packing)."""
    from softgrains import Simulation, load_case
    from softgrains.integrator.implicit import BodyStep

    sim = Simulation(load_case({
        "simulation": {"dt": 1e-3, "steps": 1, "mass_matrix": mass_matrix},
        "grid": {"cell_size": cell_size, "origin": [0.0, 0.0], "size": [2.0, 2.0]},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "disk", "shape": "disk", "center": [1.0, 1.0], "radius": 0.5,
                    "material": "gel"}],
        "output": {"progress": False},
    }))
    rng = np.random.default_rng(seed)
    F = sim.state.F
    F[:] = np.eye(2) - 0.1 * np.eye(2) + 0.03 * rng.standard_normal(F.shape)
    sim.state.vol[:] = sim.model.vol0 * np.linalg.det(F)
    step = BodyStep(sim.solver.steppers[0], sim.solver.body_points(sim.state, 0),
                    np.array([0.0, -9.81]), 1e-3, 0)
    assert step.momentum_form
    return step


@pytest.mark.parametrize("mass_matrix", ["lumped", "consistent"])
def test_the_one_call_dense_direction_is_the_general_paths(mass_matrix, monkeypatch):
    """dense_direction.momentum_direction (the chain of kernels in one GIL-free call, here
    with the band path off) gives the direction, the factorization and the contacts'
    compliance of the general path (Newton matrix, decoupled dense A_s, Cholesky, defect
    corrections) to round-off, and newton_direction takes it for a dense body of the
    momentum form."""
    import softgrains.integrator.implicit as implicit

    monkeypatch.setattr(implicit, "band_pays", lambda *args: False)
    step = _loaded_disk_step(mass_matrix=mass_matrix)
    du = step.newton_direction(direct=True)
    assert step._exact is None  # (the one-call path leaves no BSR matrix behind)
    lower = np.tril(step.factorization().lower)
    rows = np.arange(0, step.u.shape[0], 7)
    _, W = step.contact_response(rows, True)
    general = step._momentum_direction(step._matrix())
    assert step._exact is not None
    scale = float(np.abs(general).max())
    assert scale > 0.0
    np.testing.assert_allclose(du, general, rtol=0.0, atol=1e-12 * scale)
    np.testing.assert_allclose(lower, np.tril(step.factorization().lower), rtol=1e-13,
                               atol=1e-13 * float(np.abs(lower).max()))
    _, W_general = step.contact_response(rows, True)
    np.testing.assert_allclose(W, W_general, rtol=1e-12, atol=1e-12 * float(np.abs(W).max()))


@pytest.mark.parametrize("mass_matrix", ["lumped", "consistent"])
def test_the_one_call_banded_direction_is_the_general_paths(mass_matrix, monkeypatch):
    """By default a grain's direction is dense_direction.banded_momentum_direction (A_s as
    Ā's band and a rank-2k update, banded.py): the direction and the contacts' compliance
    of the general path with the dense A_s to ~1e-11, and the factorization kept for the
    compliance and the contacts' responses is the banded one."""
    import softgrains.integrator.implicit as implicit

    step = _loaded_disk_step(mass_matrix=mass_matrix)
    du = step.newton_direction(direct=True)
    assert step._exact is None  # (the one-call path)
    assert isinstance(step.factorization(), BandedDecoupled)
    assert step.factorization().ab.shape[0] < step.u.size // 3
    rows = np.arange(0, step.u.shape[0], 7)
    _, W = step.contact_response(rows, True)
    monkeypatch.setattr(implicit, "band_pays", lambda *args: False)
    general = step._momentum_direction(step._matrix())
    assert isinstance(step.factorization(), DenseCholesky)
    scale = float(np.abs(general).max())
    np.testing.assert_allclose(du, general, rtol=0.0, atol=1e-11 * scale)
    _, W_general = step.contact_response(rows, True)
    np.testing.assert_allclose(W, W_general, rtol=0.0, atol=1e-11 * float(np.abs(W).max()))


@pytest.mark.parametrize("stiffened", [False, True])
def test_a_large_body_takes_the_band_on_the_general_path(stiffened, monkeypatch):
    """Above DENSE_LIMIT (a disk at D/h 40, 2946 unknowns) the general path factorises A_s
    as Ā's band and its rank-2k update, not by SuperLU (DecoupledSparse): the same
    direction (defect-corrected; with a stiffened rotation A_s's own) and compliance to
    ~1e-10."""
    import softgrains.integrator.implicit as implicit
    from softgrains.integrator.linear_solvers import DENSE_LIMIT

    step = _loaded_disk_step(cell_size=0.025)
    assert step.u.size > DENSE_LIMIT
    if stiffened:
        assert step.stiffen_rotation()
    du = step.newton_direction(direct=True)
    assert isinstance(step.factorization(), BandedDecoupled)
    rows = np.arange(0, step.u.shape[0], 37)
    _, W = step.contact_response(rows, True)
    monkeypatch.setattr(implicit, "band_pays", lambda *args: False)
    general = step._momentum_direction(step._matrix())
    assert isinstance(step.factorization(), DecoupledSparse)
    np.testing.assert_allclose(du, general, rtol=0.0, atol=1e-10 * float(np.abs(general).max()))
    _, W_sparse = step.contact_response(rows, True)
    np.testing.assert_allclose(W, W_sparse, rtol=0.0, atol=1e-10 * float(np.abs(W).max()))


@pytest.mark.parametrize("along_x", [True, False])
def test_a_slab_long_along_the_grids_fastest_axis_keeps_superlu(along_x):
    """A free slab of 100 × 6 cells (above DENSE_LIMIT): lying along x, the axis its nodes
    are numbered along first, its band holds a whole row of the box and band_pays leaves
    it to SuperLU (DecoupledSparse); standing along y its band is narrow and taken."""
    from softgrains import Simulation, load_case
    from softgrains.integrator.implicit import BodyStep
    from softgrains.integrator.linear_solvers import DENSE_LIMIT

    size = [10.0, 0.6] if along_x else [0.6, 10.0]
    sim = Simulation(load_case({
        "simulation": {"dt": 1e-3, "steps": 1},
        "grid": {"cell_size": 0.1, "origin": [0.0, 0.0], "size": [11.0, 11.0]},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "slab", "shape": "rectangle", "lower": [0.5, 0.5],
                    "upper": [0.5 + size[0], 0.5 + size[1]], "material": "gel"}],
        "output": {"progress": False},
    }))
    step = BodyStep(sim.solver.steppers[0], sim.solver.body_points(sim.state, 0),
                    np.array([0.0, -9.81]), 1e-3, 0)
    assert step.momentum_form and step.u.size > DENSE_LIMIT
    step.newton_direction(direct=True)
    expected = DecoupledSparse if along_x else BandedDecoupled
    assert isinstance(step.factorization(), expected)


def test_a_large_body_whose_band_is_refused_takes_superlu(monkeypatch):
    """On the general path above DENSE_LIMIT, where the band factorization is refused (Ā
    not positive definite) the body takes DecoupledSparse, and keeps it for the step."""
    import softgrains.integrator.implicit as implicit

    calls = []

    def refused(*args):
        calls.append(1)

    monkeypatch.setattr(implicit, "banded_decoupled", refused)
    step = _loaded_disk_step(cell_size=0.025)
    step.newton_direction(direct=True)
    assert calls == [1] and isinstance(step.factorization(), DecoupledSparse)
    step._lu = None
    step._A = step._matrix()  # a second matrix in the same step: the band not tried again
    assert calls == [1] and isinstance(step._A, DecoupledSparse)


def test_an_indefinite_band_leaves_the_direction_to_the_dense_kernel(monkeypatch):
    """Where the band path finds Ā not positive definite, the dense A_s is factorised in the
    same call of _dense_momentum_direction: the direction is the general path's."""
    import softgrains.integrator.implicit as implicit
    from softgrains.integrator.dense_direction import INDEFINITE

    calls = []

    def indefinite(*args):
        calls.append(1)
        return INDEFINITE, 0

    monkeypatch.setattr(implicit, "banded_momentum_direction", indefinite)
    step = _loaded_disk_step()
    du = step.newton_direction(direct=True)
    assert calls and isinstance(step.factorization(), DenseCholesky)
    general = step._momentum_direction(step._matrix())
    np.testing.assert_allclose(du, general, rtol=0.0, atol=1e-12 * float(np.abs(general).max()))


def test_the_one_call_direction_leaves_a_stiffened_rotation_to_the_general_path():
    """Once the rotation is stiffened from the iterate's stresses the one-call path
    declines (its block needs them first) and the general path gives the direction."""
    step = _loaded_disk_step()
    assert step.stiffen_rotation()
    assert step._dense_momentum_direction() is None
    step.newton_direction(direct=True)
    assert step._exact is not None


@pytest.mark.parametrize("mass_matrix", ["lumped", "consistent"])
@pytest.mark.parametrize("scale", [1.0, 40.0, -1.0, 1e9])
def test_the_one_call_line_search_is_implicit_line_search(scale, mass_matrix):
    """momentum_line_search.residual_line_search (one GIL-free call) takes the trial that
    implicit.line_search takes with the momentum form's NaN potential: the full Newton
    step near the solution, a halved one where the step overshoots (``scale`` 40 blows
    the direction up), the admissible trial of least ‖R‖ along an ascent direction (−1),
    and the last trial where every one inverts a point (1e9)."""
    from softgrains.integrator.implicit import line_search

    step = _loaded_disk_step(mass_matrix=mass_matrix)
    du = scale * step.newton_direction(direct=True)
    u0, r0 = step.u.copy(), step.r.copy()
    expected = line_search(u0, du, r0, step.pi, step.internal_force, step.residual,
                           step.potential, step._threshold)
    u, r, rnorm, jmin, f_int, w_int = step._momentum_line_search(du)
    np.testing.assert_array_equal(u, expected[0])
    np.testing.assert_array_equal(r, expected[2])
    assert jmin == expected[4]
    if jmin > 0.0:  # the trial's f^int and W, which grid_dissipation takes from it
        f_at, _, w_at = step.internal_force(u, False)
        np.testing.assert_array_equal(f_int, f_at)
        assert w_int == w_at
    assert rnorm == expected[3] or (np.isnan(rnorm) and np.isnan(expected[3]))
    taken = float(np.abs(u - u0).max() / np.abs(du).max())  # the step's α
    assert (taken == 1.0) == (scale == 1.0)
    if scale == 1e9:
        assert jmin <= 0.0 and np.isnan(rnorm)  # every trial inverted: the last one
    if scale == -1.0:
        assert jmin > 0.0 and rnorm > np.linalg.norm(r0)  # no descent: the least ‖R‖


@pytest.mark.parametrize("mass_matrix", ["lumped", "consistent"])
def test_the_step_energy_reuses_the_line_searchs_forces_exactly(mass_matrix):
    """grid_dissipation takes f^int and W at the converged u from the last line search
    (or the step's set-up) instead of evaluating them again: the same value to the bit as
    with the evaluation, after the set-up and after Newton steps."""
    step = _loaded_disk_step(mass_matrix=mass_matrix)
    for _ in range(3):
        assert step._forces_at is not None and step._forces_at[0] is step.u
        reused = step.grid_dissipation()
        kept, step._forces_at = step._forces_at, None
        assert step.grid_dissipation() == reused
        step._forces_at = kept
        step.take_step(step.newton_direction(direct=True))


def test_a_body_shared_by_parallel_kernels_keeps_the_general_path(monkeypatch):
    """The one-call chains run serial kernels: a body at or above PARALLEL_MIN_POINTS
    points, whose kernels the calling thread's threads share, keeps the general path
    when the caller has several threads, and takes them on one thread (over_bodies'
    workers)."""
    import numba

    from softgrains.integrator import implicit

    step = _loaded_disk_step()
    monkeypatch.setattr(implicit, "PARALLEL_MIN_POINTS", step.nodes.shape[0])
    monkeypatch.setattr(numba, "get_num_threads", lambda: 1)
    assert step._in_one_call()
    # (the caller's thread count as Numba would report it with 2 threads, without
    # starting them: the test workers run on one)
    monkeypatch.setattr(numba, "get_num_threads", lambda: 2)
    assert not step._in_one_call()
    assert step._dense_momentum_direction() is None
    monkeypatch.setattr(implicit, "PARALLEL_MIN_POINTS", step.nodes.shape[0] + 1)
    assert step._in_one_call()

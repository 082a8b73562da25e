"""The bodies' Newton solves (integrator/linear_solvers.py): the dense Cholesky (positive
definite) or LU used for small bodies gives what SuperLU gives, for one right-hand side
and for many (the contact compliance [A⁻¹]_cc), and fails the way SuperLU does on a
singular matrix; the Newton matrix with its negative modes mirrored."""

import numpy as np
import pytest
import scipy.sparse as sp

from softgrains.integrator import linear_solvers
from softgrains.integrator.linear_solvers import (
    DenseCholesky,
    DenseLU,
    LinearSolver,
    factorize,
    mirrored_negative_modes,
    site_columns,
    sparse_times,
)


def _stiffness_like(n, seed=0):
    """A sparse, nonsymmetric, well-conditioned n × n matrix (a banded Laplacian plus a
    random perturbation of its pattern)."""
    rng = np.random.default_rng(seed)
    A = sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(n, n)).tolil()
    for _ in range(3 * n):
        i, j = rng.integers(0, n, 2)
        A[i, j] += 0.1 * rng.standard_normal()
    return sp.bsr_matrix(A.tocsr())


@pytest.mark.parametrize("n", [40, 2 * linear_solvers.DENSE_LIMIT])
def test_the_factorization_solves_one_and_many_right_hand_sides(n):
    A = _stiffness_like(n)
    lu = factorize(A)
    assert isinstance(lu, DenseLU) == (n <= linear_solvers.DENSE_LIMIT)
    rng = np.random.default_rng(1)
    b, B = rng.standard_normal(n), rng.standard_normal((n, 7))
    dense = A.toarray()
    assert np.allclose(dense @ lu.solve(b), b, atol=1e-10)
    assert np.allclose(dense @ lu.solve(B), B, atol=1e-10)
    solver = LinearSolver("direct")
    x = solver.solve(A, b, np.zeros(0, np.int64))
    assert np.allclose(dense @ x, b, atol=1e-10) and solver.last_factorization is not None


def test_a_singular_matrix_fails_like_superlu():
    """A zero row: SuperLU raises RuntimeError ("exactly singular"), which a body's Newton
    turns into a SimulationError with its diagnosis; the dense LU must do the same rather
    than return Inf/NaN."""
    A = _stiffness_like(30).tolil()
    A[5, :] = 0.0
    A = sp.csr_matrix(A)
    with pytest.raises(RuntimeError):
        DenseLU(A)


def test_mirrored_negative_modes_flip_only_the_negative_eigenvalues():
    """A⁺ = A + Σ_{λ<0} 2|λ| M v vᵀ M for A v = λ M v: a symmetric A with two negative
    generalised eigenvalues (built from chosen eigenpairs) gets them as |λ| and keeps every
    other eigenpair exactly (A⁺ v = A v there); a positive definite A gives None."""
    rng = np.random.default_rng(3)
    n = 12
    m = rng.uniform(0.5, 3.0, n)
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    lam = np.r_[-4.0, -0.5, rng.uniform(0.1, 50.0, n - 2)]
    root = np.sqrt(m)
    A = (Q * lam) @ Q.T * root[:, None] * root[None, :]  # M^½ Q Λ Qᵀ M^½
    V = Q / root[:, None]  # A v = λ M v, vᵀ M v = 1
    mirrored = mirrored_negative_modes(sp.csr_matrix(A), m)
    np.testing.assert_allclose(mirrored @ V, (V * np.abs(lam)) * m[:, None], atol=1e-9)
    np.testing.assert_allclose(mirrored @ V[:, 2:], A @ V[:, 2:], atol=1e-9)
    np.linalg.cholesky(0.5 * (mirrored + mirrored.T))  # positive definite
    positive = (Q * np.abs(lam)) @ Q.T * root[:, None] * root[None, :]
    assert mirrored_negative_modes(sp.csr_matrix(positive), m) is None
    singular = (Q * np.r_[0.0, np.abs(lam[1:])]) @ Q.T * root[:, None] * root[None, :]
    assert mirrored_negative_modes(sp.csr_matrix(singular), m) is None  # 0: no negative mode
    # a dense Newton matrix (mirrored) is solved by the LU, also where CG is asked for
    solver = LinearSolver("cg")
    b = rng.standard_normal(n)
    np.testing.assert_allclose(mirrored @ solver.solve(mirrored, b, np.zeros(0, np.int64)), b,
                               atol=1e-10)
    assert solver.last_method == "direct"


def test_a_block_sparse_matrix_is_written_densely_as_scipy_does():
    """The Newton matrices are BSR with d × d blocks; ``dense`` writes them without SciPy's
    conversion (a kernel that releases the GIL), repeated blocks summed as SciPy sums them."""
    rng = np.random.default_rng(5)
    A = sp.bsr_matrix(sp.random(12, 12, density=0.3, random_state=6).toarray(), blocksize=(2, 2))
    np.testing.assert_array_equal(linear_solvers.dense(A), A.toarray())
    blocks = rng.standard_normal((3, 2, 2))
    repeated = sp.bsr_matrix((blocks, np.array([0, 0, 1]), np.array([0, 2, 3])), shape=(4, 4))
    np.testing.assert_allclose(linear_solvers.dense(repeated), repeated.toarray(), rtol=1e-15)
    rectangular = sp.bsr_matrix(sp.random(6, 9, density=0.5, random_state=7).toarray(),
                                blocksize=(2, 3))
    np.testing.assert_array_equal(linear_solvers.dense(rectangular), rectangular.toarray())


def test_an_empty_system_factorizes_and_solves():
    """A body with no unknown left (LAPACK refuses n = 0): an empty solution."""
    lu = DenseLU(np.zeros((0, 0)))
    assert lu.solve(np.zeros(0)).shape == (0,) and lu.solve(np.zeros((0, 3))).shape == (0, 3)


def test_a_symmetric_positive_definite_matrix_is_factorised_by_cholesky():
    """factorize: Cholesky (half the LU's work) for a symmetric positive definite A, the
    LU for a symmetric indefinite or a nonsymmetric one; each solves A x = b, and the half
    solve gives Bᵀ A⁻¹ B = (L⁻¹B)ᵀ(L⁻¹B)."""
    rng = np.random.default_rng(9)
    n = 30
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    spd = (Q * rng.uniform(0.1, 10.0, n)) @ Q.T
    spd = 0.5 * (spd + spd.T)
    indefinite = (Q * np.r_[-1.0, rng.uniform(0.1, 10.0, n - 1)]) @ Q.T
    indefinite = 0.5 * (indefinite + indefinite.T)
    nonsymmetric = spd + 0.01 * np.triu(rng.standard_normal((n, n)), 1)
    b, B = rng.standard_normal(n), rng.standard_normal((n, 4))
    for A, kind in ((spd, DenseCholesky), (indefinite, DenseLU), (nonsymmetric, DenseLU),
                    (sp.bsr_matrix(spd, blocksize=(2, 2)), DenseCholesky),
                    (sp.bsr_matrix(indefinite, blocksize=(2, 2)), DenseLU),
                    (sp.bsr_matrix(nonsymmetric, blocksize=(2, 2)), DenseLU)):
        before = A.copy()
        f = factorize(A)
        assert type(f) is kind
        dense = A.toarray() if sp.issparse(A) else A
        np.testing.assert_allclose(dense @ f.solve(b), b, atol=1e-10)
        np.testing.assert_allclose(dense @ f.solve(B), B, atol=1e-10)
        assert abs(A - before).max() == 0.0  # the input is left as it was
    Y = factorize(spd).half_solve(B)
    np.testing.assert_allclose(Y.T @ Y, B.T @ np.linalg.solve(spd, B), rtol=1e-10)
    # the compliance α Bᵀ A⁻¹ B by syrk: exactly symmetric
    W = factorize(spd).compliance(B, 2.5)
    np.testing.assert_allclose(W, 2.5 * B.T @ np.linalg.solve(spd, B), rtol=1e-10)
    assert np.array_equal(W, W.T)
    # a nonsymmetric matrix whose lower triangle is positive definite is not taken for one
    assert type(factorize(np.tril(spd) + 5.0 * np.triu(np.ones((n, n)), 1))) is DenseLU
    # single precision and CSR input are factorised in double; the input is left as it was
    for A in (spd.astype(np.float32), sp.csr_matrix(spd.astype(np.float32))):
        before = A.copy()
        x = factorize(A).solve(b)
        np.testing.assert_allclose(spd @ x, b, atol=1e-4)
        assert (abs(A - before)).max() == 0.0


def test_the_lapack_kernels_agree_with_numpy():
    """integrator/lapack.py (LAPACK without the GIL): Cholesky, its solves and half solve,
    the LU and its solves, on vectors and Fortran-ordered matrices, against NumPy; a
    matrix that is not positive definite gives potrf's info > 0, a singular one getrf's."""
    from softgrains.integrator import lapack

    rng = np.random.default_rng(4)
    n = 17
    B = rng.standard_normal((n, n))
    spd = B @ B.T + n * np.eye(n)
    b, C = rng.standard_normal(n), np.asfortranarray(rng.standard_normal((n, 3)))
    L = np.array(spd, order="F")
    assert lapack.cholesky(lapack.DPOTRF, L) == 0
    np.testing.assert_allclose(np.tril(L), np.linalg.cholesky(spd), rtol=1e-12, atol=1e-12)
    for rhs in (b.copy(), C.copy(order="F")):
        assert lapack.cholesky_solve(lapack.DPOTRS, L, rhs) == 0
        np.testing.assert_allclose(spd @ rhs, b if rhs.ndim == 1 else C, atol=1e-10)
    Y = C.copy(order="F")
    lapack.lower_solve(lapack.DTRSM, L, Y)
    np.testing.assert_allclose(np.tril(L) @ Y, C, atol=1e-12)
    indefinite = np.array(spd - 100.0 * n * np.eye(n), order="F")
    assert lapack.cholesky(lapack.DPOTRF, indefinite) > 0
    general = np.array(B + n * np.eye(n), order="F")
    factors, pivots = general.copy(order="F"), np.zeros(n, np.int32)
    assert lapack.lu(lapack.DGETRF, factors, pivots) == 0
    for rhs in (b.copy(), C.copy(order="F")):
        assert lapack.lu_solve(lapack.DGETRS, factors, pivots, rhs) == 0
        np.testing.assert_allclose(general @ rhs, b if rhs.ndim == 1 else C, atol=1e-10)
    singular = general.copy(order="F")
    singular[:, 4] = 0.0
    assert lapack.lu(lapack.DGETRF, singular, pivots) == 5


def test_the_factorizations_run_concurrently_on_threads():
    """The factorizations and solves release the GIL (bodies are factorised on several
    threads): many solved on two threads at once give the serial results bit for bit."""
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(8)
    matrices = []
    for k in range(16):
        B = rng.standard_normal((40, 40))
        matrices.append(B @ B.T + 40 * np.eye(40) if k % 2 else B + 40 * np.eye(40))
    rhs = rng.standard_normal((40, 5))

    def solve(A):
        f = factorize(A)  # and the compliance (syrk) where A is positive definite
        return f.solve(rhs), (f.compliance(rhs, 0.5) if isinstance(f, DenseCholesky)
                              else np.zeros((5, 5)))

    serial = [solve(A) for A in matrices]
    with ThreadPoolExecutor(2) as pool:
        threaded = list(pool.map(solve, matrices))
    for (a, w), (b, v) in zip(serial, threaded, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(w, v)


def test_the_symmetry_test_on_blocks_agrees_with_the_dense_one():
    """factorize tests A's symmetry from its blocks when A is BSR in canonical form (no
    dense pass): the same answer as the dense test on a symmetric matrix, one with an
    asymmetric entry, one with a block whose mirror is missing, and (dense test) on a BSR
    matrix whose block columns are not sorted."""
    from softgrains.integrator.linear_solvers import _is_symmetric, _symmetric

    rng = np.random.default_rng(12)
    n = 24
    B = rng.standard_normal((n, n)) * (rng.random((n, n)) < 0.2)
    S = B + B.T + n * np.eye(n)
    asymmetric = S.copy()
    asymmetric[3, 10] += 1e-6
    lonely = S.copy()
    lonely[20, 2] = lonely[21, 3] = 0.0  # the block (10, 1) without its mirror (1, 10)
    lonely[2, 20] = 0.5
    for M, expected in ((S, True), (asymmetric, False), (lonely, False)):
        A = sp.bsr_matrix(M, blocksize=(2, 2))
        A.sort_indices()  # (SciPy's conversion from dense leaves them unsorted)
        assert A.has_canonical_format
        dense = np.asfortranarray(M)
        assert _is_symmetric(A, dense) == _symmetric(dense, 1e-12) == expected
    A = sp.bsr_matrix(S, blocksize=(2, 2))
    A.sort_indices()
    shuffled = sp.bsr_matrix((A.data[::-1].copy(), A.indices[::-1].copy(), A.indptr),
                             shape=A.shape)  # (row 0's blocks reversed, others moved)
    assert not shuffled.has_canonical_format
    assert _is_symmetric(shuffled, np.asfortranarray(shuffled.toarray())) == _symmetric(
        np.asfortranarray(shuffled.toarray()), 1e-12)


def test_site_columns_place_the_sites_on_the_free_unknowns():
    """site_columns: column i of E is row i of H (sites × the contact rows' dofs) placed at
    those dofs among all unknowns, zero at fixed dofs (duplicate CSR entries summed, as
    toarray does)."""
    rng = np.random.default_rng(2)
    H = sp.random(7, 6, density=0.5, format="csr", random_state=rng)
    H = sp.csr_matrix((np.r_[H.data, 1.5], np.r_[H.indices, 2], np.r_[H.indptr[:-1], H.nnz + 1]),
                      shape=H.shape)  # a duplicate entry (row 6, column 2)
    dofs = np.array([9, 3, 4, 11, 0, 7])
    free = np.ones(12, bool)
    free[4] = False
    E = np.full((12, 7), np.nan, order="F")
    site_columns(dofs, H.indptr, H.indices, H.data, free, E)
    expected = np.zeros((12, 7))
    expected[dofs] = H.toarray().T * free[dofs, None]
    np.testing.assert_array_equal(E, expected)


def test_sparse_times_is_scipys_product_to_the_bit():
    """linear_solvers.sparse_times (BodyStep.rigid_modes' products without SciPy's
    dispatch): H X as SciPy forms it, to the bit."""
    rng = np.random.default_rng(12)
    H = sp.random(30, 50, density=0.15, format="csr", random_state=3)
    X = rng.standard_normal((50, 3))
    np.testing.assert_array_equal(sparse_times(H, X), H @ X)

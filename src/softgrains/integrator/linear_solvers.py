"""Linear solves of the Newton systems A δu = −R (ALGORITHM.md §3).

- ``direct``: up to DENSE_LIMIT unknowns a dense factorization (LAPACK): A = L Lᵀ
  (Cholesky) where A is symmetric positive definite, as a body's Newton matrix mostly is
  (the Hessian of the step's potential; 96% of them in the frictionless compaction), else
  the LU; above DENSE_LIMIT the sparse LU (SuperLU through scipy.sparse.linalg.splu, A in
  CSC form).
- ``cg``: conjugate gradients preconditioned by the inverse d×d diagonal blocks of A
  (block Jacobi). A is symmetric: the tangent of a hyperelastic law plus a lumped mass.
- ``auto``: CG while it converges within ``CG_MAX_ITERATIONS``; the first time it does not
  (stiffness dominates the mass term at large Δt), switch that body to the direct solver for
  the rest of the run. benchmarks/bench_single_disk.py measured both (docs/dev-notes.md).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from softgrains.integrator import lapack

CG_MAX_ITERATIONS = 200
CG_RELATIVE_TOLERANCE = 1e-10
# a body with at most this many unknowns is factorised dense: a grain in contact needs its
# compliance at nearly all its rows ([A⁻¹]_cc, 235 of 262 columns for a D/h 10 grain of the
# dense compaction), which LAPACK's blocked solves give in half SuperLU's time (session 26:
# 0.126 s against 0.253 s for a step's 54 factorizations); at D/h 20 (grains of 600-1070
# unknowns, ~270 compliance columns) in under a third (session 38: 0.46 s against 1.64 s
# for the 30 grains' factorizations and compliances; 2.0-3.4× at 5% of the columns; 23
# against 71 ms at 1066 unknowns, benchmarks/compliance_paths.py; a free disk with n/4
# columns: 1.37× at 1242 unknowns, 1.13× at 3156): the dense work (n³/3 + n² per column)
# nears the sparse LU's at a few thousand unknowns, and a dense factor holds n² floats
# (18 MB at 1500)
DENSE_LIMIT = 1500
# a body with at most this many unknowns may have its Newton matrix's negative modes
# mirrored (a dense eigensolve, mirrored_negative_modes); larger ones take the projected
# tangent instead (coupling._switch_indefinite)
MIRROR_LIMIT = 600
NEGATIVE_MODE = 1e-12  # an eigenvalue below −this × max diag is a negative mode
# A is taken as symmetric (Cholesky tried) when |A_ij − A_ji| ≤ this × max |A_ij|: the
# Newton matrices are symmetric to round-off (a mirrored one to ~1e-16)
SYMMETRY_TOLERANCE = 1e-12


@njit(cache=True, nogil=True)
def _bsr_to_dense(indptr, indices, data, out):
    """out = the block-sparse matrix (indptr, indices, data[k] d × d) written densely
    (repeated blocks summed)."""
    d = data.shape[1]
    out[:] = 0.0
    for i in range(indptr.size - 1):
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            for a in range(d):
                for b in range(d):
                    out[i * d + a, j * d + b] += data[k, a, b]


def dense(A: sp.spmatrix | np.ndarray) -> np.ndarray:
    """A as a dense array (a BSR matrix of square blocks by a kernel that releases the
    GIL)."""
    if isinstance(A, sp.bsr_matrix) and A.blocksize[0] == A.blocksize[1]:
        out = np.empty(A.shape)
        _bsr_to_dense(A.indptr, A.indices, A.data, out)
        return out
    return A.toarray() if sp.issparse(A) else A


@njit(cache=True, nogil=True)
def _symmetric(A, tolerance):
    """Whether max |A_ij − A_ji| ≤ tolerance × max |A_ij| (A square; one pass over the
    pairs i ≥ j, by tiles so that both A_ij and A_ji are read from cache)."""
    n, tile = A.shape[0], 32
    scale, asymmetry = 0.0, 0.0
    for j0 in range(0, n, tile):
        for i0 in range(j0, n, tile):
            for j in range(j0, min(j0 + tile, n)):
                for i in range(max(i0, j), min(i0 + tile, n)):
                    lower, upper = A[i, j], A[j, i]
                    scale = max(scale, abs(lower), abs(upper))
                    asymmetry = max(asymmetry, abs(lower - upper))
    return asymmetry <= tolerance * scale


@njit(cache=True, nogil=True)
def _bsr_symmetric(indptr, indices, data, tolerance):
    """_symmetric for a block-sparse matrix of square blocks with sorted, distinct block
    columns per block row: each block B_ij against B_jiᵀ (found by bisection; a missing
    one is zero), without writing the matrix out."""
    d = data.shape[1]
    scale, asymmetry = 0.0, 0.0
    for i in range(indptr.size - 1):
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            lo, hi = indptr[j], indptr[j + 1]
            while lo < hi:  # the first block column ≥ i in block row j
                mid = (lo + hi) // 2
                if indices[mid] < i:
                    lo = mid + 1
                else:
                    hi = mid
            mirror = lo if lo < indptr[j + 1] and indices[lo] == i else -1
            for a in range(d):
                for b in range(d):
                    value = data[k, a, b]
                    other = data[mirror, b, a] if mirror >= 0 else 0.0
                    scale = max(scale, abs(value))
                    asymmetry = max(asymmetry, abs(value - other))
    return asymmetry <= tolerance * scale


def _is_symmetric(A: sp.spmatrix | np.ndarray, matrix: np.ndarray) -> bool:
    """Whether A (written densely as ``matrix``) is symmetric to SYMMETRY_TOLERANCE: from
    A's blocks where it is BSR in canonical form (a tenth of the dense test's time for a
    grain), else from ``matrix``."""
    if (isinstance(A, sp.bsr_matrix) and A.blocksize[0] == A.blocksize[1]
            and A.shape[0] == A.shape[1] and A.has_canonical_format):
        return bool(_bsr_symmetric(A.indptr, A.indices, A.data, SYMMETRY_TOLERANCE))
    return bool(_symmetric(matrix, SYMMETRY_TOLERANCE))


@njit(cache=True, nogil=True)
def _compliance(trsm, syrk, lower, B, alpha, Y, out):
    """out ← α (L⁻¹B)ᵀ(L⁻¹B) through Y ← L⁻¹B (B, Y and out Fortran-ordered)."""
    for j in range(B.shape[1]):  # (a slice assignment between Fortran arrays compiled ~2 s)
        for i in range(B.shape[0]):
            Y[i, j] = B[i, j]
    lapack.lower_solve(trsm, lower, Y)
    lapack.gram(syrk, Y, alpha, out)


@njit(cache=True, nogil=True)
def site_columns(dofs, indptr, indices, data, free, out):
    """out[dofs[j], i] = H_ij where dof dofs[j] is free (out zero elsewhere; H the CSR
    matrix (indptr, indices, data) of a body's contact sites on its contact rows' dofs,
    out (unknowns × sites) in Fortran order): the sites' columns Hᵀ on the unknowns
    (duplicate entries of H add up, as in H.toarray())."""
    out[:, :] = 0.0
    for i in range(indptr.shape[0] - 1):
        for q in range(indptr[i], indptr[i + 1]):
            dof = dofs[indices[q]]
            if free[dof]:
                out[dof, i] += data[q]


def sparse_times(H: sp.csr_matrix, X: np.ndarray) -> np.ndarray:
    """H X for a CSR matrix H and a dense X (n, m): SciPy's sums in SciPy's order (row by
    row, entries as stored) by a kernel, without SciPy's dispatch (~20 µs a call, twice
    per body and coupling iteration in BodyStep.rigid_modes)."""
    H = H.tocsr()  # (itself where it is CSR)
    out = np.zeros((H.shape[0], X.shape[1]))
    _csr_times_dense(H.indptr, H.indices, H.data, np.ascontiguousarray(X, float), out)
    return out


@njit(cache=True, nogil=True)
def _csr_times_dense(indptr, indices, data, X, out):
    """out += H X for H in CSR arrays, row by row, each row's entries in order."""
    for i in range(indptr.shape[0] - 1):
        for q in range(indptr[i], indptr[i + 1]):
            for k in range(X.shape[1]):
                out[i, k] += data[q] * X[indices[q], k]


class DenseCholesky:
    """A = L Lᵀ of a symmetric positive definite A (LAPACK potrf, lower triangle), with
    SuperLU's ``solve(b)`` (potrs) and the half solve ``L⁻¹ B`` (trsm), from which a
    compliance Bᵀ A⁻¹ B = (L⁻¹ B)ᵀ (L⁻¹ B) is formed symmetric and positive semidefinite by
    construction, at about half the work of the LU's two triangular solves. Build it with
    :meth:`attempt`: None where A is not positive definite. LAPACK runs without the GIL
    (integrator/lapack.py)."""

    def __init__(self, lower: np.ndarray) -> None:
        self.lower = lower

    @classmethod
    def attempt(cls, matrix: np.ndarray) -> DenseCholesky | None:
        """The factorization of ``matrix`` (Fortran order, overwritten), None where a pivot
        is not positive (or not finite)."""
        _fortran(matrix)
        if lapack.cholesky(lapack.DPOTRF, matrix) != 0:
            return None
        return cls(matrix)

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = np.array(b, float, order="F")
        info = lapack.cholesky_solve(lapack.DPOTRS, self.lower, x)
        if info != 0:
            raise RuntimeError(f"LAPACK potrs failed (info {info})")
        return x

    def half_solve(self, B: np.ndarray) -> np.ndarray:
        """L⁻¹ B (B a matrix)."""
        Y = np.array(B, float, order="F")
        lapack.lower_solve(lapack.DTRSM, self.lower, Y)
        return Y

    def compliance(self, B: np.ndarray, alpha: float = 1.0) -> np.ndarray:
        """α Bᵀ A⁻¹ B = α (L⁻¹B)ᵀ(L⁻¹B) (B a matrix), exactly symmetric: the product by
        BLAS syrk, which forms one triangle (half the work of a general product); the copy,
        the half solve and the product in one call that releases the GIL (on the threads
        of over_bodies the copy alone, made by NumPy, held it for a tenth of the call)."""
        B = np.asfortranarray(B, float)
        Y = np.empty(B.shape, order="F")
        out = np.empty((B.shape[1], B.shape[1]), order="F")
        _compliance(lapack.DTRSM, lapack.DSYRK, self.lower, B, float(alpha), Y, out)
        return out


class DenseLU:
    """A dense LU factorization with SuperLU's ``solve(b)`` (b a vector or a matrix): LAPACK's
    getrf and getrs called without the GIL (integrator/lapack.py; no warnings machinery,
    which is not thread-safe: bodies are factorised on several threads,
    threads.over_bodies)."""

    def __init__(self, A: sp.spmatrix | np.ndarray, overwrite: bool = False) -> None:
        """``overwrite``: A is a float64 Fortran-ordered array the factors may overwrite."""
        if overwrite:
            _fortran(A)
        matrix = A if overwrite else np.array(dense(A), float, order="F")
        self.pivots = np.zeros(matrix.shape[0], np.int32)
        self.lu = matrix
        if matrix.size == 0:  # (LAPACK refuses n = 0)
            return
        if matrix.shape[0] != matrix.shape[1]:
            raise ValueError(f"LU of a {matrix.shape} matrix: it must be square")
        info = lapack.lu(lapack.DGETRF, matrix, self.pivots)
        if info < 0:
            raise ValueError(f"LAPACK getrf: argument {-info} is invalid")
        if info > 0 or not np.all(np.isfinite(matrix)):
            raise RuntimeError("Factor is exactly singular")

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = np.array(b, float, order="F")
        if self.lu.size == 0:
            return x
        info = lapack.lu_solve(lapack.DGETRS, self.lu, self.pivots, x)
        if info != 0:
            raise RuntimeError(f"LAPACK getrs failed (info {info})")
        return x


def _fortran(matrix: np.ndarray) -> None:
    """The kernels of integrator/lapack.py read a square float64 Fortran-ordered array."""
    if (matrix.dtype != np.float64 or not matrix.flags.f_contiguous or matrix.ndim != 2
            or matrix.shape[0] != matrix.shape[1]):
        raise ValueError("a square float64 matrix in Fortran order is required")


def factorize(A: sp.spmatrix | np.ndarray):
    """A factorization of A with ``.solve(b)``: for a dense A or up to DENSE_LIMIT unknowns
    the Cholesky factorization where A is symmetric positive definite, else the dense LU;
    above, SuperLU."""
    if A.shape[0] <= DENSE_LIMIT or not sp.issparse(A):
        rows = _rows_copy(A)
        if rows.size and _is_symmetric(A, rows):
            # A = Aᵀ: its rows in C order, read in Fortran order, are A itself. (Writing a
            # BSR matrix's blocks row by row is ~4× faster than column by column: 0.08
            # against 0.30 ms at 264 unknowns within a run, session 35.)
            cholesky = DenseCholesky.attempt(rows.T)  # (overwrites it)
            if cholesky is not None:
                return cholesky
            return DenseLU(A)  # (A itself, not Aᵀ: equal only to the symmetry tolerance)
        return DenseLU(np.asfortranarray(rows), overwrite=True)
    return spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A")


def _rows_copy(A: sp.spmatrix | np.ndarray) -> np.ndarray:
    """A new float64 C-ordered dense copy of A."""
    rows = dense(A)
    return np.array(rows, float, order="C") if rows is A or rows.dtype != np.float64 else rows


def mirrored_negative_modes(A: sp.spmatrix, m: np.ndarray) -> np.ndarray | None:
    """A⁺ = A + Σ_{λ<0} 2|λ| M v vᵀ M (dense) over the eigenpairs A v = λ M v with
    M = diag(m) > 0, A symmetric: the negative modes mirrored, the others unchanged (from
    B = M^-½ A M^-½ = Σ λ u uᵀ, v = M^-½ u). None where A has no negative mode."""
    root = np.sqrt(m)
    full = dense(A)
    B = full / root[:, None] / root[None, :]
    B = 0.5 * (B + B.T)
    # below round-off of B's scale: a zero eigenvalue is no negative mode
    below = -NEGATIVE_MODE * float(np.abs(np.diagonal(B)).max(initial=0.0))
    lam, U = sla.eigh(B, subset_by_value=(-np.inf, below), check_finite=False)
    if lam.size == 0:
        return None
    MV = U * root[:, None]  # M v = M^½ u
    return full + (MV * (-2.0 * lam)) @ MV.T


def _block_jacobi(A: sp.bsr_matrix, diag_slot: np.ndarray) -> sp.bsr_matrix:
    """Inverse of A's diagonal blocks, as a block-diagonal BSR matrix."""
    blocks = np.linalg.inv(A.data[diag_slot])
    n = blocks.shape[0]
    return sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=A.shape)


class LinearSolver:
    """Solves one body's Newton systems; remembers whether CG has failed for it."""

    def __init__(self, kind: str) -> None:
        if kind not in ("auto", "direct", "cg"):
            raise ValueError(f"unknown linear solver {kind!r}")
        self.kind = kind
        self.use_direct = kind == "direct"
        self.last_method = ""
        self.last_iterations = 0
        self.last_factorization = None  # of the last direct solve (contact reuses it)

    def solve(self, A: sp.bsr_matrix | np.ndarray, b: np.ndarray, diag_slot: np.ndarray,
              direct: bool = False) -> np.ndarray:
        """x = A⁻¹ b; ``direct`` forces the LU (a body in contact needs it for its Delassus
        compliance anyway: CG first would be spent for nothing), as does a dense A (a
        Newton matrix with mirrored negative modes)."""
        if not (self.use_direct or direct or not sp.issparse(A)):  # a dense A: the LU
            x, info, its = self._cg(A, b, diag_slot)
            if info == 0:
                self.last_method, self.last_iterations = "cg", its
                self.last_factorization = None
                return x
            if self.kind == "cg":
                raise np.linalg.LinAlgError(
                    f"CG did not converge in {CG_MAX_ITERATIONS} iterations "
                    "(try linear_solver = \"direct\" or \"auto\")")
            self.use_direct = True
        self.last_method, self.last_iterations = "direct", 1
        self.last_factorization = factorize(A)
        return self.last_factorization.solve(b)

    @staticmethod
    def _cg(A, b, diag_slot):
        count = [0]

        def tick(_):
            count[0] += 1

        M = _block_jacobi(A, diag_slot)
        x, info = spla.cg(A, b, rtol=CG_RELATIVE_TOLERANCE, atol=0.0,
                          maxiter=CG_MAX_ITERATIONS, M=M, callback=tick)
        return x, info, count[0]

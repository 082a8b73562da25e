"""A_s, the momentum form's Newton matrix with the rigid rotations decoupled
(rotations.py), factorised as a band matrix and a rank-2k update (issue 14).

    A_s = PᵀĀP + Q B Qᵀ = Ā + U C Uᵀ,   U = [Q, ĀR],   C = [[RᵀĀR + B, −I], [−I, 0]]

(Ā = ½(A + Aᵀ), P = I − R Qᵀ; R the k rigid rotations, B their block; k = 1 in 2D, 3 in
3D). Ā has the band of a body's node box: a grain's nodes are numbered row by row, and the
B-spline stencils couple nodes at most two rows apart, so its lower bandwidth kd is about
two rows of the box (56 of 262 unknowns for a grain at D/h 10, 96 of 804 at D/h 20),
while A_s's rank-2k part fills the whole matrix. With Ā = L Lᵀ (LAPACK's band Cholesky,
n kd² work against n³/3 for A_s dense) and the Woodbury identity

    A_s⁻¹ = Ā⁻¹ − Ā⁻¹U (C⁻¹ + UᵀĀ⁻¹U)⁻¹ UᵀĀ⁻¹,   C⁻¹ = [[0, −I], [−I, −(RᵀĀR + B)]]

a solve is a band solve (n kd against n² work) plus 2k columns. Ā positive definite makes
A_s positive definite (xᵀA_s x = (Px)ᵀĀ(Px) + (Qᵀx)ᵀB(Qᵀx), zero only for x = 0 since
PR = 0 and QᵀR = I); where Ā is not, the band Cholesky says so and the caller factorises
A_s dense (its Cholesky or LU). Solves agree with the dense Cholesky of A_s to 1e-13–6e-12
(relative, the dense compaction's grains; 4.5e-11 at a quasi-static squeeze step, cond
2.5e7; tests/kernels/test_momentum_form.py). The contacts' compliance BᵀA_s⁻¹B takes
L⁻¹B by rows from each site column's first entry (:func:`_lower_solve_rows`: 2.2× faster
than LAPACK's band solve, tbtrs, on a grain's site columns).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from softgrains.integrator import lapack

# the band path is taken where the band (kd + 1 rows) is at most this fraction of the
# unknowns: its factorization's work n kd² against the dense A_s's n³/3, with its 2k extra
# solves (not tuned: measured at 0.21, D/h 10, a direction 0.40 against 0.61 ms, and 0.12,
# D/h 20, 1.5 against 6.6 ms)
BAND_FRACTION = 0.35
# above DENSE_LIMIT (where SuperLU factorised A_s) the band is taken only where
# kd ≤ NARROW_BAND √(d n): the band of a body about as wide as it is tall on a 2D grid
# (disks at D/h 40 and 80: kd 177 and 337 against 230 and 443, factorised 6.5 and 9×
# faster than by SuperLU). A 3D body's band grows as n^(2/3), and a body long along the
# grid's fastest axis has a band of that length: SuperLU's fill grows more slowly (a
# 200 × 10-cell slab along x: kd 817, n kd² ~ 3.5 GFlop)
NARROW_BAND = 3.0


def band_pays(n: int, kd: int, d: int, dense_limit: int) -> bool:
    """Whether A_s (n unknowns, dimension d) is factorised as its band (lower bandwidth kd)
    rather than dense (n ≤ ``dense_limit``) or by SuperLU (above): see BAND_FRACTION and
    NARROW_BAND."""
    if kd + 1 > BAND_FRACTION * n:
        return False
    return n <= dense_limit or kd <= NARROW_BAND * np.sqrt(d * n)


def lower_bandwidth(indptr: np.ndarray, indices: np.ndarray, d: int) -> int:
    """kd of a BSR pattern of d × d blocks: the largest i − j of an entry (i, j) with
    i ≥ j, counting whole blocks."""
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    return int(np.abs(rows - indices).max(initial=0)) * d + d - 1


@njit(cache=True, nogil=True)
def _symmetric_band_times(indptr, indices, data, X, ab, out):
    """In one pass over the BSR matrix A (indptr, indices, data): ab ← the lower band of
    Ā = ½(A + Aᵀ) (ab[i − j, j] = Ā_ij, (kd + 1) × n; kd must hold A's pattern,
    :func:`lower_bandwidth`) and out ← Ā X (X and out n × m, m ≥ 0)."""
    d = data.shape[1]
    ab[:, :] = 0.0
    out[:, :] = 0.0
    for r in range(indptr.shape[0] - 1):
        for q in range(indptr[r], indptr[r + 1]):
            c = indices[q]
            for i in range(d):
                for j in range(d):
                    row, col = r * d + i, c * d + j
                    half = 0.5 * data[q, i, j]
                    if row >= col:
                        ab[row - col, col] += half
                    if col >= row:
                        ab[col - row, row] += half
                    for a in range(X.shape[1]):
                        out[row, a] += half * X[col, a]
                        out[col, a] += half * X[row, a]


@njit(cache=True, nogil=True)
def factorize(pbtrf, pbtrs, indptr, indices, data, R, Q, block, ab, U, BU, capacitance):
    """A_s of the module docstring from the BSR A: ab ← L (Ā = L Lᵀ, band storage), U =
    [Q, ĀR], BU = Ā⁻¹U, ``capacitance`` = (C⁻¹ + UᵀĀ⁻¹U)⁻¹ (U, BU n × 2k in Fortran order,
    ``block`` B k × k). Returns the band Cholesky's info (≠ 0: Ā is not positive definite;
    the rest is then unset)."""
    n, k = R.shape
    AR = np.empty((n, k))
    _symmetric_band_times(indptr, indices, data, R, ab, AR)
    info = lapack.band_cholesky(pbtrf, ab)
    if info != 0:
        return info
    for i in range(n):
        for a in range(k):
            U[i, a] = Q[i, a]
            U[i, k + a] = AR[i, a]
            BU[i, a] = Q[i, a]
            BU[i, k + a] = AR[i, a]
    lapack.band_cholesky_solve(pbtrs, ab, BU)
    middle = np.zeros((2 * k, 2 * k))  # C⁻¹ + UᵀĀ⁻¹U
    for a in range(k):
        middle[a, k + a] -= 1.0
        middle[k + a, a] -= 1.0
        for b in range(k):
            acc = block[a, b]
            for i in range(n):
                acc += R[i, a] * AR[i, b]
            middle[k + a, k + b] -= acc
    for a in range(2 * k):
        for b in range(2 * k):
            acc = 0.0
            for i in range(n):
                acc += U[i, a] * BU[i, b]
            middle[a, b] += acc
    inverse = np.linalg.inv(middle)
    for a in range(2 * k):  # (symmetric in exact arithmetic: made so)
        for b in range(2 * k):
            capacitance[a, b] = 0.5 * (inverse[a, b] + inverse[b, a])
    return 0


@njit(cache=True, nogil=True)
def solve(pbtrs, ab, U, BU, capacitance, x):
    """x ← A_s⁻¹ x (x a vector): the band solve, then the Woodbury correction. Returns the
    band solve's LAPACK info."""
    info = lapack.band_cholesky_solve(pbtrs, ab, x)
    m = U.shape[1]
    t = np.zeros(m)
    for a in range(m):
        acc = 0.0
        for i in range(x.shape[0]):
            acc += U[i, a] * x[i]
        t[a] = acc
    s = capacitance @ t
    for i in range(x.shape[0]):
        acc = 0.0
        for a in range(m):
            acc += BU[i, a] * s[a]
        x[i] -= acc
    return info


@njit(cache=True, nogil=True)
def _solve_columns(pbtrs, ab, U, BU, capacitance, X):
    """X ← A_s⁻¹ X (X n × m, Fortran order), column by column as :func:`solve`. Returns the
    first failed band solve's LAPACK info, else 0."""
    for j in range(X.shape[1]):
        info = solve(pbtrs, ab, U, BU, capacitance, X[:, j])
        if info != 0:
            return info
    return 0


@njit(cache=True, nogil=True)
def _lower_solve_rows(ab, B, order, starts, Y):
    """Y ← L⁻¹ B[:, order] (Y n × m in C order: a row's columns contiguous), where column
    order[j] of B is zero above row starts[j] (non-decreasing): forward substitution row
    by row, each row's update of the kd rows below it applied to the columns begun by
    then, which are contiguous (the same operations per column as LAPACK's band solve,
    tbsv, without the rows above a column's first entry: a grain's site columns begin
    0.38 of the way down on average)."""
    n, m = Y.shape
    kd = ab.shape[0] - 1
    for i in range(n):
        for j in range(m):
            Y[i, j] = B[i, order[j]]
    active = 0
    for k in range(n):
        while active < m and starts[active] <= k:
            active += 1
        if active == 0:
            continue
        pivot = ab[0, k]
        for j in range(active):
            Y[k, j] /= pivot
        for i in range(1, min(kd, n - 1 - k) + 1):
            factor = ab[i, k]
            if factor != 0.0:
                for j in range(active):
                    Y[k + i, j] -= factor * Y[k, j]


@njit(cache=True, nogil=True)
def _compliance(syrk, ab, BU, capacitance, B, alpha, Y, out):
    """out ← α BᵀA_s⁻¹B = α((L⁻¹B)ᵀ(L⁻¹B) − V cap Vᵀ), V = BᵀĀ⁻¹U (B and out Fortran
    order, Y n × m scratch), exactly symmetric."""
    n, m = B.shape
    starts = np.full(m, n, np.int64)  # each column's first nonzero row
    for j in range(m):
        for i in range(n):
            if B[i, j] != 0.0:
                starts[j] = i
                break
    order = np.argsort(starts, kind="mergesort")
    sorted_starts = starts[order]
    _lower_solve_rows(ab, B, order, sorted_starts, Y)
    gram = np.empty((m, m))  # (symmetric: its transpose is the Fortran array syrk fills)
    lapack.gram_rows(syrk, Y, alpha, gram.T)
    for b in range(m):
        for a in range(m):
            out[order[a], order[b]] = gram[a, b]
    V = B.T @ BU
    correction = V @ capacitance @ V.T
    for j in range(m):
        for i in range(j, m):
            value = alpha * 0.5 * (correction[i, j] + correction[j, i])
            out[i, j] -= value
            if i != j:
                out[j, i] = out[i, j]


def decoupled(A, rotations, block: np.ndarray, kd: int) -> BandedDecoupled | None:
    """A_s of the BSR Newton matrix A (rotations.RigidRotations ``rotations``, their block
    B) factorised as above, or None where Ā is not positive definite."""
    factors = BandedDecoupled.workspace(A.shape[0], kd, rotations.fields.shape[1])
    if factorize(lapack.DPBTRF, lapack.DPBTRS, A.indptr, A.indices, A.data,
                 rotations.fields, rotations.dual, np.asarray(block, float), *factors) != 0:
        return None
    return BandedDecoupled(*factors)


class BandedDecoupled:
    """The factorization of A_s of the module docstring, with DenseCholesky's interface
    (``solve``, ``compliance``); A_s is positive definite."""

    def __init__(self, ab: np.ndarray, U: np.ndarray, BU: np.ndarray,
                 capacitance: np.ndarray) -> None:
        self.ab, self.U, self.BU, self.capacitance = ab, U, BU, capacitance

    @classmethod
    def workspace(cls, n: int, kd: int, k: int) -> tuple[np.ndarray, ...]:
        """Arrays for :func:`factorize`: ab, U, BU, capacitance."""
        return (np.empty((kd + 1, n), order="F"), np.empty((n, 2 * k), order="F"),
                np.empty((n, 2 * k), order="F"), np.empty((2 * k, 2 * k)))

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = np.array(b, float, order="F")
        kernel = solve if x.ndim == 1 else _solve_columns
        info = kernel(lapack.DPBTRS, self.ab, self.U, self.BU, self.capacitance, x)
        if info != 0:
            raise RuntimeError(f"LAPACK pbtrs failed (info {info})")
        return x

    def compliance(self, B: np.ndarray, alpha: float = 1.0) -> np.ndarray:
        """α Bᵀ A_s⁻¹ B (B a matrix), exactly symmetric (its band part by BLAS syrk)."""
        B = np.asfortranarray(B, float)
        Y = np.empty(B.shape)
        out = np.empty((B.shape[1], B.shape[1]), order="F")
        _compliance(lapack.DSYRK, self.ab, self.BU, self.capacitance, B, float(alpha), Y,
                    out)
        return out

"""LAPACK and BLAS (dense and band routines) called from Numba kernels that release the
GIL.

SciPy's f2py wrappers (scipy.linalg.lapack, scipy.linalg.blas) hold the GIL while LAPACK
runs, so the bodies' factorizations on the threads of :func:`softgrains.threads.over_bodies`
ran one at a time: two threads were no faster than one (measured: 200 Cholesky
factorizations and half solves of a 262-unknown grain, 0.41 s serial, 0.43 s on two
threads; through these kernels 0.38 s and 0.20 s). The routines are SciPy's own
(scipy.linalg.cython_lapack / cython_blas, 32-bit integers), passed to each kernel as a
first-class function argument: a function address read as a global would keep Numba from
caching the kernel.

Every matrix is in Fortran (column) order (:func:`gram_rows` reads a C-ordered one as its
transpose); band matrices are LAPACK's lower band storage ab[i − j, j] = a_ij. The kernels
work in place. Scalars go to Fortran by reference, through small arrays.
"""

from __future__ import annotations

import ctypes

import numpy as np
from numba import njit
from numba.extending import get_cython_function_address

_P = ctypes.c_void_p


def _routine(module: str, name: str, arguments: int):
    return ctypes.CFUNCTYPE(None, *([_P] * arguments))(
        get_cython_function_address(f"scipy.linalg.cython_{module}", name))


# (uplo, n, a, lda, info)
DPOTRF = _routine("lapack", "dpotrf", 5)
# (uplo, n, nrhs, a, lda, b, ldb, info)
DPOTRS = _routine("lapack", "dpotrs", 8)
# (side, uplo, transa, diag, m, n, alpha, a, lda, b, ldb)
DTRSM = _routine("blas", "dtrsm", 11)
# (uplo, trans, n, k, alpha, a, lda, beta, c, ldc)
DSYRK = _routine("blas", "dsyrk", 10)
# (m, n, a, lda, ipiv, info)
DGETRF = _routine("lapack", "dgetrf", 6)
# (trans, n, nrhs, a, lda, ipiv, b, ldb, info)
DGETRS = _routine("lapack", "dgetrs", 9)
# band storage (ab[i − j, j] = a_ij for j ≤ i ≤ j + kd, (kd + 1) × n): (uplo, n, kd, ab,
# ldab, info)
DPBTRF = _routine("lapack", "dpbtrf", 6)
# (uplo, n, kd, nrhs, ab, ldab, b, ldb, info)
DPBTRS = _routine("lapack", "dpbtrs", 9)

_LOWER, _LEFT, _NO, _NOT_UNIT, _TRANSPOSED = ord("L"), ord("L"), ord("N"), ord("N"), ord("T")


@njit(cache=True, nogil=True)
def _columns(b):
    """The right-hand sides of b: its columns, 1 for a vector."""
    return 1 if b.ndim == 1 else b.shape[1]


@njit(cache=True, nogil=True)
def cholesky(potrf, a):
    """a ← L (lower triangle; the upper is left as it was) with a = L Lᵀ. Returns LAPACK's
    info (> 0: the leading minor of that order is not positive definite), or −1 where a
    pivot is not finite."""
    n = a.shape[0]
    chars = np.array([_LOWER], np.uint8)
    ints = np.array([n, max(n, 1), 0], np.int32)  # n, lda, info
    potrf(chars.ctypes.data, ints[0:1].ctypes.data, a.ctypes.data, ints[1:2].ctypes.data,
          ints[2:3].ctypes.data)
    if ints[2] != 0:
        return ints[2]
    for i in range(n):
        if not np.isfinite(a[i, i]):
            return -1
    return 0


@njit(cache=True, nogil=True)
def cholesky_solve(potrs, lower, b):
    """b ← A⁻¹ b with A = L Lᵀ (``lower``: :func:`cholesky`'s a); b a vector or a
    Fortran-ordered matrix. Returns LAPACK's info."""
    n = lower.shape[0]
    chars = np.array([_LOWER], np.uint8)
    ints = np.array([n, _columns(b), max(n, 1), max(n, 1), 0], np.int32)
    potrs(chars.ctypes.data, ints[0:1].ctypes.data, ints[1:2].ctypes.data,
          lower.ctypes.data, ints[2:3].ctypes.data, b.ctypes.data, ints[3:4].ctypes.data,
          ints[4:5].ctypes.data)
    return ints[4]


@njit(cache=True, nogil=True)
def lower_solve(trsm, lower, b):
    """b ← L⁻¹ b (``lower``: :func:`cholesky`'s a; b Fortran-ordered, n × k)."""
    n = lower.shape[0]
    chars = np.array([_LEFT, _LOWER, _NO, _NOT_UNIT], np.uint8)
    ints = np.array([n, _columns(b), max(n, 1), max(n, 1)], np.int32)
    alpha = np.ones(1)
    trsm(chars[0:1].ctypes.data, chars[1:2].ctypes.data, chars[2:3].ctypes.data,
         chars[3:4].ctypes.data, ints[0:1].ctypes.data, ints[1:2].ctypes.data,
         alpha.ctypes.data, lower.ctypes.data, ints[2:3].ctypes.data, b.ctypes.data,
         ints[3:4].ctypes.data)


@njit(cache=True, nogil=True)
def lu(getrf, a, pivots):
    """a ← its LU factors, ``pivots`` (int32, n) the row interchanges (1-based, LAPACK's).
    Returns LAPACK's info (> 0: a zero pivot, a singular matrix)."""
    n = a.shape[0]
    ints = np.array([n, n, max(n, 1), 0], np.int32)  # m, n, lda, info
    getrf(ints[0:1].ctypes.data, ints[1:2].ctypes.data, a.ctypes.data, ints[2:3].ctypes.data,
          pivots.ctypes.data, ints[3:4].ctypes.data)
    return ints[3]


@njit(cache=True, nogil=True)
def lu_solve(getrs, factors, pivots, b):
    """b ← A⁻¹ b from :func:`lu`'s factors and pivots; b a vector or a Fortran-ordered
    matrix. Returns LAPACK's info."""
    n = factors.shape[0]
    chars = np.array([_NO], np.uint8)
    ints = np.array([n, _columns(b), max(n, 1), max(n, 1), 0], np.int32)
    getrs(chars.ctypes.data, ints[0:1].ctypes.data, ints[1:2].ctypes.data,
          factors.ctypes.data, ints[2:3].ctypes.data, pivots.ctypes.data, b.ctypes.data,
          ints[3:4].ctypes.data, ints[4:5].ctypes.data)
    return ints[4]


@njit(cache=True, nogil=True)
def _lower_gram(syrk, trans, k, n, lda, y, alpha, out):
    """out ← α yᵀy (k × k, Fortran order) by BLAS syrk: y's memory read as the n × k
    Fortran matrix y (``trans`` "T", lda n) or as its k × n transpose (``trans`` "N", lda
    k); the lower triangle computed, the upper copied from it (exactly symmetric)."""
    chars = np.array([_LOWER, trans], np.uint8)
    ints = np.array([k, n, lda, max(k, 1)], np.int32)  # n, k, lda, ldc (BLAS names)
    scalars = np.array([alpha, 0.0])
    syrk(chars[0:1].ctypes.data, chars[1:2].ctypes.data, ints[0:1].ctypes.data,
         ints[1:2].ctypes.data, scalars[0:1].ctypes.data, y.ctypes.data, ints[2:3].ctypes.data,
         scalars[1:2].ctypes.data, out.ctypes.data, ints[3:4].ctypes.data)
    for j in range(k):  # out is Fortran-ordered: out[i, j], i ≥ j, is the lower triangle
        for i in range(j + 1, k):
            out[j, i] = out[i, j]


@njit(cache=True, nogil=True)
def gram(syrk, y, alpha, out):
    """out ← α yᵀy (y Fortran-ordered, n × k; out k × k): the lower triangle by syrk
    (half of the product's work), the upper copied from it, so out is exactly symmetric."""
    n, k = y.shape
    _lower_gram(syrk, _TRANSPOSED, k, n, max(n, 1), y, alpha, out)


@njit(cache=True, nogil=True)
def band_cholesky(pbtrf, ab):
    """ab ← L in the same band storage, for the symmetric band matrix A = L Lᵀ given by its
    lower band ab ((kd + 1) × n, Fortran order: ab[i − j, j] = a_ij, j ≤ i ≤ j + kd).
    Returns LAPACK's info (> 0: not positive definite), or −1 where a pivot is not
    finite."""
    kd, n = ab.shape[0] - 1, ab.shape[1]
    chars = np.array([_LOWER], np.uint8)
    ints = np.array([n, kd, max(kd + 1, 1), 0], np.int32)  # n, kd, ldab, info
    pbtrf(chars.ctypes.data, ints[0:1].ctypes.data, ints[1:2].ctypes.data, ab.ctypes.data,
          ints[2:3].ctypes.data, ints[3:4].ctypes.data)
    if ints[3] != 0:
        return ints[3]
    for j in range(n):
        if not np.isfinite(ab[0, j]):
            return -1
    return 0


@njit(cache=True, nogil=True)
def band_cholesky_solve(pbtrs, ab, b):
    """b ← A⁻¹ b with A = L Lᵀ (``ab``: :func:`band_cholesky`'s); b a vector or a
    Fortran-ordered matrix. Returns LAPACK's info."""
    kd, n = ab.shape[0] - 1, ab.shape[1]
    chars = np.array([_LOWER], np.uint8)
    ints = np.array([n, kd, _columns(b), max(kd + 1, 1), max(n, 1), 0], np.int32)
    pbtrs(chars.ctypes.data, ints[0:1].ctypes.data, ints[1:2].ctypes.data,
          ints[2:3].ctypes.data, ab.ctypes.data, ints[3:4].ctypes.data, b.ctypes.data,
          ints[4:5].ctypes.data, ints[5:6].ctypes.data)
    return ints[5]


@njit(cache=True, nogil=True)
def gram_rows(syrk, y, alpha, out):
    """out ← α yᵀy for y in C order (n × k: its memory is yᵀ in Fortran order; out k × k,
    Fortran order), as :func:`gram`."""
    n, k = y.shape
    _lower_gram(syrk, _NO, k, n, max(k, 1), y, alpha, out)

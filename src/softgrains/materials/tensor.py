"""Allocation-free small-matrix helpers for per-point kernels (2D closed forms, 3D cofactors).

The 3D forms sit in functions of their own that are not inlined: keeping them out of the 2D
path makes the inlined 2D code several times faster in the per-point kernels.
"""

from numba import njit


@njit(cache=True)
def _determinant3(F):
    return (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
            - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
            + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))


@njit(cache=True)
def _inverse3(F, out):
    det = _determinant3(F)
    r = 1.0 / det if det != 0.0 else 0.0
    for i in range(3):
        for j in range(3):
            i1, i2 = (j + 1) % 3, (j + 2) % 3
            j1, j2 = (i + 1) % 3, (i + 2) % 3
            out[i, j] = (F[i1, j1] * F[i2, j2] - F[i1, j2] * F[i2, j1]) * r
    return det


@njit(cache=True, inline="always")
def determinant(F):
    """det F for d = 2 or 3."""
    if F.shape[0] == 2:
        return F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    return _determinant3(F)


@njit(cache=True, inline="always")
def inverse(F, out):
    """Write F⁻¹ into out (d = 2 or 3); return det F (callers must reject det F ≤ 0)."""
    if F.shape[0] != 2:
        return _inverse3(F, out)
    det = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    r = 1.0 / det if det != 0.0 else 0.0
    out[0, 0] = F[1, 1] * r
    out[0, 1] = -F[0, 1] * r
    out[1, 0] = -F[1, 0] * r
    out[1, 1] = F[0, 0] * r
    return det

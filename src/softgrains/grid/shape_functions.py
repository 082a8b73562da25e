"""Shape functions on the uniform lattice and each point's stencil (ALGORITHM.md §2).

Tensor-product functions N_I(x) = Π_j φ((x_j − X_I,j)/h):
- ``linear`` hats (code 0, stencil width s = 2): φ(ξ) = 1 − |ξ| for |ξ| < 1;
- ``bspline2`` quadratic B-splines (code 1, s = 3):
  φ(ξ) = 3/4 − ξ² for |ξ| < 1/2,  ½(3/2 − |ξ|)² for 1/2 ≤ |ξ| < 3/2.
A point's stencil is the s^d nodes starting at its base node; entry k of the stencil is the
node base + (k_0, k_1, ...) with k_j = (k // s^j) % s. Gradients are ∇N_I(x_p); note that
∇N_I(x_p) points from the point towards node I.
"""

import numpy as np
from numba import njit, prange

from softgrains.threads import parallel_kernel

SHAPE_FUNCTIONS = {"linear": 0, "bspline2": 1}


def stencil_width(kind: int) -> int:
    """Nodes per dimension that a point touches."""
    return 2 if kind == 0 else 3


@njit(cache=True, inline="always")
def weights_1d(kind, xi, w, dw, inv_h):
    """Weights and derivatives along one axis; xi = (x − origin)/h. Returns the base node."""
    if kind == 0:
        base = int(np.floor(xi))
        f = xi - base
        w[0] = 1.0 - f
        w[1] = f
        dw[0] = -inv_h
        dw[1] = inv_h
        return base
    base = int(np.floor(xi - 0.5))
    f = xi - base  # in [0.5, 1.5)
    w[0] = 0.5 * (1.5 - f) ** 2
    w[1] = 0.75 - (f - 1.0) ** 2
    w[2] = 0.5 * (f - 0.5) ** 2
    dw[0] = -(1.5 - f) * inv_h
    dw[1] = -2.0 * (f - 1.0) * inv_h
    dw[2] = (f - 0.5) * inv_h
    return base


@parallel_kernel(cache=True, nogil=True)
def compute_stencils(x, origin, h, kind, base, N, dN):
    """For every point: base node (n, d), N (n, s^d) and ∇N (n, s^d, d) at positions x."""
    n, d = x.shape
    s = 2 if kind == 0 else 3
    inv_h = 1.0 / h
    for p in prange(n):
        w = np.empty((d, s))
        dw = np.empty((d, s))
        for j in range(d):
            base[p, j] = weights_1d(kind, (x[p, j] - origin[j]) * inv_h, w[j], dw[j], inv_h)
        for k in range(s**d):
            val = 1.0
            rem = k
            for j in range(d):
                val *= w[j, rem % s]
                rem //= s
            N[p, k] = val
            for g in range(d):
                prod = 1.0
                rem = k
                for j in range(d):
                    kj = rem % s
                    prod *= dw[j, kj] if j == g else w[j, kj]
                    rem //= s
                dN[p, k, g] = prod

"""Isotropic linear elasticity (small strain; for checks against analytic solutions).

    ε = ½(F + Fᵀ) − I,   σ = λ tr ε I + 2μ ε,   W = ½ λ (tr ε)² + μ ε:ε
    The stress is used as the first Piola–Kirchhoff stress: P = σ, A = C
    (geometrically linear, not objective: use only for small rotations).
    Plane strain: σ_zz = λ tr ε = ν (σ_xx + σ_yy).
"""

from numba import njit

from softgrains.materials.tensor import determinant


@njit(cache=True, inline="always")
def pk1_and_tangent(F, lam, mu, P, A, Finv, tangent):
    """Fill P = σ(ε(F)) and, if ``tangent``, A = C; return det F. Finv is unused."""
    d = F.shape[0]
    tr = 0.0
    for i in range(d):
        tr += F[i, i] - 1.0
    for i in range(d):
        for a in range(d):
            eps = 0.5 * (F[i, a] + F[a, i])
            if i == a:
                eps -= 1.0
            P[i, a] = 2.0 * mu * eps
            if i == a:
                P[i, a] += lam * tr
    if not tangent:
        return determinant(F)
    for i in range(d):
        for a in range(d):
            for k in range(d):
                for b in range(d):
                    val = 0.0
                    if i == a and k == b:
                        val += lam
                    if i == k and a == b:
                        val += mu
                    if i == b and a == k:
                        val += mu
                    A[i, a, k, b] = val
    return determinant(F)


@njit(cache=True, inline="always")
def strain_energy(F, lam, mu):
    """W = ½ λ (tr ε)² + μ ε:ε per unit reference volume."""
    d = F.shape[0]
    tr = 0.0
    ee = 0.0
    for i in range(d):
        tr += F[i, i] - 1.0
        for a in range(d):
            eps = 0.5 * (F[i, a] + F[a, i])
            if i == a:
                eps -= 1.0
            ee += eps * eps
    return 0.5 * lam * tr * tr + mu * ee


@njit(cache=True, inline="always")
def out_of_plane_stress(F, lam, mu):
    """σ_zz = λ tr ε in plane strain."""
    d = F.shape[0]
    tr = 0.0
    for i in range(d):
        tr += F[i, i] - 1.0
    return lam * tr

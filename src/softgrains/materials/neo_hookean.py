"""Compressible neo-Hookean law (ALGORITHM.md §3), total Lagrangian form.

    W(F) = μ/2 (tr FᵀF − d) − μ ln J + λ/2 (ln J)²
    P    = μ (F − F⁻ᵀ) + λ ln J F⁻ᵀ                    (first Piola–Kirchhoff)
    A_iJkL = ∂P_iJ/∂F_kL = μ δ_ik δ_JL + λ F⁻¹_Ji F⁻¹_Lk − (λ ln J − μ) F⁻¹_Jk F⁻¹_Li
    σ    = P Fᵀ / J,  and in plane strain σ_zz = λ ln J / J   (b_zz = 1)

Equivalent to τ = μ(b − I) + λ ln J I. In 2D the out-of-plane stretch is 1, so the 2D formulas
are the plane-strain ones (tr C − 2 in W).
"""

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _inverse(F):
    d = F.shape[0]
    if d == 2:
        det = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        inv = np.empty((2, 2))
        inv[0, 0] = F[1, 1] / det
        inv[0, 1] = -F[0, 1] / det
        inv[1, 0] = -F[1, 0] / det
        inv[1, 1] = F[0, 0] / det
        return inv, det
    return np.linalg.inv(F), np.linalg.det(F)


@njit(cache=True)
def pk1_and_tangent(F, lam, mu, P, A):
    """Fill P (d×d) and A (d×d×d×d) for deformation gradient F; return J."""
    d = F.shape[0]
    Finv, J = _inverse(F)
    if J <= 0.0:
        return J
    lnJ = np.log(J)
    c = lam * lnJ - mu
    for i in range(d):
        for a in range(d):
            P[i, a] = mu * F[i, a] + c * Finv[a, i]
    for i in range(d):
        for a in range(d):
            for k in range(d):
                for b in range(d):
                    val = lam * Finv[a, i] * Finv[b, k] - c * Finv[a, k] * Finv[b, i]
                    if i == k and a == b:
                        val += mu
                    A[i, a, k, b] = val
    return J


@njit(cache=True)
def strain_energy(F, lam, mu):
    """W(F) per unit reference volume (plane strain in 2D)."""
    d = F.shape[0]
    _, J = _inverse(F)
    if J <= 0.0:
        return np.inf
    trC = 0.0
    for i in range(d):
        for a in range(d):
            trC += F[i, a] * F[i, a]
    lnJ = np.log(J)
    return 0.5 * mu * (trC - d) - mu * lnJ + 0.5 * lam * lnJ * lnJ


@njit(cache=True)
def out_of_plane_stress(F, lam, mu):
    """σ_zz = λ ln J / J in plane strain."""
    _, J = _inverse(F)
    return lam * np.log(J) / J

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

from softgrains.materials.tensor import determinant, inverse


@njit(cache=True, inline="always")
def pk1_and_tangent(F, lam, mu, P, A, Finv, tangent):
    """Fill P (d×d) and, if ``tangent``, A (d×d×d×d) for deformation gradient F; return J.

    ``Finv`` is d×d scratch (receives F⁻¹), so that the function allocates nothing.
    """
    d = F.shape[0]
    J = inverse(F, Finv)
    if J <= 0.0:
        return J
    lnJ = np.log(J)
    c = lam * lnJ - mu
    for i in range(d):
        for a in range(d):
            P[i, a] = mu * F[i, a] + c * Finv[a, i]
    if not tangent:
        return J
    for i in range(d):
        for a in range(d):
            for k in range(d):
                for b in range(d):
                    val = lam * Finv[a, i] * Finv[b, k] - c * Finv[a, k] * Finv[b, i]
                    if i == k and a == b:
                        val += mu
                    A[i, a, k, b] = val
    return J


@njit(cache=True, inline="always")
def strain_energy(F, lam, mu):
    """W(F) per unit reference volume (plane strain in 2D)."""
    d = F.shape[0]
    J = determinant(F)
    if J <= 0.0:
        return np.inf
    trC = 0.0
    for i in range(d):
        for a in range(d):
            trC += F[i, a] * F[i, a]
    lnJ = np.log(J)
    return 0.5 * mu * (trC - d) - mu * lnJ + 0.5 * lam * lnJ * lnJ


@njit(cache=True, inline="always")
def out_of_plane_stress(F, lam, mu):
    """σ_zz = λ ln J / J in plane strain."""
    J = determinant(F)
    return lam * np.log(J) / J

"""Dispatch from an integer law code to the law's per-point functions.

Kernels carry one int per point (``law``), so every body can have its own law without
Python objects in the hot loops.
"""

from numba import njit

from softgrains.materials import linear_elastic, neo_hookean

LAW_CODES = {"neo-hookean": 0, "linear-elastic": 1}
# the linear law: geometrically linear, its stress no push-forward of an objective S (the
# momentum form of the internal forces leaves it out)
LINEAR_LAW = LAW_CODES["linear-elastic"]


def law_code(name: str) -> int:
    """Integer code of a law name from the case file."""
    return LAW_CODES[name]


def lame_parameters(young: float, poisson: float) -> tuple[float, float]:
    """(λ, μ) from Young's modulus and Poisson's ratio (3D relations, used in plane strain)."""
    lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    mu = young / (2.0 * (1.0 + poisson))
    return lam, mu


@njit(cache=True, inline="always")
def pk1_and_tangent(law, F, lam, mu, P, A, Finv, tangent=True):
    """P(F) and (if ``tangent``) A = dP/dF; returns J = det F (≤ 0 flags an inverted point).

    P (d×d), A (d×d×d×d) and the scratch Finv (d×d) are filled in place (no allocation).
    """
    if law == LINEAR_LAW:
        return linear_elastic.pk1_and_tangent(F, lam, mu, P, A, Finv, tangent)
    return neo_hookean.pk1_and_tangent(F, lam, mu, P, A, Finv, tangent)


@njit(cache=True, inline="always")
def strain_energy(law, F, lam, mu):
    """Strain energy density W(F) per unit reference volume."""
    if law == LINEAR_LAW:
        return linear_elastic.strain_energy(F, lam, mu)
    return neo_hookean.strain_energy(F, lam, mu)


@njit(cache=True, inline="always")
def cauchy_stress(law, F, lam, mu, sigma, P, A, Finv):
    """Fill sigma (3×3 in 2D plane strain: in-plane block and σ_zz; d×d in 3D).

    P, A and Finv are scratch arrays as in :func:`pk1_and_tangent`.
    """
    d = F.shape[0]
    J = pk1_and_tangent(law, F, lam, mu, P, A, Finv, False)
    sigma[:, :] = 0.0
    if law == LINEAR_LAW:
        for i in range(d):
            for j in range(d):
                sigma[i, j] = P[i, j]
        if d == 2:
            sigma[2, 2] = linear_elastic.out_of_plane_stress(F, lam, mu)
        return
    for i in range(d):
        for j in range(d):
            s = 0.0
            for a in range(d):
                s += P[i, a] * F[j, a]
            sigma[i, j] = s / J
    if d == 2:
        sigma[2, 2] = neo_hookean.out_of_plane_stress(F, lam, mu)

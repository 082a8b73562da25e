"""Von Mises equivalent stress per point (ALGORITHM.md §9).

    σ_vm = √(½[(σxx−σyy)² + (σyy−σzz)² + (σzz−σxx)²] + 3(σxy² + σyz² + σzx²))
with σ_zz the plane-strain out-of-plane stress in 2D (stored in sigma[:, 2, 2]).
"""

import numpy as np


def von_mises(sigma: np.ndarray) -> np.ndarray:
    """σ_vm of Cauchy stresses sigma (n, 3, 3)."""
    sxx, syy, szz = sigma[:, 0, 0], sigma[:, 1, 1], sigma[:, 2, 2]
    shear = sigma[:, 0, 1] ** 2 + sigma[:, 1, 2] ** 2 + sigma[:, 2, 0] ** 2
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * shear)

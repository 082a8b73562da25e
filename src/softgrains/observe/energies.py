"""Energies per unit thickness (2D) or total (3D).

    kinetic  E_k = ½ Σ_p m_p |v_p|²
    strain   E_s = Σ_p V⁰_p W(F_p)     (W: the law's strain-energy density)
"""

import numpy as np
from numba import prange

from softgrains.materials.dispatch import strain_energy as _w
from softgrains.threads import parallel_kernel, threads_for


def kinetic_energy(mass: np.ndarray, v: np.ndarray) -> float:
    return float(0.5 * np.sum(mass * np.sum(v * v, axis=1)))


@parallel_kernel(cache=True)
def _strain_energies(law, F, lam, mu, vol0, out):
    for p in prange(F.shape[0]):
        out[p] = vol0[p] * _w(law[p], F[p], lam[p], mu[p])


def strain_energy(law, F, lam, mu, vol0) -> float:
    out = np.empty(F.shape[0])
    with threads_for(F.shape[0]):
        _strain_energies(law, F, lam, mu, vol0, out)
    return float(out.sum())

"""Energies per unit thickness (2D) or total (3D).

    kinetic  E_k = ½ Σ_p m_p |v_p|²
    strain   E_s = Σ_p V⁰_p W(F_p)     (W: the law's strain-energy density)
    spin     E_ω = ½ Lᵀ J⁻¹ L per body (L, J: its points' angular momentum and inertia
             about their mass centre)
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


def spin_energies(mass: np.ndarray, x: np.ndarray, v: np.ndarray, body_id: np.ndarray,
                  n_bodies: int) -> np.ndarray:
    """Per body the kinetic energy of its best-fit rigid spin, ½ Lᵀ J⁻¹ L, with L = Σ_p m_p
    r_p × (v_p − V) and J = Σ_p m_p (|r_p|² I − r_p r_pᵀ) (2D: the polar moment) about the
    mass centre (r_p = x_p − c, V the mass-centre velocity); 0 for a body without points."""
    d = x.shape[1]

    def per_body(values: np.ndarray) -> np.ndarray:
        return np.stack([np.bincount(body_id, values[:, k], minlength=n_bodies)
                         for k in range(values.shape[1])], axis=1)

    total = np.bincount(body_id, mass, minlength=n_bodies)
    safe = np.maximum(total, 1e-300)[:, None]
    r = x - (per_body(mass[:, None] * x) / safe)[body_id]
    w = v - (per_body(mass[:, None] * v) / safe)[body_id]
    if d == 2:
        L = np.bincount(body_id, mass * (r[:, 0] * w[:, 1] - r[:, 1] * w[:, 0]),
                        minlength=n_bodies)
        polar = np.bincount(body_id, mass * (r * r).sum(axis=1), minlength=n_bodies)
        return np.where(polar > 0.0, 0.5 * L * L / np.maximum(polar, 1e-300), 0.0)
    L = per_body(mass[:, None] * np.cross(r, w))
    outer = per_body((mass[:, None, None] * np.einsum("pi,pj->pij", r, r)).reshape(-1, 9))
    J = (np.trace(outer.reshape(-1, 3, 3), axis1=1, axis2=2)[:, None, None] * np.eye(3)
         - outer.reshape(-1, 3, 3))
    held = total > 0.0
    out = np.zeros(n_bodies)
    # J⁺ (pseudo-inverse): a body whose points lie on a line has no spin about it
    out[held] = 0.5 * np.einsum("bi,bij,bj->b", L[held], np.linalg.pinv(J[held]), L[held])
    return out

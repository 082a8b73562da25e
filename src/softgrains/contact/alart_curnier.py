"""The Alart–Curnier function of a contact problem and its generalized Jacobian, per contact
(the semismooth Newton of solvers.py), as one Numba kernel over the contacts.

In each contact's frame, with impulses r = (r_n, r_t), velocities u, gap bias b, ρ > 0:

    λ_n = r_n − ρ (u_n + b),   λ_t = r_t − ρ u_t,
    Φ_n = r_n − max(0, λ_n),   Φ_t = r_t − proj_{B(s)}(λ_t),

B(s) the ball of radius s = μ max(0, λ_n) (Coulomb) or a fixed threshold (Tresca). G is
the derivative of the projections w.r.t. λ: G_nn = [λ_n > 0]; G_tt = I inside the ball,
(s/‖λ_t‖)(I − t̂ t̂ᵀ) on its boundary (t̂ = λ_t/‖λ_t‖), and with Coulomb G_tn = μ t̂ there.
A contact no body can move at (``movable`` false) has Φ_t = r_t and G_t = 0.
Dimension-generic: d − 1 tangential components (2D and 3D).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass
class Linearised:
    """Φ(r) and the pieces of its generalized Jacobian at one r (local frames)."""

    phi: np.ndarray  # (n, d)
    G: np.ndarray  # (n, d, d): derivative of the projections w.r.t. λ


@njit(cache=True, nogil=True)
def _all_contacts(r, u, bias, mu, rho, movable, threshold, coulomb):
    """Φ (n, d) and G (n, d, d) of every contact (module docstring): the same operations
    in the same order as the array version this kernel replaced (bit-identical results)."""
    n, d = r.shape
    phi = np.empty((n, d))
    G = np.zeros((n, d, d))
    lam_t = np.empty(max(d - 1, 1))
    for c in range(n):
        lam_n = r[c, 0] - rho[c] * (u[c, 0] + bias[c])
        norm2 = 0.0
        for a in range(1, d):
            lam_t[a - 1] = r[c, a] - rho[c] * u[c, a]
            norm2 += lam_t[a - 1] * lam_t[a - 1]
        norm_t = np.sqrt(norm2)
        free = movable[c]
        pressed = lam_n > 0.0 and free
        if coulomb:
            radius = mu[c] * lam_n if pressed else 0.0
        else:
            radius = threshold[c] if free else 0.0
        inside = norm_t <= radius or norm_t == 0.0
        safe = 1.0 if inside else norm_t
        scale = radius / safe
        phi[c, 0] = r[c, 0] - (lam_n if pressed else 0.0)
        G[c, 0, 0] = 1.0 if pressed else 0.0
        for a in range(1, d):
            if not free:
                projected = 0.0
            elif inside:
                projected = lam_t[a - 1]
                G[c, a, a] = 1.0
            else:  # sliding: G_tt = (s/‖λ_t‖)(I − t̂ t̂ᵀ), and μ t̂ on the normal column
                projected = scale * lam_t[a - 1]
                unit_a = lam_t[a - 1] / safe
                for b in range(1, d):
                    G[c, a, b] = scale * ((1.0 if a == b else 0.0)
                                          - unit_a * (lam_t[b - 1] / safe))
                if coulomb:
                    G[c, a, 0] = (mu[c] * (1.0 if pressed else 0.0)) * unit_a
            phi[c, a] = r[c, a] - projected
    return phi, G


def linearise(r: np.ndarray, u: np.ndarray, bias: np.ndarray, mu: np.ndarray,
              rho: np.ndarray, movable: np.ndarray,
              threshold: np.ndarray | None = None) -> Linearised:
    """Φ and G of the Alart–Curnier function at local impulses r and velocities u (n, d);
    with ``threshold`` (per contact) the Tresca law of that fixed friction bound instead of
    Coulomb's μ max(0, λ_n)."""
    coulomb = threshold is None
    phi, G = _all_contacts(np.ascontiguousarray(r, float), np.ascontiguousarray(u, float),
                           np.ascontiguousarray(bias, float), np.ascontiguousarray(mu, float),
                           np.ascontiguousarray(rho, float), np.ascontiguousarray(movable, bool),
                           np.zeros(r.shape[0]) if coulomb
                           else np.ascontiguousarray(threshold, float), coulomb)
    return Linearised(phi, G)

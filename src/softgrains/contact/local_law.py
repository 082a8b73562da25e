"""Local Signorini–Coulomb solution at one contact, impulse form (ALGORITHM.md §5).

The impulse P = P_n n + P_t acts on α (−P on β) over the step. With the local relation
w = w^free + W P between the end-of-step relative velocity w = v^α − v^β and P, and the
normal and tangential compliances 1/m_n, 1/m_t (lumped masses: 1/m* = 1/m^α + 1/m^β, and
1/m^α against a kinematic wall),

    P_n = max(0, −m_n (w_n^free + g/Δt))          (Signorini on w̃_n = w_n + g/Δt)
    P_t^trial = −m_t w_t^free
    P_t = P_t^trial                  if ‖P_t^trial‖ ≤ μ P_n   (stick: w_t = 0)
        = μ P_n P_t^trial/‖P_t^trial‖ otherwise             (slip, opposing the sliding)

g ≥ 0 is the gap between the bodies' boundaries along n: a body may close it within the step,
not cross it. Dimension-generic, allocation-free (the impulse is written into ``P``).
"""

import numpy as np
from numba import njit

OPEN, STICK, SLIP = 0, 1, 2


@njit(cache=True, inline="always")
def local_impulse(w_free, n, m_n, m_t, gap_over_dt, mu, P):
    """Write the contact impulse into P (d,); return OPEN, STICK or SLIP."""
    d = n.shape[0]
    wn = 0.0
    for j in range(d):
        wn += w_free[j] * n[j]
    pn = -m_n * (wn + gap_over_dt)
    if pn <= 0.0:
        for j in range(d):
            P[j] = 0.0
        return OPEN
    norm_t = 0.0
    for j in range(d):
        P[j] = -m_t * (w_free[j] - wn * n[j])
        norm_t += P[j] * P[j]
    norm_t = np.sqrt(norm_t)
    status = STICK
    if norm_t > mu * pn:
        scale = mu * pn / norm_t
        for j in range(d):
            P[j] *= scale
        status = SLIP
    for j in range(d):
        P[j] += pn * n[j]
    return status

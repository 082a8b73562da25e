"""The Gauss–Seidel sweeps over contacts with a d×d local compliance (ALGORITHM.md §5–6).

Every deformable body s in contact carries, at its k_s contact rows, the velocities V_s
(k_s, d) and the compliance W_s (k_s d × k_s d): the change of those velocities per unit
impulse at one of them (lumped: diag(1/m); Delassus: κ w [A⁻¹]_cc). At contact c between
α (row i) and β (row j), w = v^α_i − v^β_j and an impulse change ΔP (on α, −ΔP on β) gives

    ΔV_α = W_α[:, i] ΔP,   ΔV_β = −W_β[:, j] ΔP,   Δw = (W_α[i, i] + W_β[j, j]) ΔP = W_c ΔP.

In 2D each visit solves the local problem exactly with the full 2×2 block W_c
(local_impulse_2d: open, stick or slip±, on w^free = w − W_c P). Otherwise (3D, or no
branch consistent) it applies the closed-form law of local_law.py with the scalar masses
m_n = 1/(n·W_c n), m_t = (d − 1)/(tr W_c − n·W_c n) on w^free = w − P_n/m_n n − P_t/m_t:
the own impulse removed with the same scalar compliances, so that a fixed point satisfies
Signorini and Coulomb exactly (removing it with the full W_c leaves w_t = W_tn P_n at a
"sticking" fixed point). Kinematic walls (slot −1) have W = 0 and a prescribed velocity.
The impulse changes are summed per body row in Q, passed on to the bodies afterwards.
"""

import numpy as np
from numba import njit

from softgrains.contact.local_law import OPEN, SLIP, STICK, local_impulse


@njit(cache=True, inline="always")
def _add_block(W, base, kd, col, d, sign, Wc):
    """Wc += sign · W_s[col, col] (the d×d diagonal block of one body's compliance)."""
    for p in range(d):
        for q in range(d):
            Wc[p, q] += sign * W[base + (col * d + p) * kd + col * d + q]


@njit(cache=True, inline="always")
def _spread(W, base, kd, k, col, d, sign, dP, V, v_off):
    """V_s += sign · W_s[:, col] ΔP (the velocity change of all of a body's contact rows),
    read as the rows W_s[col, :] (W_s is symmetric: contiguous, where its columns are
    strided by the body's k d — the sweeps of a 1000-grain problem read 200 MB)."""
    for r in range(k):
        for p in range(d):
            acc = 0.0
            for q in range(d):
                acc += W[base + (col * d + q) * kd + r * d + p] * dP[q]
            V[v_off + r, p] += sign * acc


@njit(cache=True, inline="always")
def _spread_any(W, base, k, col, d, sign, dP, V, v_off):
    """:func:`_spread` with d passed as a literal (2 or 3): its loops then have known
    bounds, and the dense compaction's sweeps took 1.9× less time (the same sums in the
    same order, session 54)."""
    if d == 2:
        _spread(W, base, k * 2, k, col, 2, sign, dP, V, v_off)
    else:
        _spread(W, base, k * 3, k, col, 3, sign, dP, V, v_off)


@njit(cache=True, inline="always")
def local_impulse_2d(w_free, n, Wc, gap_over_dt, mu, P):
    """Exact 2D local solution with the full 2×2 compliance: w = w^free + W_c P.

    Tries, in order, open (P = 0), stick (W_c P = −w^free − (g/Δt) n) and slip with
    P = P_n (n + s μ t), s = ±1, keeping the first that satisfies its conditions; returns
    its status, or −1 when none does (then the caller uses the scalar-mass solution).
    """
    t0, t1 = -n[1], n[0]
    wn = w_free[0] * n[0] + w_free[1] * n[1] + gap_over_dt
    if wn >= 0.0:
        P[0] = 0.0
        P[1] = 0.0
        return OPEN
    det = Wc[0, 0] * Wc[1, 1] - Wc[0, 1] * Wc[1, 0]
    if det > 0.0:
        r0 = -w_free[0] - gap_over_dt * n[0]
        r1 = -w_free[1] - gap_over_dt * n[1]
        p0 = (Wc[1, 1] * r0 - Wc[0, 1] * r1) / det
        p1 = (Wc[0, 0] * r1 - Wc[1, 0] * r0) / det
        pn = p0 * n[0] + p1 * n[1]
        pt = p0 * t0 + p1 * t1
        if pn >= 0.0 and abs(pt) <= mu * pn:
            P[0] = p0
            P[1] = p1
            return STICK
    for s in (1.0, -1.0):
        e0 = n[0] + s * mu * t0
        e1 = n[1] + s * mu * t1
        We0 = Wc[0, 0] * e0 + Wc[0, 1] * e1
        We1 = Wc[1, 0] * e0 + Wc[1, 1] * e1
        denominator = n[0] * We0 + n[1] * We1
        if denominator <= 0.0:
            continue
        pn = -wn / denominator
        wt = (w_free[0] + pn * We0) * t0 + (w_free[1] + pn * We1) * t1
        if pn >= 0.0 and s * wt <= 0.0:
            P[0] = pn * e0
            P[1] = pn * e1
            return SLIP
    return -1


@njit(cache=True)
def gauss_seidel(a_slot, a_col, b_slot, b_col, wall_va, wall_vb, normal, gap_over_dt, mu,
                 k_off, w_off, k_size, W, V, Q, P, status, tolerance, floor, max_sweeps):
    """Sweep until max|ΔP| ≤ tolerance·max|P| + floor; P, status, V and Q updated in place.

    Returns (sweeps, last max|ΔP|).
    """
    n, d = normal.shape
    Wc = np.empty((d, d))
    w = np.empty(d)
    w_free = np.empty(d)
    P_new = np.empty(d)
    dP = np.empty(d)
    sweeps = 0
    change = 0.0
    for _ in range(max_sweeps):
        change = 0.0
        largest = 0.0
        for c in range(n):
            sa, sb = a_slot[c], b_slot[c]
            Wc[:, :] = 0.0
            if sa >= 0:
                _add_block(W, w_off[sa], k_size[sa] * d, a_col[c], d, 1.0, Wc)
            if sb >= 0:
                _add_block(W, w_off[sb], k_size[sb] * d, b_col[c], d, 1.0, Wc)
            wnn = 0.0
            trace = 0.0
            for p in range(d):
                trace += Wc[p, p]
                for q in range(d):
                    wnn += normal[c, p] * Wc[p, q] * normal[c, q]
            if wnn <= 0.0:
                continue  # no body can move at this node
            wtt = (trace - wnn) / (d - 1)  # mean tangential compliance
            m_t = 1.0 / wtt if wtt > 1e-12 * wnn else 0.0
            pn = 0.0
            for p in range(d):
                pn += P[c, p] * normal[c, p]
                va = V[k_off[sa] + a_col[c], p] if sa >= 0 else wall_va[c, p]
                vb = V[k_off[sb] + b_col[c], p] if sb >= 0 else wall_vb[c, p]
                w[p] = va - vb
            state = -1
            if d == 2:  # exact, the own impulse removed with the full W_c
                for p in range(d):
                    w_free[p] = w[p]
                    for q in range(d):
                        w_free[p] -= Wc[p, q] * P[c, q]
                state = local_impulse_2d(w_free, normal[c], Wc, gap_over_dt[c], mu[c], P_new)
            if state < 0:  # scalar masses, the own impulse removed with the same scalars
                ct = wtt if m_t > 0.0 else 0.0
                for p in range(d):
                    w_free[p] = (w[p] - wnn * pn * normal[c, p]
                                 - ct * (P[c, p] - pn * normal[c, p]))
                state = local_impulse(w_free, normal[c], 1.0 / wnn, m_t, gap_over_dt[c],
                                      mu[c], P_new)
            status[c] = state
            moved = 0.0
            for p in range(d):
                dP[p] = P_new[p] - P[c, p]
                moved = max(moved, abs(dP[p]))
                largest = max(largest, abs(P_new[p]))
            if moved == 0.0:
                continue
            if sa >= 0:
                _spread_any(W, w_off[sa], k_size[sa], a_col[c], d, 1.0, dP, V, k_off[sa])
                for p in range(d):
                    Q[k_off[sa] + a_col[c], p] += dP[p]
            if sb >= 0:
                _spread_any(W, w_off[sb], k_size[sb], b_col[c], d, -1.0, dP, V, k_off[sb])
                for p in range(d):
                    Q[k_off[sb] + b_col[c], p] -= dP[p]
            for p in range(d):
                P[c, p] = P_new[p]
            change = max(change, moved)
        sweeps += 1
        if change <= tolerance * largest + floor:
            break
    for c in range(n):
        if P[c, 0] == 0.0 and (d < 2 or P[c, 1] == 0.0) and (d < 3 or P[c, 2] == 0.0):
            status[c] = OPEN
    return sweeps, change

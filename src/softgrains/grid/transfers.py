"""Transfers between one body's material points and its own nodal fields (ALGORITHM.md §2, §7).

P2G (lumped):  m_I = Σ_p N_I(x_p) m_p,   m_I v_I = Σ_p N_I(x_p) m_p v_p   (same for a_I)
G2P:           x_p ← x_p + Σ_I N_I u_I
               v_p ← α (v_p + Σ_I N_I Δv_I) + (1 − α) Σ_I N_I v_I^{n+1}    (α: FLIP fraction)
               F_p ← ΔF_p F_p,  ΔF_p = I + Σ_I u_I ⊗ ∇N_I(X_p)
Nodal arrays are indexed by the body's local node index (its node box, axis 0 fastest).
"""

import numpy as np
from numba import njit, prange

from softgrains.materials.dispatch import cauchy_stress


@njit(cache=True, parallel=True)
def local_node_indices(base, lower, strides, s, out):
    """Local node index (in the body's box) of every stencil entry: out (n, s^d)."""
    n, d = base.shape
    for p in prange(n):
        for k in range(s**d):
            rem = k
            idx = 0
            for j in range(d):
                idx += (base[p, j] + rem % s - lower[j]) * strides[j]
                rem //= s
            out[p, k] = idx


@njit(cache=True)
def particles_to_grid(nodes, N, mass, v, a, n_box, m_I, mv_I, ma_I):
    """Scatter mass, momentum and mass-weighted acceleration to the body's nodes."""
    n, ns = nodes.shape
    d = v.shape[1]
    m_I[:] = 0.0
    mv_I[:, :] = 0.0
    ma_I[:, :] = 0.0
    for p in range(n):
        for k in range(ns):
            I = nodes[p, k]
            wm = N[p, k] * mass[p]
            m_I[I] += wm
            for j in range(d):
                mv_I[I, j] += wm * v[p, j]
                ma_I[I, j] += wm * a[p, j]


@njit(cache=True, parallel=True)
def grid_to_particles(nodes, N, dN, u_I, v_old_I, v_new_I, a_new_I, flip, update_a,
                      law, lam, mu, vol0, x, v, a, F, sigma, vol):
    """Move points with the converged nodal solution and update v, a, F, σ, V (in place).

    Returns the smallest J found (≤ 0 means an inverted point).
    """
    n, ns = nodes.shape
    d = x.shape[1]
    Jmin = np.inf
    Jp = np.empty(n)
    for p in prange(n):
        dF = np.eye(d)
        du = np.zeros(d)
        dv = np.zeros(d)
        vpic = np.zeros(d)
        apic = np.zeros(d)
        for k in range(ns):
            I = nodes[p, k]
            w = N[p, k]
            for i in range(d):
                du[i] += w * u_I[I, i]
                dv[i] += w * (v_new_I[I, i] - v_old_I[I, i])
                vpic[i] += w * v_new_I[I, i]
                apic[i] += w * a_new_I[I, i]
                for j in range(d):
                    dF[i, j] += u_I[I, i] * dN[p, k, j]
        Fn = F[p].copy()
        Fnew = dF @ Fn
        for i in range(d):
            x[p, i] += du[i]
            v[p, i] = flip * (v[p, i] + dv[i]) + (1.0 - flip) * vpic[i]
            if update_a:
                a[p, i] = apic[i]
        F[p] = Fnew
        J = np.linalg.det(Fnew)
        Jp[p] = J
        if J > 0.0:
            cauchy_stress(law[p], Fnew, lam[p], mu[p], sigma[p])
            vol[p] = J * vol0[p]
    for p in range(n):
        if Jp[p] < Jmin:
            Jmin = Jp[p]
    return Jmin

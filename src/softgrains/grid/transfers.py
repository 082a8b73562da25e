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
from softgrains.materials.tensor import determinant


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


@njit(cache=True, inline="always")
def deformation_increment(nodes, dN, p, u_I, dF):
    """ΔF_p = I + Σ_k u_{I_k} ⊗ ∇N_k(X_p) for point p (written into dF)."""
    d = dF.shape[0]
    for i in range(d):
        for j in range(d):
            dF[i, j] = 1.0 if i == j else 0.0
    for k in range(nodes.shape[1]):
        I = nodes[p, k]
        for i in range(d):
            for j in range(d):
                dF[i, j] += u_I[I, i] * dN[p, k, j]


@njit(cache=True, inline="always")
def matmul(A, B, out):
    """out = A B for small square matrices."""
    d = A.shape[0]
    for i in range(d):
        for j in range(d):
            acc = 0.0
            for k in range(d):
                acc += A[i, k] * B[k, j]
            out[i, j] = acc


@njit(cache=True, parallel=True)
def grid_to_particles(nodes, N, dN, u_I, v_old_I, v_new_I, a_new_I, flip, update_a,
                      law, lam, mu, vol0, x, v, a, F, sigma, vol, n_chunks):
    """Move points with the converged nodal solution and update v, a, F, σ, V (in place).

    Points are processed in ``n_chunks`` chunks, each with its own scratch arrays.
    Returns the smallest J found (≤ 0 means an inverted point).
    """
    n, ns = nodes.shape
    d = x.shape[1]
    n_chunks = max(1, min(n, n_chunks))
    Jmin_chunk = np.full(n_chunks, np.inf)
    for c in prange(n_chunks):
        dF = np.empty((d, d))
        Fnew = np.empty((d, d))
        P = np.empty((d, d))
        A = np.empty((d, d, d, d))
        Finv = np.empty((d, d))
        for p in range(c * n // n_chunks, (c + 1) * n // n_chunks):
            deformation_increment(nodes, dN, p, u_I, dF)
            for i in range(d):
                du = 0.0
                dv = 0.0
                vpic = 0.0
                apic = 0.0
                for k in range(ns):
                    I = nodes[p, k]
                    w = N[p, k]
                    du += w * u_I[I, i]
                    dv += w * (v_new_I[I, i] - v_old_I[I, i])
                    vpic += w * v_new_I[I, i]
                    apic += w * a_new_I[I, i]
                x[p, i] += du
                v[p, i] = flip * (v[p, i] + dv) + (1.0 - flip) * vpic
                if update_a:
                    a[p, i] = apic
            matmul(dF, F[p], Fnew)
            F[p] = Fnew
            J = determinant(Fnew)
            if J < Jmin_chunk[c]:
                Jmin_chunk[c] = J
            if J > 0.0:
                cauchy_stress(law[p], Fnew, lam[p], mu[p], sigma[p], P, A, Finv)
                vol[p] = J * vol0[p]
    return Jmin_chunk.min()

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
from softgrains.threads import parallel_kernel


@parallel_kernel(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def restrict_to_active(nodes, N, dN, active_row):
    """Remove inactive nodes from the points' stencils, keeping the interpolation consistent.

    For a point touching inactive nodes (set D): N_k ← N_k / Σ_{k∉D} N_k and
    ∇N_k ← ∇N_k + N_k/Σ_{k∉D} N_k · Σ_{j∈D} ∇N_j on the active entries, zero on D. The
    weights still sum to 1 and the gradients to 0, so a rigid motion stays strain-free and
    momentum transfers stay exact. Returns the number of points changed.
    """
    n, ns = nodes.shape
    d = dN.shape[2]
    changed = 0
    for p in range(n):
        w_active = 0.0
        touches = False
        for k in range(ns):
            if active_row[nodes[p, k]] >= 0:
                w_active += N[p, k]
            else:
                touches = True
        if not touches:
            continue
        changed += 1
        for j in range(d):
            g_dropped = 0.0
            for k in range(ns):
                if active_row[nodes[p, k]] < 0:
                    g_dropped += dN[p, k, j]
            for k in range(ns):
                if active_row[nodes[p, k]] >= 0:
                    dN[p, k, j] += N[p, k] / w_active * g_dropped
                else:
                    dN[p, k, j] = 0.0
        for k in range(ns):
            if active_row[nodes[p, k]] >= 0:
                N[p, k] /= w_active
            else:
                N[p, k] = 0.0
    return changed


@njit(cache=True, nogil=True)
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


UPDATE_FLIP_THETA = 0  # v: FLIP/PIC blend of nodal v^{n+1}
UPDATE_FLIP_NEWMARK = 1  # v: FLIP/PIC blend; a: interpolated nodal a^{n+1}
UPDATE_PARTICLE_THETA = 2  # v from the point's own displacement, θ-scheme
UPDATE_PARTICLE_NEWMARK = 3  # v, a from the point's own displacement, Newmark


@parallel_kernel(cache=True, nogil=True)
def grid_to_particles(nodes, N, dN, u_I, v_old_I, v_new_I, a_new_I, update, params,
                      law, lam, mu, vol0, x, v, a, F, sigma, vol, n_chunks):
    """Move points with the converged nodal solution and update v, a, F, σ, V (in place).

    ``params`` = (Δt, FLIP fraction α, θ, β, γ). With the consistent mass matrix the points
    are integrated on their own displacement δx_p = Σ N_I u_I (``UPDATE_PARTICLE_*``):
        θ-scheme: v_p ← (δx_p/Δt − (1−θ) v_p)/θ
        Newmark:  a_p ← (δx_p − Δt v_p − (½−β)Δt² a_p)/(βΔt²),  v_p ← v_p + Δt[(1−γ)a_p + γ a_p⁺]
    which conserves the energy exactly for θ = 1/2 and a linear law, since the grid equations
    with the consistent mass are the same rule projected (docs/theory.md).
    Points are processed in ``n_chunks`` chunks, each with its own scratch arrays.
    Returns the smallest J found (≤ 0 means an inverted point).
    """
    n, ns = nodes.shape
    d = x.shape[1]
    dt, flip, theta, beta, gamma = params[0], params[1], params[2], params[3], params[4]
    n_chunks = max(1, min(n, n_chunks))
    Jmin_chunk = np.empty(n_chunks)
    for c in prange(n_chunks):
        dF = np.empty((d, d))
        Fnew = np.empty((d, d))
        P = np.empty((d, d))
        A = np.empty((d, d, d, d))
        Finv = np.empty((d, d))
        jmin = np.inf
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
                if update == UPDATE_PARTICLE_THETA:
                    v[p, i] = (du / dt - (1.0 - theta) * v[p, i]) / theta
                elif update == UPDATE_PARTICLE_NEWMARK:
                    a_new = ((du - dt * v[p, i] - (0.5 - beta) * dt * dt * a[p, i])
                             / (beta * dt * dt))
                    v[p, i] += dt * ((1.0 - gamma) * a[p, i] + gamma * a_new)
                    a[p, i] = a_new
                else:
                    v[p, i] = flip * (v[p, i] + dv) + (1.0 - flip) * vpic
                    if update == UPDATE_FLIP_NEWMARK:
                        a[p, i] = apic
            matmul(dF, F[p], Fnew)
            F[p] = Fnew
            J = determinant(Fnew)
            jmin = min(jmin, J)
            if J > 0.0:
                cauchy_stress(law[p], Fnew, lam[p], mu[p], sigma[p], P, A, Finv)
                vol[p] = J * vol0[p]
        Jmin_chunk[c] = jmin
    return Jmin_chunk.min()

"""Internal force and consistent tangent of one body over a step (ALGORITHM.md §3).

Updated Lagrangian over the step: the grid moves with the material, the unknown is the nodal
displacement increment u. With X_p the start-of-step positions and F_p^n the start-of-step
gradients,

    ΔF_p = I + Σ_I u_I ⊗ ∇_X N_I(X_p),        F_p = ΔF_p F_p^n,
    P̃_p  = (1/J_p^n) P(F_p) F_p^nᵀ  = ΔJ σ ΔF⁻ᵀ    (first P–K stress relative to step start)
    f_I^int = −Σ_p V_p^n P̃_p ∇_X N_I                (equal to −Σ V_p σ_p ∇_x N_I)
    K_IJ,ik = −∂f_I,i/∂u_J,k = Σ_p V_p^n ∇_X N_I,a Ã_iakb ∇_X N_J,b
    Ã_iakb  = (1/J^n) Σ_{M,N} A_iMkN F^n_aM F^n_bN  (A = ∂P/∂F of the law: material + geometric)

The tangent is stored block-sparse (BSR, d×d blocks) over the body's active nodes; its
pattern links active nodes within the stencil reach (|ΔI_j| ≤ s − 1). Per-point terms are
computed in parallel, then scattered serially into the fixed pattern (no write conflicts).
"""

import numpy as np
from numba import njit, prange

from softgrains.materials.dispatch import pk1_and_tangent


@njit(cache=True)
def pair_codes(s, d):
    """Neighbourhood code of node b relative to node a for every pair of stencil entries."""
    ns = s**d
    w = 2 * s - 1
    codes = np.empty((ns, ns), dtype=np.int64)
    for ka in range(ns):
        for kb in range(ns):
            ra = ka
            rb = kb
            c = 0
            mult = 1
            for _ in range(d):
                c += (rb % s - ra % s + s - 1) * mult
                mult *= w
                ra //= s
                rb //= s
            codes[ka, kb] = c
    return codes


@njit(cache=True)
def block_pattern(active_row, box_shape, s):
    """BSR pattern over active nodes: (indptr, indices, slot[row, code], diag_slot[row]).

    ``active_row[I]`` is the row of local node I, or −1 if I is inactive. Rows follow the local
    node order, and columns within a row are sorted, so the pattern is canonical.
    """
    d = box_shape.shape[0]
    w = 2 * s - 1
    ncode = w**d
    n_box = active_row.shape[0]
    n_rows = 0
    for I in range(n_box):
        if active_row[I] >= 0:
            n_rows += 1
    strides = np.empty(d, dtype=np.int64)
    strides[0] = 1
    for j in range(1, d):
        strides[j] = strides[j - 1] * box_shape[j - 1]
    slot = -np.ones((n_rows, ncode), dtype=np.int64)
    diag_slot = np.empty(n_rows, dtype=np.int64)
    indptr = np.zeros(n_rows + 1, dtype=np.int64)
    indices = np.empty(n_rows * ncode, dtype=np.int64)
    nnz = 0
    idx = np.empty(d, dtype=np.int64)
    for I in range(n_box):
        r = active_row[I]
        if r < 0:
            continue
        rem = I
        for j in range(d):
            idx[j] = rem % box_shape[j]
            rem //= box_shape[j]
        for c in range(ncode):
            rem = c
            J = 0
            inside = True
            for j in range(d):
                off = rem % w - (s - 1)
                rem //= w
                q = idx[j] + off
                if q < 0 or q >= box_shape[j]:
                    inside = False
                J += q * strides[j]
            if not inside:
                continue
            col = active_row[J]
            if col < 0:
                continue
            indices[nnz] = col
            slot[r, c] = nnz
            if col == r:
                diag_slot[r] = nnz
            nnz += 1
        indptr[r + 1] = nnz
    return indptr, indices[:nnz].copy(), slot, diag_slot


@njit(cache=True, parallel=True)
def point_forces_and_tangents(nodes, dN, u_I, F_n, vol_n, law, lam, mu, fp, Kp, want_tangent):
    """Per-point internal-force terms fp (n, ns, d) and tangent blocks Kp (n, ns, ns, d, d).

    Returns the smallest J of the trial state (≤ 0: the trial state inverts a point).
    """
    n, ns = nodes.shape
    d = u_I.shape[1]
    Jtrial = np.empty(n)
    for p in prange(n):
        dF = np.eye(d)
        for k in range(ns):
            I = nodes[p, k]
            for i in range(d):
                for j in range(d):
                    dF[i, j] += u_I[I, i] * dN[p, k, j]
        Fn = F_n[p]
        F = dF @ Fn
        P = np.empty((d, d))
        A = np.empty((d, d, d, d))
        J = pk1_and_tangent(law[p], F, lam[p], mu[p], P, A)
        Jtrial[p] = J
        if J <= 0.0:
            fp[p] = 0.0
            if want_tangent:
                Kp[p] = 0.0
            continue
        Jn = Fn[0, 0] * Fn[1, 1] - Fn[0, 1] * Fn[1, 0] if d == 2 else np.linalg.det(Fn)
        scale = vol_n[p] / Jn
        # P_rel = P Fnᵀ / Jn, folded with V^n into `scale`
        Prel = P @ Fn.T
        for k in range(ns):
            for i in range(d):
                acc = 0.0
                for a in range(d):
                    acc += Prel[i, a] * dN[p, k, a]
                fp[p, k, i] = -scale * acc
        if not want_tangent:
            continue
        # Ã_iakb (times J^n) = Σ_MN A_iMkN Fn_aM Fn_bN ; then contract with ∇N on a and b
        At = np.zeros((d, d, d, d))
        for i in range(d):
            for k in range(d):
                for a in range(d):
                    for b in range(d):
                        acc = 0.0
                        for M in range(d):
                            for N_ in range(d):
                                acc += A[i, M, k, N_] * Fn[a, M] * Fn[b, N_]
                        At[i, a, k, b] = acc
        for ka in range(ns):
            for kb in range(ns):
                for i in range(d):
                    for k in range(d):
                        acc = 0.0
                        for a in range(d):
                            ga = dN[p, ka, a]
                            for b in range(d):
                                acc += ga * At[i, a, k, b] * dN[p, kb, b]
                        Kp[p, ka, kb, i, k] = scale * acc
    Jmin = np.inf
    for p in range(n):
        if Jtrial[p] < Jmin:
            Jmin = Jtrial[p]
    return Jmin


@njit(cache=True)
def scatter_forces(nodes, fp, f_I):
    """f_I (n_box, d) = Σ_p fp (serial: no write conflicts)."""
    n, ns = nodes.shape
    d = f_I.shape[1]
    f_I[:, :] = 0.0
    for p in range(n):
        for k in range(ns):
            I = nodes[p, k]
            for i in range(d):
                f_I[I, i] += fp[p, k, i]


@njit(cache=True)
def scatter_tangent(nodes, Kp, active_row, slot, codes, data):
    """Accumulate per-point tangent blocks into the BSR data array (nnzb, d, d).

    Terms that touch an inactive node (mass below the activity threshold) are dropped: such a
    node carries no unknown (its displacement is zero).
    """
    n, ns = nodes.shape
    d = data.shape[1]
    data[:, :, :] = 0.0
    for p in range(n):
        for ka in range(ns):
            r = active_row[nodes[p, ka]]
            if r < 0:
                continue
            for kb in range(ns):
                q = slot[r, codes[ka, kb]]
                if q < 0:
                    continue
                for i in range(d):
                    for k in range(d):
                        data[q, i, k] += Kp[p, ka, kb, i, k]


@njit(cache=True)
def add_diagonal_and_constrain(data, indptr, indices, diag_slot, diag, fixed):
    """data += diag on the block diagonals; then rows/columns of fixed dofs become identity.

    ``diag`` and ``fixed`` are per dof (row-major: dof = row*d + i).
    """
    n_rows = indptr.shape[0] - 1
    d = data.shape[1]
    for r in range(n_rows):
        q = diag_slot[r]
        for i in range(d):
            data[q, i, i] += diag[r * d + i]
    for r in range(n_rows):
        for q in range(indptr[r], indptr[r + 1]):
            c = indices[q]
            for i in range(d):
                for k in range(d):
                    if fixed[r * d + i] or fixed[c * d + k]:
                        data[q, i, k] = 1.0 if (r == c and i == k) else 0.0

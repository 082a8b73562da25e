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
computed in parallel over points (V^n P̃ and V^n Ã), then gathered in parallel over the rows
of the fixed pattern through a node → points map (no write conflicts, no per-pair storage).
"""

import numpy as np
from numba import njit, prange

from softgrains.grid.transfers import deformation_increment, matmul
from softgrains.materials.dispatch import LINEAR_LAW, pk1_and_tangent, strain_energy
from softgrains.materials.tensor import determinant, inverse
from softgrains.threads import parallel_kernel


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


@njit(cache=True, nogil=True)
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


@njit(cache=True)
def project_to_psd(Av, p, M):
    """Replace the point's tangent Av[p] (a symmetric d²×d² matrix over (i a), (k b)) by its
    positive semi-definite part Σ max(λ, 0) v vᵀ (projected Newton, Teran et al. 2005).

    Under compression the rotational modes of a point's tangent are negative
    (∝ (P₁ + P₂)/(λ₁ + λ₂) in 2D); in MPM no element stiffness offsets them, and at large
    Δt the mass term cannot either: the Newton matrix turns indefinite.
    """
    d = Av.shape[1]
    n = d * d
    for i in range(d):
        for a in range(d):
            for k in range(d):
                for b in range(d):
                    M[i * d + a, k * d + b] = Av[p, i, a, k, b]
    for r in range(n):
        for c in range(r + 1, n):
            mean = 0.5 * (M[r, c] + M[c, r])
            M[r, c] = mean
            M[c, r] = mean
    w, V = np.linalg.eigh(M)
    if w[0] >= 0.0:
        return
    for i in range(d):
        for a in range(d):
            for k in range(d):
                for b in range(d):
                    acc = 0.0
                    for e in range(n):
                        if w[e] > 0.0:
                            acc += w[e] * V[i * d + a, e] * V[k * d + b, e]
                    Av[p, i, a, k, b] = acc


@njit(cache=True, inline="always")
def momentum_form(dF, Pv, Av, p, want_tangent, dFinv, S, T):
    """The momentum form of the point's stress and tangent (in place):

        V^n P̃ = V⁰ F S Fⁿᵀ  →  Ŝ = V⁰ Fⁿ S Fⁿᵀ = ΔF⁻¹ (V^n P̃)   (symmetric)
        V^n Ã  →  ∂Ŝ/∂(∇u) = ΔF⁻¹ (V^n Ã − δ ⊗ Ŝ)             (not major-symmetric)

    with S the end-of-step second Piola–Kirchhoff stress and F = ΔF Fⁿ. Ŝ is symmetric,
    so the internal forces −Σ Ŝ ∇N have no moment about the start nodes for any u: the
    θ = 1 step keeps each free body's angular momentum (docs/theory.md). V^n Ã's
    geometric part δ_jk (V⁰ F S Fⁿᵀ)_ab drops out (Ŝ changes with u only through S).
    Scratch: dFinv, S (d×d), T (d×d×d×d)."""
    d = dF.shape[0]
    inverse(dF, dFinv)
    for i in range(d):
        for a in range(d):
            acc = 0.0
            for j in range(d):
                acc += dFinv[i, j] * Pv[p, j, a]
            S[i, a] = acc
    if want_tangent:
        for i in range(d):
            for a in range(d):
                for k in range(d):
                    for b in range(d):
                        acc = -dFinv[i, k] * S[a, b]
                        for j in range(d):
                            acc += dFinv[i, j] * Av[p, j, a, k, b]
                        T[i, a, k, b] = acc
        for i in range(d):
            for a in range(d):
                for k in range(d):
                    for b in range(d):
                        Av[p, i, a, k, b] = T[i, a, k, b]
    for i in range(d):
        for a in range(d):
            Pv[p, i, a] = 0.5 * (S[i, a] + S[a, i])


def dimension(d: int) -> tuple:
    """The dimension as a value whose Numba type holds it: (0,) * d, a tuple of d integers.
    A kernel taking it reads d = len(dims) as a constant of its compiled code: its loops
    over the dimension compile with known bounds (:func:`point_stresses` ran 2× faster than
    with d read from an array's shape, session 54), and only the dimension a run uses is
    compiled (a literal 2 and 3 in two branches would compile both)."""
    return (0,) * d


@parallel_kernel(cache=True, nogil=True)
def point_stresses(nodes, dN, u_I, F_n, vol_n, law, lam, mu, Pv, Av, want_tangent, n_chunks,
                   project, momentum, dims):
    """Per point: Pv = V^n P̃ (d×d) and, if ``want_tangent``, Av = V^n Ã (d×d×d×d), made
    positive semi-definite per point when ``project`` (:func:`project_to_psd`); with
    ``momentum``, both in the momentum form of :func:`momentum_form` (not for the linear
    law, whose stress is no push-forward of an objective S). ``dims``: :func:`dimension`
    of the points' d.

    Points are processed in ``n_chunks`` chunks (a few per thread), each with its own
    scratch arrays (no allocation per point). Returns (smallest J of the trial state, strain
    energy Σ V⁰ W(F) of the trial state); J ≤ 0 means the trial state inverts a point (that
    point's Pv and Av are then left unset and the energy is meaningless).
    """
    if len(dims) != u_I.shape[1]:
        raise ValueError("point_stresses: dims is not the points' dimension")
    n = nodes.shape[0]
    n_chunks = max(1, min(n, n_chunks))
    Jmin_chunk = np.empty(n_chunks)
    W_chunk = np.empty(n_chunks)
    for c in prange(n_chunks):
        d = len(dims)  # (a constant here, in the parallel loop's body too)
        dF = np.empty((d, d))
        F = np.empty((d, d))
        P = np.empty((d, d))
        Finv = np.empty((d, d))
        Fn = np.empty((d, d))
        A = np.empty((d, d, d, d))
        psd = np.empty((d * d, d * d))
        S = np.empty((d, d))
        T = np.empty((d, d, d, d))
        jmin = np.inf
        energy = 0.0
        for p in range(c * n // n_chunks, (c + 1) * n // n_chunks):
            deformation_increment(nodes, dN, p, u_I, dF)
            for i in range(d):
                for j in range(d):
                    Fn[i, j] = F_n[p, i, j]
            matmul(dF, Fn, F)
            J = pk1_and_tangent(law[p], F, lam[p], mu[p], P, A, Finv, want_tangent)
            jmin = min(jmin, J)
            if J <= 0.0:
                continue
            scale = vol_n[p] / determinant(Fn)  # = V⁰
            energy += scale * strain_energy(law[p], F, lam[p], mu[p])
            # V^n P̃ = (V^n/J^n) P Fnᵀ
            for i in range(d):
                for a in range(d):
                    acc = 0.0
                    for M in range(d):
                        acc += P[i, M] * Fn[a, M]
                    Pv[p, i, a] = scale * acc
            objective = momentum and law[p] != LINEAR_LAW
            if not want_tangent:
                if objective:
                    momentum_form(dF, Pv, Av, p, False, Finv, S, T)
                continue
            # V^n Ã_iakb = (V^n/J^n) Σ_MN A_iMkN Fn_aM Fn_bN
            for i in range(d):
                for k in range(d):
                    for a in range(d):
                        for b in range(d):
                            acc = 0.0
                            for M in range(d):
                                for N_ in range(d):
                                    acc += A[i, M, k, N_] * Fn[a, M] * Fn[b, N_]
                            Av[p, i, a, k, b] = scale * acc
            if objective:
                momentum_form(dF, Pv, Av, p, True, Finv, S, T)
            if project:
                project_to_psd(Av, p, psd)
        Jmin_chunk[c] = jmin
        W_chunk[c] = energy
    return Jmin_chunk.min(), W_chunk.sum()


@njit(cache=True, nogil=True)
def start_strain_energy(F_n, vol_n, law, lam, mu, n_chunks):
    """Σ_p V⁰_p W(F^n_p), V⁰ = V^n/J^n: the strain energy :func:`point_stresses` returns at
    u = 0 (where F = ΔF F^n = F^n exactly), summed in its chunks as its serial twin sums
    them, without the stresses (a θ = 1 or Newmark step needs no f^int at its start, only
    this energy)."""
    n = F_n.shape[0]
    n_chunks = max(1, min(n, n_chunks))
    W_chunk = np.empty(n_chunks)
    for c in range(n_chunks):
        energy = 0.0
        for p in range(c * n // n_chunks, (c + 1) * n // n_chunks):
            Fn = F_n[p]
            J = determinant(Fn)
            if J <= 0.0:  # (an inverted point: left out, as point_stresses leaves it)
                continue
            energy += vol_n[p] / J * strain_energy(law[p], Fn, lam[p], mu[p])
        W_chunk[c] = energy
    return W_chunk.sum()


@njit(cache=True, nogil=True)
def node_point_map(nodes, active_row, n_rows):
    """For every active row, the stencil entries (p·ns + k) of the points that touch it.

    Returns (ptr, entries) in CSR form, so that rows can be assembled in parallel.
    """
    n, ns = nodes.shape
    ptr = np.zeros(n_rows + 1, dtype=np.int64)
    for p in range(n):
        for k in range(ns):
            r = active_row[nodes[p, k]]
            if r >= 0:
                ptr[r + 1] += 1
    for r in range(n_rows):
        ptr[r + 1] += ptr[r]
    fill = ptr[:-1].copy()
    entries = np.empty(ptr[n_rows], dtype=np.int64)
    for p in range(n):
        for k in range(ns):
            r = active_row[nodes[p, k]]
            if r >= 0:
                entries[fill[r]] = p * ns + k
                fill[r] += 1
    return ptr, entries


@parallel_kernel(cache=True, nogil=True)
def gather_forces(ptr, entries, dN, Pv, f):
    """f_r = −Σ_{(p,k) at r} (V^n P̃_p) ∇N_k(X_p), row-parallel (f: (n_rows, d))."""
    n_rows, d = f.shape
    ns = dN.shape[1]
    for r in prange(n_rows):
        for i in range(d):
            acc = 0.0
            for q in range(ptr[r], ptr[r + 1]):
                p = entries[q] // ns
                k = entries[q] % ns
                for a in range(d):
                    acc += Pv[p, i, a] * dN[p, k, a]
            f[r, i] = -acc


@njit(cache=True, nogil=True)
def _gather_tangent_row(r, ptr, entries, dN, Av, slot, codes, data, d):
    """Row r of :func:`gather_tangent` (its blocks zeroed, then summed). Called with d a
    literal (2 or 3): Numba compiles the loops over the dimension with their bounds known,
    and this kernel took 2.2× less time than with d read from an array's shape (the
    same sums in the same order, session 54)."""
    ns = dN.shape[1]
    T = np.empty((d, d, d))
    for c in range(slot.shape[1]):
        q = slot[r, c]
        if q >= 0:
            for i in range(d):
                for k in range(d):
                    data[q, i, k] = 0.0
    for e in range(ptr[r], ptr[r + 1]):
        p = entries[e] // ns
        ka = entries[e] % ns
        for i in range(d):
            for k in range(d):
                for b in range(d):
                    acc = 0.0
                    for a in range(d):
                        acc += dN[p, ka, a] * Av[p, i, a, k, b]
                    T[i, k, b] = acc
        for kb in range(ns):
            q = slot[r, codes[ka, kb]]
            if q < 0:  # column node inactive
                continue
            for i in range(d):
                for k in range(d):
                    acc = 0.0
                    for b in range(d):
                        acc += T[i, k, b] * dN[p, kb, b]
                    data[q, i, k] += acc


@parallel_kernel(cache=True, nogil=True)
def gather_tangent(ptr, entries, dN, Av, slot, codes, data):
    """BSR data (nnzb, d, d) of K: block (r, c) = Σ_p ∇N_a · (V^n Ã_p) · ∇N_b, row-parallel,
    as T_ikb = Σ_a ∇N_a,a (V^n Ã_p)_iakb once per (p, a), then Σ_b T_ikb ∇N_b,b per column
    node b (d⁴ + n_s d³ products per (p, a) instead of n_s d⁴).

    Terms that touch an inactive node (mass below the activity threshold) are dropped: such a
    node carries no unknown (its displacement is zero).
    """
    d = data.shape[1]
    for r in prange(ptr.shape[0] - 1):
        if d == 2:
            _gather_tangent_row(r, ptr, entries, dN, Av, slot, codes, data, 2)
        else:
            _gather_tangent_row(r, ptr, entries, dN, Av, slot, codes, data, 3)


@parallel_kernel(cache=True, nogil=True)
def gather_consistent_mass(ptr, entries, N, mass, slot, codes, m_blocks):
    """Consistent mass M_IJ = Σ_p m_p N_I(X_p) N_J(X_p) (a scalar per block), row-parallel."""
    n_rows = ptr.shape[0] - 1
    ns = N.shape[1]
    for r in prange(n_rows):
        for c in range(slot.shape[1]):
            q = slot[r, c]
            if q >= 0:
                m_blocks[q] = 0.0
        for e in range(ptr[r], ptr[r + 1]):
            p = entries[e] // ns
            ka = entries[e] % ns
            w = mass[p] * N[p, ka]
            for kb in range(ns):
                q = slot[r, codes[ka, kb]]
                if q >= 0:
                    m_blocks[q] += w * N[p, kb]


@parallel_kernel(cache=True, nogil=True)
def block_scalar_matvec(indptr, indices, m_blocks, u, out):
    """out = (M ⊗ I_d) u for a matrix M with one scalar per block of the BSR pattern."""
    n_rows, d = out.shape
    for r in prange(n_rows):
        for i in range(d):
            acc = 0.0
            for q in range(indptr[r], indptr[r + 1]):
                acc += m_blocks[q] * u[indices[q], i]
            out[r, i] = acc


@njit(cache=True, nogil=True)
def add_block_mass(data, m_blocks, c):
    """data[q] += c m_q I_d for every block q (the consistent mass term of the Newton matrix)."""
    d = data.shape[1]
    for q in range(data.shape[0]):
        for i in range(d):
            data[q, i, i] += c * m_blocks[q]


@njit(cache=True, nogil=True)
def add_diagonal(data, diag_slot, diag):
    """data += diag on the block diagonals (the lumped mass term; diag per dof = row*d + i)."""
    d = data.shape[1]
    for r in range(diag_slot.shape[0]):
        q = diag_slot[r]
        for i in range(d):
            data[q, i, i] += diag[r * d + i]


@njit(cache=True, nogil=True)
def constrain(data, indptr, indices, fixed):
    """Rows and columns of fixed dofs (per dof, row*d + i) become those of the identity."""
    n_rows = indptr.shape[0] - 1
    d = data.shape[1]
    for r in range(n_rows):
        for q in range(indptr[r], indptr[r + 1]):
            c = indices[q]
            for i in range(d):
                for k in range(d):
                    if fixed[r * d + i] or fixed[c * d + k]:
                        data[q, i, k] = 1.0 if (r == c and i == k) else 0.0

"""The generalized Jacobian of the Alart–Curnier function on its engaged rows (solvers.py).

    J = I − G + G ρ (W + εI)        (G: block-diagonal d × d per contact, ρ per contact)

A row where G vanishes (an open contact's components) is a row of the identity, so the
Newton step needs only the engaged rows E: J_EE dr_E = −Φ_E − J_EO dr_O. Block row c of
G ρ W is ρ_c G_c W_c,: : a Numba kernel builds J_EE from W's d × d block rows (delassus.py)
as CSR and J_EO dr_O on the way (the sparse products, the slicing and the CSR → CSC
conversion took ~25% of a Newton iteration on 1600 contacts of a dense compaction).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit


@njit(cache=True)
def _engaged_rows(indptr, indices, blocks, G, rho, shift, engaged, position, dr):
    """CSR arrays of J_EE and the vector J_EO dr_O (position[j]: j's index in E or −1):
    row i = c d + a is e_i − G_c,a + ρ_c G_c,a (W_c,: + shift e_c,:)."""
    d = G.shape[1]
    m = engaged.size
    row_ptr = np.zeros(m + 1, np.int64)
    for e in range(m):
        c = engaged[e] // d
        count = 0
        for k in range(indptr[c], indptr[c + 1]):
            for q in range(d):
                if position[indices[k] * d + q] >= 0:
                    count += 1
        row_ptr[e + 1] = row_ptr[e] + count
    cols = np.empty(row_ptr[m], np.int64)
    data = np.empty(row_ptr[m])
    coupling = np.zeros(m)
    g = np.empty(d)
    for e in range(m):
        i = engaged[e]
        c, a = i // d, i % d
        for b in range(d):
            g[b] = rho[c] * G[c, a, b]
        at = row_ptr[e]
        for k in range(indptr[c], indptr[c + 1]):
            c2 = indices[k]
            for q in range(d):
                value = 0.0
                for b in range(d):
                    value += g[b] * blocks[k, b, q]
                if c2 == c:
                    value += g[q] * shift - G[c, a, q] + (1.0 if a == q else 0.0)
                j = c2 * d + q
                if position[j] >= 0:
                    cols[at] = position[j]
                    data[at] = value
                    at += 1
                else:
                    coupling[e] += value * dr[j]
    return row_ptr, cols, data, coupling


def engaged_jacobian(W: sp.bsr_matrix, G: np.ndarray, rho: np.ndarray, engaged: np.ndarray,
                     dr: np.ndarray, shift: float = 0.0) -> tuple[sp.csr_matrix, np.ndarray]:
    """(J_EE, J_EO dr_O) of J = I − G + G ρ (W + shift I): W as d × d block rows (BSR),
    G (n, d, d), ρ (n,), the engaged rows E (sorted), dr the step's values on the other
    rows (only dr_O is read). An engaged contact's block row must hold its diagonal block
    (the I − G terms are added there): engaged rows are movable (G vanishes where
    W_cc,nn = 0), and a contact touching a body is in its own block row (delassus.py)."""
    n, d = G.shape[0], G.shape[1]
    position = -np.ones(n * d, np.int64)
    position[engaged] = np.arange(engaged.size)
    row_ptr, cols, data, coupling = _engaged_rows(  # W's own index arrays (int32 or 64)
        W.indptr, W.indices, W.data, G, rho, float(shift), engaged, position, dr)
    return sp.csr_matrix((data, cols, row_ptr), shape=(engaged.size, engaged.size)), coupling

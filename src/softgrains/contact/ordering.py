"""A fill-reducing order for the contact Newton matrix's engaged rows (newton_matrix.py).

J_EE's pattern is that of W on the engaged contacts: contacts c and c' are coupled where
they touch a common body, so each grain's contacts form a clique and the cliques are
chained through the contact network. SuperLU's column orderings (COLAMD, the default, or
minimum degree on A + Aᵀ) fill such a network's factors as a 2D grid ordered without
separators: on a 1000-grain dense compaction's J_EE (20 290 rows, 1.5 M nonzeros) the
factors hold 13.7 M entries and take 0.53 s. Nested dissection of the contacts' graph
(METIS_NodeND through pymetis) orders each separator after the two halves it splits: 7.0 M
entries, 0.18 s with the ordering (session 56, this 2-core AMD EPYC). At 772 rows (30
grains) the ordering costs more than it saves (3.2 ms with COLAMD, 2.7 + 2.5 ms
dissected); at 5680 rows (300 grains) it pays (67 ms, 16 + 31 ms); the 30-grain
compaction at D/h 20 (1650–1870 rows, ~190 entries a row) is about the crossover (COLAMD
18–25 ms, dissected 15–21 ms + an ordering of 13–20 ms on the rows' graph, less on the
contacts'). Below DISSECTION_ROWS engaged rows SuperLU's own ordering is kept. Where METIS
fails, a warning says so and SuperLU's ordering is kept too.
"""

from __future__ import annotations

import warnings

import numpy as np
import pymetis
import scipy.sparse as sp
from numba import njit

from softgrains.contact.delassus import BlockRows

# engaged rows from which J_EE is ordered by nested dissection (5680 rows of a 300-grain
# compaction: 67 ms with COLAMD, 16 + 31 ms dissected; 772 rows: no gain)
DISSECTION_ROWS = 2000


@njit(cache=True)
def _member_pattern(start, end, indices, contacts, place):
    """(indptr, adjacency, canonical): block rows ``contacts`` of W's pattern (row c is
    ``indices[start[c]:end[c]]``) restricted to the members (``place`` ≥ 0: their index),
    without the diagonal; canonical: each row strictly increasing (sorted, no duplicate)
    and each entry (e, j) with its mirror (j, e) — as delassus builds W's rows (c and c'
    touch a common body). A row unsorted or repeated, or a mirror missing: not canonical
    (METIS needs a symmetric graph without duplicate edges)."""
    m = contacts.size
    ptr = np.zeros(m + 1, np.int64)
    for e in range(m):
        count = 0
        for q in range(start[contacts[e]], end[contacts[e]]):
            j = place[indices[q]]
            if j >= 0 and j != e:
                count += 1
        ptr[e + 1] = ptr[e] + count
    adjacency = np.empty(ptr[m], np.int64)
    for e in range(m):
        k = ptr[e]
        for q in range(start[contacts[e]], end[contacts[e]]):
            j = place[indices[q]]
            if j >= 0 and j != e:
                adjacency[k] = j
                k += 1
    for e in range(m):
        for q in range(ptr[e] + 1, ptr[e + 1]):
            if adjacency[q] <= adjacency[q - 1]:
                return ptr, adjacency, False
    for e in range(m):
        for q in range(ptr[e], ptr[e + 1]):
            j = adjacency[q]
            at = np.searchsorted(adjacency[ptr[j]:ptr[j + 1]], e)
            if at == ptr[j + 1] - ptr[j] or adjacency[ptr[j] + at] != e:
                return ptr, adjacency, False
    return ptr, adjacency, True


def contact_graph(W: BlockRows, contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The adjacency of ``contacts`` (sorted, distinct) in W's block pattern, symmetric
    and without its diagonal, as CSR arrays (indptr, indices): c ~ c' where block row c
    holds c' or block row c' holds c (both among ``contacts``)."""
    W.ensure(contacts)
    place = np.full(W.n, -1, np.int64)
    place[contacts] = np.arange(contacts.size)
    ptr, adjacency, canonical = _member_pattern(W.start, W.end, W.indices, contacts, place)
    if canonical:
        return ptr, adjacency
    # (a pattern given by hand, e.g. a BSR matrix in a test: made symmetric, duplicates
    # summed)
    graph = sp.csr_matrix((np.ones(adjacency.size), adjacency, ptr),
                          shape=(contacts.size, contacts.size))
    graph = (graph + graph.T).tocsr()
    graph.sort_indices()
    return graph.indptr.astype(np.int64), graph.indices.astype(np.int64)


def dissection_order(W: BlockRows, rows: np.ndarray) -> np.ndarray | None:
    """``rows`` (rows of J: contact c's component a is row c d + a; sorted) reordered by
    nested dissection of their contacts' graph, a contact's rows kept together; ``rows``
    as they are for fewer than 3 contacts; None where METIS fails (with a warning)."""
    d = W.d
    contacts, owner = np.unique(rows // d, return_inverse=True)
    if contacts.size < 3:  # (nothing to order; METIS stops the process on an empty graph)
        return rows
    try:
        perm, _ = pymetis.nested_dissection(
            pymetis.CSRAdjacency(*contact_graph(W, contacts)))
    except (RuntimeError, ValueError) as err:
        warnings.warn(f"nested dissection of {contacts.size} contacts failed ({err}): "
                      "SuperLU's own ordering instead", RuntimeWarning, stacklevel=2)
        return None
    rank = np.empty(contacts.size, np.int64)
    rank[np.asarray(perm, np.int64)] = np.arange(contacts.size)
    return rows[np.argsort(rank[owner] * d + rows % d, kind="stable")]

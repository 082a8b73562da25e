"""A fill-reducing order for the contact Newton matrix's engaged rows (newton_matrix.py).

J_EE's pattern is that of W on the engaged contacts: contacts c and c' are coupled where
they touch a common body, so each grain's contacts form a clique and the cliques are
chained through the contact network. SuperLU's column orderings (COLAMD, the default, or
minimum degree on A + Aᵀ) fill such a network's factors as a 2D grid ordered without
separators: on a 1000-grain dense compaction's J_EE (20 290 rows, 1.5 M nonzeros) the
factors hold 13.7 M entries and take 0.53 s. Nested dissection of the contacts' graph
(METIS_NodeND through pymetis) orders each separator after the two halves it splits: 7.0 M
entries, 0.18 s with the ordering (session 56, this 2-core AMD EPYC). Below
DISSECTION_ROWS engaged rows the ordering costs what it saves (772 rows: 3.2 ms with
COLAMD, 2.7 + 2.5 ms), and SuperLU's own ordering is kept.
"""

from __future__ import annotations

import numpy as np
import pymetis
import scipy.sparse as sp

from softgrains.contact.delassus import BlockRows

# engaged rows from which J_EE is ordered by nested dissection (5680 rows of a 300-grain
# compaction: 67 ms with COLAMD, 16 + 31 ms dissected; 772 rows: no gain)
DISSECTION_ROWS = 2000


def contact_graph(W: BlockRows, contacts: np.ndarray) -> sp.csr_matrix:
    """The adjacency of ``contacts`` (sorted, distinct) in W's block pattern, as a symmetric
    CSR pattern without its diagonal: c ~ c' where block row c holds c' (both among
    ``contacts``)."""
    W.ensure(contacts)
    place = np.full(W.n, -1, np.int64)
    place[contacts] = np.arange(contacts.size)
    counts = W.end[contacts] - W.start[contacts]
    rows = np.repeat(np.arange(contacts.size), counts)
    first = np.cumsum(counts) - counts  # each row's first entry among the gathered
    entries = np.arange(rows.size) + np.repeat(W.start[contacts] - first, counts)
    cols = place[W.indices[entries]]
    keep = (cols >= 0) & (cols != rows)
    graph = sp.csr_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])),
                          shape=(contacts.size, contacts.size))
    graph = (graph + graph.T).tocsr()
    graph.sort_indices()
    return graph


def dissection_order(W: BlockRows, rows: np.ndarray) -> np.ndarray:
    """``rows`` (rows of J: contact c's component a is row c d + a; sorted) reordered by
    nested dissection of their contacts' graph, a contact's rows kept together."""
    d = W.d
    contacts, owner = np.unique(rows // d, return_inverse=True)
    graph = contact_graph(W, contacts)
    perm, _ = pymetis.nested_dissection(
        pymetis.CSRAdjacency(graph.indptr.astype(np.int64), graph.indices.astype(np.int64)))
    rank = np.empty(contacts.size, np.int64)
    rank[np.asarray(perm, np.int64)] = np.arange(contacts.size)
    return rows[np.argsort(rank[owner] * d + rows % d, kind="stable")]

"""The nested-dissection order of the contact Newton matrix's engaged rows (ordering.py)."""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from softgrains.contact.delassus import BlockRows
from softgrains.contact.newton_matrix import NewtonMatrix
from softgrains.contact.ordering import DISSECTION_ROWS, dissection_order


def lattice_delassus(k: int, d: int, seed: int = 0) -> sp.bsr_matrix:
    """W = H Hᵀ + I/10 for k × k grains on a square lattice, one contact between each pair
    of neighbours, H_c = [R_c on its first grain, −R_c on its second] (R_c random d × d):
    W's block c c' is not zero where contacts c and c' touch a common grain, as a packing's."""
    rng = np.random.default_rng(seed)
    grain = np.arange(k * k).reshape(k, k)
    pairs = np.vstack([np.c_[grain[:, :-1].ravel(), grain[:, 1:].ravel()],
                       np.c_[grain[:-1].ravel(), grain[1:].ravel()]])
    n = len(pairs)
    R = rng.normal(size=(n, d, d))
    H = sp.bsr_matrix((np.concatenate([R[:, None], -R[:, None]], axis=1).reshape(-1, d, d),
                       pairs.ravel(), np.arange(0, 2 * n + 1, 2)),
                      shape=(n * d, k * k * d))
    return sp.bsr_matrix((H @ H.T + 0.1 * sp.identity(n * d)).tocsr(), blocksize=(d, d))


@pytest.mark.parametrize("d", [2, 3])
def test_the_order_keeps_each_contacts_rows_together_in_component_order(d):
    """Every engaged row once; a contact's rows adjacent, normal first (the order only
    permutes contacts)."""
    W = BlockRows.from_bsr(lattice_delassus(8, d))
    rng = np.random.default_rng(1)
    rows = np.flatnonzero(rng.uniform(size=W.n * d) < 0.7)
    order = dissection_order(W, rows)
    assert np.array_equal(np.sort(order), rows)
    contact = order // d
    starts = np.flatnonzero(np.r_[True, contact[1:] != contact[:-1]])
    assert starts.size == np.unique(contact).size  # each contact in one run
    runs = np.split(order, starts[1:])
    assert all(np.all(np.diff(run) > 0) for run in runs)


@pytest.mark.parametrize("d", [2, 3])
def test_a_large_contact_network_is_factorised_with_less_fill_and_solves_the_same(d):
    """A 40 × 40-grain lattice's 3120 contacts, all sticking (J_EE = ρ W, 6240 / 9360 rows,
    past DISSECTION_ROWS): the dissected factors hold under 60% of SuperLU's own ordering's
    entries (measured 0.41 / 0.35), and the Newton step solves J dr = b to round-off."""
    W = lattice_delassus(40, d)
    n = W.shape[0] // d
    assert n * d >= DISSECTION_ROWS
    G = np.broadcast_to(np.eye(d), (n, d, d)).copy()
    rho = np.full(n, 0.5)
    solver = NewtonMatrix(W, rho)
    b = np.random.default_rng(2).normal(size=n * d)
    dr = solver.solve(G, b)
    J = 0.5 * W.tocsr()
    np.testing.assert_allclose(J @ dr, b, atol=1e-9 * np.abs(b).max())
    lu = solver.base.lu
    assert solver.base.dissected
    reference = spla.splu(J.T.tocsc())
    ratio = (lu.L.nnz + lu.U.nnz) / (reference.L.nnz + reference.U.nnz)
    assert ratio < 0.6, ratio


def test_the_contact_graph_is_ws_block_pattern_among_the_contacts_symmetric():
    """contact_graph: c ~ c' where W's block row c holds c' (both chosen), no diagonal, the
    same as SciPy's pattern; a pattern not symmetric (by hand) is made symmetric."""
    from softgrains.contact.ordering import contact_graph

    W = lattice_delassus(6, 2)
    rows = BlockRows.from_bsr(W)
    chosen = np.flatnonzero(np.random.default_rng(3).uniform(size=rows.n) < 0.6)
    ptr, adjacency = contact_graph(rows, chosen)
    pattern = sp.csr_matrix((np.ones(W.indices.size), W.indices, W.indptr))[chosen][:, chosen]
    pattern.setdiag(0.0)
    pattern.eliminate_zeros()
    pattern.sort_indices()
    np.testing.assert_array_equal(ptr, pattern.indptr)
    np.testing.assert_array_equal(adjacency, pattern.indices)
    one_way = BlockRows.from_bsr(sp.bsr_matrix(np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 0.0],
                                                         [0.0, 1.0, 1.0]]), blocksize=(1, 1)))
    ptr, adjacency = contact_graph(one_way, np.arange(3))
    np.testing.assert_array_equal(ptr, [0, 1, 3, 4])
    np.testing.assert_array_equal(adjacency, [1, 0, 2, 1])
    repeated = BlockRows(3, 1)  # a block column twice in each row (METIS must not see it)
    repeated.start[:], repeated.end[:], repeated.built[:] = [0, 2, 4], [2, 4, 6], True
    repeated.indices = np.array([1, 1, 0, 0, 1, 1])
    repeated.data, repeated.size = np.ones((6, 1, 1)), 6
    ptr, adjacency = contact_graph(repeated, np.arange(3))
    np.testing.assert_array_equal(ptr, [0, 1, 3, 4])
    np.testing.assert_array_equal(adjacency, [1, 0, 2, 1])


def test_a_factorization_whose_diagonal_pivots_fail_the_backward_error_is_redone(monkeypatch):
    """Where the dissected factorization's first solve misses BACKWARD_ERROR (forced), J_EE
    is factorised again in the same order with partial pivoting; where METIS fails, a
    warning and SuperLU's own ordering; a problem with no engaged row (all contacts open)
    past the bound is the identity."""
    from softgrains.contact import newton_matrix, ordering

    d = 2
    W = lattice_delassus(12, d)
    n = W.shape[0] // d
    G = np.broadcast_to(np.eye(d), (n, d, d)).copy()
    b = np.random.default_rng(4).normal(size=n * d)
    monkeypatch.setattr(newton_matrix, "DISSECTION_ROWS", 0)
    monkeypatch.setattr(newton_matrix, "BACKWARD_ERROR", -1.0)
    solver = NewtonMatrix(W, np.full(n, 0.5))
    dr = solver.solve(G, b)
    np.testing.assert_allclose(0.5 * W.tocsr() @ dr, b, atol=1e-9 * np.abs(b).max())
    assert solver.repivoted == 1 and solver.factorizations == 2
    assert solver.base.dissected and solver.base.pivot == 1.0
    monkeypatch.setattr(newton_matrix, "BACKWARD_ERROR", 1e-12)
    solver = NewtonMatrix(W, np.full(n, 0.5))
    solver.solve(G, b)
    assert solver.repivoted == 0 and solver.base.backward_error(solver.solve(G, b), b) < 1e-15

    with warnings.catch_warnings():  # (METIS itself: no graph to order, no warning)
        warnings.simplefilter("error")
        np.testing.assert_array_equal(NewtonMatrix(W, np.full(n, 0.5)).solve(0.0 * G, b), b)

    def failing(*args, **kwargs):
        raise RuntimeError("METIS_ERROR")

    monkeypatch.setattr(ordering.pymetis, "nested_dissection", failing)
    solver = NewtonMatrix(W, np.full(n, 0.5))
    with pytest.warns(RuntimeWarning, match="nested dissection"):
        dr = solver.solve(G, b)
    np.testing.assert_allclose(0.5 * W.tocsr() @ dr, b, atol=1e-9 * np.abs(b).max())
    assert not solver.base.dissected

"""The contact sites' maps (contact/sites.py)."""

import numpy as np
import pytest
import scipy.sparse as sp

from softgrains.contact.detection import ContactNodes
from softgrains.contact.problem import row_impulses
from softgrains.contact.sites import (
    Members,
    SideStencils,
    Slots,
    _site_map,
    _site_rows_of,
    subset,
)


def _contacts_and_stencils(rng, nodal: bool, n: int = 9, d: int = 2):
    """n contacts among deformable bodies 0 and 1 and a wall 2 (on either side), each
    side's site a random stencil of 3 node rows (of 8) with random d × d blocks
    (``nodal``: a node row of its own, keyed by the row: no site map H); some sites
    shared."""
    pairs = np.array([(0, 1), (0, 2), (1, 2), (2, 0)])[rng.integers(0, 4, n)]
    contacts = ContactNodes(np.arange(n), pairs[:, 0], pairs[:, 1], rng.standard_normal((n, d)),
                            -np.ones(n, np.int64), -np.ones(n, np.int64))
    sides = []
    for side in range(2):
        rows = rng.integers(0, 8, (n, 1 if nodal else 3))
        blocks = (np.broadcast_to(np.eye(d), (n, 1, d, d)).copy() if nodal
                  else rng.standard_normal((n, 3, d, d)))
        key = rows[:, 0].copy() if nodal else -1 - np.arange(n) - 100 * side
        key[n - 1] = key[0]  # the last contact shares the first one's site
        rows[n - 1], blocks[n - 1] = rows[0], blocks[0]
        wall = pairs[:, side] == 2
        rows[wall] = -1
        sides.append(SideStencils(rows, blocks, key))
    return contacts, (sides[0], sides[1])


def _site_velocities(slots: Slots, fields: dict, d: int) -> np.ndarray:
    """Each contact's relative velocity v_α − v_β at its sites (walls at rest)."""
    zero = np.zeros((slots.a_slot.size, d))
    return slots.relative_velocities(slots.stack(lambda body, rows: fields[body][rows]),
                                     zero, zero)


def _row_impulses(slots: Slots, P: np.ndarray) -> dict:
    """The impulses P (per contact) on each body's node rows (8 rows, d)."""
    Q = row_impulses(slots.a_slot, slots.a_col, slots.b_slot, slots.b_col, slots.k_off, P,
                     int(slots.k_size.sum()))
    out = {}
    for slot, body in enumerate(slots.bodies):
        on_rows = np.zeros((8, P.shape[1]))
        on_rows[slots.rows[slot]] = slots.to_rows(slot, Q[slots.span(slot)])
        out[body] = on_rows
    return out


@pytest.mark.parametrize("nodal", [False, True])
def test_restricted_slots_are_the_slots_of_the_chosen_contacts(nodal):
    """Slots.restricted (the working set of coupling.py): the same site velocities and the
    same impulses on the node rows as slots built from the chosen contacts' stencils, for
    point sites (a site map H) and nodal ones (none), with a body left out or not."""
    rng = np.random.default_rng(3)
    d = 2
    contacts, stencils = _contacts_and_stencils(rng, nodal)
    steps = {0: None, 1: None}
    everywhere = Slots(steps, contacts, stencils)
    assert all((H is None) == nodal for H in everywhere.H)
    fields = {b: rng.standard_normal((8, d)) for b in steps}
    one_body = np.flatnonzero(np.isin(contacts.alpha, [0, 2]) & np.isin(contacts.beta, [0, 2]))
    for chosen in (np.array([4, 1, 3]), np.array([0, 8, 2]), np.array([0, 5, 6]),
                   one_body, np.arange(9)[::-1]):
        restricted = everywhere.restricted(chosen)
        direct = Slots(steps, subset(contacts, chosen), tuple(
            SideStencils(s.rows[chosen], s.blocks[chosen], s.key[chosen]) for s in stencils))
        np.testing.assert_allclose(_site_velocities(restricted, fields, d),
                                   _site_velocities(direct, fields, d), rtol=1e-13,
                                   atol=1e-13)
        np.testing.assert_allclose(_site_velocities(restricted, fields, d),
                                   _site_velocities(everywhere, fields, d)[chosen],
                                   rtol=1e-13, atol=1e-13)
        P = rng.standard_normal((chosen.size, d))
        got, expected = _row_impulses(restricted, P), _row_impulses(direct, P)
        assert restricted.bodies == direct.bodies
        assert restricted.k_size.tolist() == direct.k_size.tolist()
        for body in expected:
            np.testing.assert_allclose(got[body], expected[body], rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("d", [2, 3])
def test_site_rows_are_scipys_row_selection(d):
    """_site_rows_of (the working set's rows of H) gives SciPy's fancy row indexing: the
    same CSR arrays, index types and shape, sites repeated or out of order included."""
    H = sp.random(12 * d, 40, density=0.2, format="csr", random_state=d)
    sites = np.array([3, 0, 7, 11, 3])
    expected = H[(sites[:, None] * d + np.arange(d)).ravel()]
    got = _site_rows_of(H, sites, d)
    assert got.shape == expected.shape
    for name in ("indptr", "indices", "data"):
        assert getattr(got, name).dtype == getattr(expected, name).dtype
        np.testing.assert_array_equal(getattr(got, name), getattr(expected, name))


def test_site_map_is_the_sum_of_each_sites_stencil_blocks():
    """_site_map (a kernel since session 36): H, in SciPy's canonical form, is the map
    v_site = Σ_k B_k v_{row_k} built independently as a dense matrix, for sites from two
    sides of different stencil widths, unordered stencils, padding (row −1), a row twice
    in one site (blocks summed) and sites listed twice (``first`` picks one)."""
    rng = np.random.default_rng(11)
    d = 2
    parts = []
    for n, width in ((6, 4), (5, 2)):
        rows = rng.integers(0, 9, (n, width))
        rows[rng.random((n, width)) < 0.25] = -1
        parts.append((np.arange(n), SideStencils(rows, rng.standard_normal((n, width, d, d)),
                                                 np.zeros(n, np.int64))))
    parts[0][1].rows[0, :2] = 7  # one row twice in a site
    first = np.array([0, 2, 3, 4, 5, 6, 7, 9, 10])  # sites 1 and 8: duplicates left out
    stacked = [(part[1].rows, part[1].blocks) for part in parts]
    site_rows = np.full((11, 4), -1)
    site_blocks = np.zeros((11, 4, d, d))
    site_rows[:6], site_blocks[:6] = stacked[0]
    site_rows[6:, :2], site_blocks[6:, :2] = stacked[1]
    site_rows, site_blocks = site_rows[first], site_blocks[first]
    rows, H = _site_map(parts, first, first.size, d)
    np.testing.assert_array_equal(rows, np.unique(site_rows[site_rows >= 0]))
    dense = np.zeros((first.size * d, rows.size * d))
    for s, k in zip(*np.nonzero(site_rows >= 0), strict=True):
        c = int(np.searchsorted(rows, site_rows[s, k]))
        dense[s * d:(s + 1) * d, c * d:(c + 1) * d] += site_blocks[s, k]
    assert H.has_canonical_format
    np.testing.assert_allclose(H.toarray(), dense, rtol=1e-15, atol=1e-15)


def test_distinct_pairs_are_the_sorted_set_of_pairs():
    """sites._distinct_pairs: the distinct (α, β) of the contacts ascending, as the sorted
    set of tuples it replaced (none for no contact)."""
    from softgrains.contact.sites import _distinct_pairs

    rng = np.random.default_rng(2)
    alpha, beta = rng.integers(0, 6, 200), rng.integers(6, 12, 200)
    expected = sorted({(int(a), int(b)) for a, b in zip(alpha, beta, strict=True)})
    assert _distinct_pairs(alpha, beta) == expected
    assert _distinct_pairs(alpha[:0], beta[:0]) == []


def test_members_are_the_indices_of_each_owner_ascending():
    """sites.Members(owner)(v) is np.flatnonzero(owner == v) for every v (walls −1, bodies
    with no contact, repeated owners), from one sort instead of a pass over all contacts a
    body."""
    owner = np.random.default_rng(5).integers(-1, 40, size=500)
    of = Members(owner)
    for v in range(-2, 42):
        np.testing.assert_array_equal(of(v), np.flatnonzero(owner == v))

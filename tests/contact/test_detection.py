"""Contact nodes and normals (ALGORITHM.md §4, VALIDATION.md B5, first part)."""

import numpy as np
import pytest

from softgrains.contact import find_contact_nodes, nodal_field
from softgrains.geometry import Disk, Rectangle, seed_points
from softgrains.grid.lattice import Lattice
from softgrains.grid.stencils import body_stencils

H = 0.1
LAT = Lattice.covering([0.0, 0.0], [3.0, 3.0], H)


def _field(index, shape, kind=0):
    x, v0 = seed_points(shape, LAT.domain_lower, H, 2)
    return nodal_field(index, body_stencils(LAT, kind, x), np.full(len(x), 1000.0 * v0)), x


@pytest.mark.parametrize("normal", ["difference", "alpha", "beta"])
@pytest.mark.parametrize("kind", [0, 1], ids=["linear", "bspline2"])
def test_normals_of_two_half_planes_point_from_beta_into_alpha(kind, normal):
    """Two blocks a quarter cell apart: every contact normal satisfies
    n·(centroid_α − centroid_β) > 0, and away from the corners n = (−1, 0), whichever
    gradient(s) the normal comes from."""
    fa, xa = _field(0, Rectangle(np.array([0.5, 0.5]), np.array([1.5, 2.5])), kind)
    fb, xb = _field(1, Rectangle(np.array([1.525, 0.5]), np.array([2.5, 2.5])), kind)
    contacts = find_contact_nodes(LAT, [fa, fb], normal_kind=normal)
    assert len(contacts) > 0
    assert np.all(contacts.alpha == 0) and np.all(contacts.beta == 1)
    towards_alpha = xa.mean(axis=0) - xb.mean(axis=0)
    assert np.all(contacts.normal @ towards_alpha > 0)
    ny = LAT.node_origin[1] + H * (contacts.node // LAT.n_nodes[0])
    middle = (ny > 0.8) & (ny < 2.2)
    assert np.allclose(contacts.normal[middle], [-1.0, 0.0], atol=1e-12)
    assert np.allclose(np.linalg.norm(contacts.normal, axis=1), 1.0)


def test_separated_bodies_have_no_contact_node():
    fa, _ = _field(0, Disk(np.array([1.0, 1.5]), 0.3))
    fb, _ = _field(1, Disk(np.array([2.0, 1.5]), 0.3))
    assert len(find_contact_nodes(LAT, [fa, fb])) == 0


def test_three_bodies_at_one_node_give_three_contacts():
    """Three blocks meeting near the node (1.5, 1.5): one contact per pair at that node."""
    fa, _ = _field(0, Rectangle(np.array([1.0, 1.0]), np.array([1.48, 1.48])))
    fb, _ = _field(1, Rectangle(np.array([1.52, 1.0]), np.array([2.0, 1.48])))
    fc, _ = _field(2, Rectangle(np.array([1.0, 1.52]), np.array([2.0, 2.0])))
    contacts = find_contact_nodes(LAT, [fa, fb, fc])
    i, j = np.rint((np.array([1.5, 1.5]) - LAT.node_origin) / H).astype(int)
    at_node = contacts.node == i + j * LAT.n_nodes[0]
    pairs = sorted(zip(contacts.alpha[at_node], contacts.beta[at_node], strict=True))
    assert pairs == [(0, 1), (0, 2), (1, 2)]


@pytest.mark.parametrize("angle", [0.0, 30.0, 45.0])
@pytest.mark.parametrize("gap", [0.0, 0.3 * H])
def test_boundary_gap_between_ring_seeded_disks_at_any_angle(angle, gap):
    """ALGORITHM.md §4: two ring-seeded disks (R = 0.5, D/h = 10) a known distance apart
    along a line at ``angle``; the gap at the lattice node between them is recovered within
    0.05 δ. Ring cells are aligned with the radius: a lattice square's half-extent ½δ‖n‖₁
    would make each disk 0.21 δ larger at 45°."""
    from softgrains.contact.detection import ContactNodes
    from softgrains.contact.gap import boundary_gaps
    from softgrains.geometry import seed_disk_rings

    delta, radius = H / 2, 0.5
    node = np.array([15, 15]) + 2  # lattice node at (1.5, 1.5) (two padding nodes)
    X = LAT.node_origin + H * node
    n = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
    centres = X + (radius + gap / 2) * n, X - (radius + gap / 2) * n
    points = {b: seed_disk_rings(Disk(c, radius), delta)[0] for b, c in enumerate(centres)}
    index = np.array([node[0] + LAT.n_nodes[0] * node[1]])
    contacts = ContactNodes(index, np.array([0]), np.array([1]), n[None, :],
                            np.zeros(1, np.int64), np.zeros(1, np.int64))
    reach = H * np.sqrt(2)
    found = boundary_gaps(LAT, contacts, points, delta, reach, round_bodies={0, 1})[0]
    assert found == pytest.approx(gap, abs=0.05 * delta)


@pytest.mark.parametrize("angle", [0.0, 20.0, 37.0, 45.0, 60.0])
def test_boundary_gap_never_reports_an_overlap_between_separated_grains(angle):
    """Two lattice-seeded disks (B-splines, R = 4.5 h and 3.5 h) whose cells are half a cell
    apart (circles 0.6 h apart along a line at ``angle``): no contact node, with its
    mass-gradient normal, reports an overlap. A body with no point on the line through a
    node is absent there (open gap); falling back to all points within the reach, as before
    session 7, gave −0.48 h at 0° and −0.57 h at 60°."""
    from softgrains.contact.gap import boundary_gaps

    n = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
    c, gap = np.array([1.513, 1.513]), 0.6 * H
    fa, xa = _field(0, Disk(c + (0.45 + gap / 2) * n, 0.45), kind=1)
    fb, xb = _field(1, Disk(c - (0.35 + gap / 2) * n, 0.35), kind=1)
    contacts = find_contact_nodes(LAT, [fa, fb])
    assert len(contacts) > 5
    gaps = boundary_gaps(LAT, contacts, {0: xa, 1: xb}, H / 2, 1.5 * H * np.sqrt(2))
    assert gaps.min() >= 0.0


def test_a_normal_pointing_from_alpha_to_beta_is_turned_towards_alpha():
    """gap.oriented_normals: n·(x̄_α − x̄_β) must be > 0 near the node; a reversed normal is
    replaced by the direction between the local centroids, a right one and a wall's kept."""
    from softgrains.contact.detection import ContactNodes
    from softgrains.contact.gap import near_points, oriented_normals

    _, xa = _field(0, Rectangle(np.array([1.0, 1.0]), np.array([1.5, 2.0])))
    _, xb = _field(1, Rectangle(np.array([1.5, 1.0]), np.array([2.0, 2.0])))
    node = np.rint((np.array([1.5, 1.5]) - LAT.node_origin) / H).astype(int)
    index = np.full(3, node[0] + LAT.n_nodes[0] * node[1])
    given = np.array([[1.0, 0.0], [-0.8, 0.6], [1.0, 0.0]])
    contacts = ContactNodes(index, np.zeros(3, np.int64), np.ones(3, np.int64), given,
                            np.zeros(3, np.int64), np.zeros(3, np.int64))
    X = np.tile(LAT.node_origin + H * node, (3, 1))
    points = {0: xa, 1: xb}
    near = near_points(contacts, X, points, 1.5 * H)
    normal = oriented_normals(contacts, X, points, near, np.array([False, False, True]))
    assert np.allclose(normal[0], [-1.0, 0.0], atol=1e-12)
    assert np.allclose(normal[1:], given[1:])


def test_effective_gap_removes_only_the_overlap_beyond_the_tolerance():
    """g̃ = g (gap), 0 (overlap within t), r (g + t) (deeper overlap), NaN → 0."""
    from softgrains.contact.gap import effective_gaps

    g = np.array([0.3, 0.0, -0.1, -0.2, -1.0, np.nan])
    assert np.allclose(effective_gaps(g, 0.0), [0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert np.allclose(effective_gaps(g, 0.5), [0.3, 0.0, -0.05, -0.1, -0.5, 0.0])
    assert np.allclose(effective_gaps(g, 0.5, 0.2), [0.3, 0.0, 0.0, 0.0, -0.4, 0.0])


@pytest.mark.parametrize("walls_first", [False, True])
def test_a_grain_in_a_box_corner_gets_each_walls_inner_face_normal(walls_first):
    """A grain squeezed into the top-right corner of a box whose top wall ends where the right wall
    begins (the [sample] layout): at every node the top wall's normal is (0, −1) and the right
    wall's (−1, 0). The nearest face of the top wall to the corner nodes is its end against
    the right wall, which gave normals (+1, 0) and (−1, 0) at one node: two impulses that
    cancel on the grain and can grow without bound (seen: a 400 σ0 spike of the wall stress
    in the frictional compaction)."""
    W, Y = 2.0, 2.03  # inner corner: the right wall on a node line, the top wall between
    t = 0.3
    grain = Rectangle(np.array([W - 0.5, Y - 0.5]), np.array([W - 0.02, Y + 0.02]))
    top = Rectangle(np.array([0.5, Y]), np.array([W, Y + t]))
    right = Rectangle(np.array([W, 0.5]), np.array([W + t, Y + t]))
    g, t_, r = (2, 0, 1) if walls_first else (0, 1, 2)  # body indices
    shapes = {g: grain, t_: top, r: right}
    fields = [_field(i, shapes[i])[0] for i in range(3)]
    contacts = find_contact_nodes(LAT, fields, walls={t_: top, r: right})
    grain_top = (contacts.alpha == g) & (contacts.beta == t_)
    grain_right = (contacts.alpha == g) & (contacts.beta == r)
    assert grain_top.any() and grain_right.any()
    assert np.allclose(contacts.normal[grain_top], [0.0, -1.0])
    assert np.allclose(contacts.normal[grain_right], [-1.0, 0.0])


def test_pairs_within_groups_are_the_nested_loops_pairs_in_order():
    """detection._pairs_within (the kernel that lists the body pairs at a node): every
    pair a < b within each group, group after group, in the order of the nested loops it
    replaced; none from groups of one."""
    from softgrains.contact.detection import _pairs_within

    starts, counts = np.array([0, 4, 5, 9]), np.array([4, 1, 4, 3])
    expected = [(a, b) for s, c in zip(starts, counts, strict=True)
                for a in range(s, s + c) for b in range(a + 1, s + c)]
    a, b = _pairs_within(starts, counts)
    assert list(zip(a.tolist(), b.tolist(), strict=True)) == expected
    assert _pairs_within(starts[:0], counts[:0])[0].size == 0

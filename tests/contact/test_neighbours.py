"""The cell-list ball query (contact/neighbours.py) against a brute-force search."""

import numpy as np
import pytest

from softgrains.contact.neighbours import PointCells


@pytest.mark.parametrize("d", [2, 3])
def test_ball_finds_exactly_the_points_within_the_radius(d):
    rng = np.random.default_rng(d)
    points = rng.random((300, d)) * 6.0
    x = rng.random((200, d)) * 10.0 - 2.0  # some queries far outside the points' box
    radius = 1.1
    ptr, flat = PointCells(points, radius).ball(x)
    distance = np.linalg.norm(x[:, None, :] - points[None, :, :], axis=2)
    for i in range(len(x)):
        found = flat[ptr[i]:ptr[i + 1]]
        assert len(set(found.tolist())) == found.size  # each point once
        assert set(found.tolist()) == set(np.flatnonzero(distance[i] <= radius).tolist())
    assert ptr[-1] > 0


def test_ball_on_a_single_point_and_on_no_queries():
    cells = PointCells(np.array([[0.5, 0.5]]), 0.3)
    ptr, flat = cells.ball(np.array([[0.5, 0.7], [0.5, 0.81]]))
    assert ptr.tolist() == [0, 1, 1] and flat.tolist() == [0]
    ptr, flat = cells.ball(np.zeros((0, 2)))
    assert ptr.tolist() == [0] and flat.size == 0


def test_ball_finds_the_points_at_exactly_the_radius_on_a_lattice():
    """Lattice points (spacing h/2) queried at lattice points with the radius 1.5 h: many
    points lie at exactly the radius, where round-off could put them two cells of side
    1.5 h away from the query's cell (the cells are a hair wider than the radius)."""
    h = 0.1
    axis = np.arange(40) * 0.5 * h + 0.0123
    points = np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1).reshape(-1, 2)
    radius = 1.5 * h
    ptr, flat = PointCells(points, radius).ball(points)
    distance = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    within = distance <= radius
    counts = np.diff(ptr)
    assert np.array_equal(counts, within.sum(axis=1))
    for i in range(0, len(points), 7):
        assert set(flat[ptr[i]:ptr[i + 1]].tolist()) == set(np.flatnonzero(within[i]).tolist())


def test_far_flung_points_get_fewer_larger_cells():
    """Two points far apart against the radius: the cells stay few (at most 8 a point and
    64), and the queries are still exact."""
    points = np.array([[0.0, 0.0], [1e6, 1e6]])
    cells = PointCells(points, 1.0)
    assert cells.start.size - 1 <= 8 * 2 + 64
    ptr, flat = cells.ball(np.array([[0.5, 0.5], [1e6, 1e6 - 1.0], [5e5, 5e5]]))
    assert ptr.tolist() == [0, 1, 2, 2] and flat.tolist() == [0, 1]

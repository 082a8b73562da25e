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

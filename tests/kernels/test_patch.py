"""Patch tests of the point update (VALIDATION.md A1): affine nodal motion gives exact F;
a rigid rotation gives no stress (objectivity)."""

import numpy as np
import pytest

from softgrains.grid.transfers import grid_to_particles
from softgrains.materials import lame_parameters


def _update(small_body, kind, nodal_map):
    lat, x, v0, box, nodes, N, dN, s = small_body(kind)
    n = len(x)
    xn = lat.node_positions(box)
    u = nodal_map(xn) - xn
    lam, mu = lame_parameters(1.0e6, 0.3)
    F = np.tile(np.eye(2), (n, 1, 1))
    sigma = np.empty((n, 3, 3))
    vol = np.empty(n)
    v = np.zeros((n, 2))
    zeros = np.zeros((box.size, 2))
    xp = x.copy()
    grid_to_particles(nodes, N, dN, u, zeros, zeros, zeros, 0, np.array([1.0, 1.0, 0.5, 0.25, 0.5]),
                      np.zeros(n, dtype=np.int64), np.full(n, lam), np.full(n, mu),
                      np.full(n, v0), xp, v, np.zeros((n, 2)), F, sigma, vol, 4)
    return x, xp, F, sigma, vol, v0, mu


@pytest.mark.parametrize("kind", [0, 1], ids=["linear", "bspline2"])
def test_affine_motion_is_reproduced_exactly(small_body, kind):
    G = np.array([[1.2, 0.3], [-0.1, 0.8]])
    c = np.array([0.05, -0.02])
    x, xp, F, sigma, vol, v0, _ = _update(small_body, kind, lambda y: y @ G.T + c)
    assert np.allclose(xp, x @ G.T + c, atol=1e-13)
    assert np.allclose(F, G, atol=1e-13)
    assert np.allclose(vol, v0 * np.linalg.det(G), rtol=1e-13)


@pytest.mark.parametrize("kind", [0, 1], ids=["linear", "bspline2"])
def test_rigid_rotation_is_stress_free(small_body, kind):
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    x, xp, F, sigma, vol, v0, mu = _update(small_body, kind, lambda y: (y - 0.5) @ R.T + 0.5)
    assert np.allclose(F, R, atol=1e-13)
    assert np.abs(sigma).max() < 1e-8 * mu
    assert np.allclose(vol, v0, rtol=1e-12)

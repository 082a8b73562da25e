"""Patch tests of the point update (VALIDATION.md A1): affine nodal motion gives exact F;
a rigid rotation gives no stress (objectivity)."""

import numpy as np
import pytest

import softgrains.integrator.implicit as implicit
from softgrains.grid.lattice import Lattice
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


def _moving_block(xs):
    """Points at xs (spacing 0.05) of a neo-Hookean block moving at 1 m/s along x."""
    n, vol = len(xs), np.full(len(xs), 0.05**2)
    lam, mu = lame_parameters(1.0e6, 0.3)
    return implicit.BodyPoints(
        x=xs.copy(), v=np.tile([1.0, 0.0], (n, 1)), a=np.zeros((n, 2)),
        F=np.tile(np.eye(2), (n, 1, 1)), sigma=np.zeros((n, 3, 3)), vol=vol.copy(),
        mass=1000 * vol, vol0=vol.copy(), law=np.zeros(n, dtype=np.int64),
        lam=np.full(n, lam), mu=np.full(n, mu))


def test_points_next_to_a_removed_node_stay_strain_free_in_rigid_motion():
    """A node lighter than the activity threshold is removed from the stencils; the weights
    are renormalised and its gradient moved to the active nodes, so a rigid translation of a
    block whose edge sits 1e-6 h past a node line gives F = I exactly (and the momentum is
    transferred exactly). Without the correction the strain was ~1e-2."""
    h = 0.1
    xs = np.array([[0.325 + 0.05 * i, 0.325 + 0.05 * j] for i in range(4) for j in range(4)])
    xs[xs[:, 0] > 0.45, 0] = 0.5 + 1e-6 * h
    pts = _moving_block(xs)
    stepper = implicit.BodyStepper("block", Lattice.covering([0, 0], [1, 1], h), 0,
                                   implicit.IntegratorSettings(), [])
    stepper.step(pts, np.zeros(2), 1e-3, 0)
    assert np.abs(pts.F - np.eye(2)).max() < 1e-15
    assert np.allclose(pts.v, [1.0, 0.0], atol=1e-14)


def test_fixed_nodes_pass_their_velocity_to_the_points_with_flip():
    """All nodes clamped at rest: after a FLIP step the points are at rest too (the FLIP
    increment starts from the unconstrained nodal velocity)."""
    xs = np.array([[0.325 + 0.05 * i, 0.325 + 0.05 * j] for i in range(4) for j in range(4)])
    pts = _moving_block(xs)
    clamp = implicit.DirichletBox(np.array([-1.0, -1.0]), np.array([2.0, 2.0]),
                                  np.array([True, True]), np.zeros(2))
    stepper = implicit.BodyStepper("block", Lattice.covering([0, 0], [1, 1], 0.1), 0,
                                   implicit.IntegratorSettings(), [clamp])
    stepper.step(pts, np.zeros(2), 1e-3, 0)
    assert np.abs(pts.v).max() < 1e-14 and np.abs(pts.x - xs).max() < 1e-15

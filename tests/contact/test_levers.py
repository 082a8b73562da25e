"""The surface side's lever (contact/levers.py): the moment its impulses gain when they act
where the surface grain's material started, and the rigid-rotation impulses that carry it."""

from types import SimpleNamespace

import numpy as np
import pytest

from softgrains.contact.levers import (
    SurfaceSides,
    lever_moments,
    moment,
    rotation_basis,
    rotation_impulses,
)
from softgrains.grid.lattice import Lattice, NodeBox


def _step(dim: int, seed: int):
    """A body step's stand-in: a box of nodes, some of them active, with lumped masses."""
    rng = np.random.default_rng(seed)
    lattice = Lattice.covering(np.zeros(dim), np.ones(dim), 0.1)
    box = NodeBox(lower=np.full(dim, 2, np.int64), shape=np.array([4, 5, 3][:dim], np.int64))
    active = np.sort(rng.choice(box.size, size=box.size - 3, replace=False))
    m = rng.uniform(0.5, 2.0, active.size)[:, None] * np.ones(dim)
    return SimpleNamespace(stepper=SimpleNamespace(lattice=lattice), box=box, active=active,
                           m=m), lattice.node_positions(box)[active]


@pytest.mark.parametrize("dim, torque", [(2, 0.7), (3, np.array([0.3, -0.2, 0.5]))])
def test_rotation_impulses_carry_the_torque_and_no_net_impulse(dim, torque):
    step, x = _step(dim, seed=dim)
    g = rotation_impulses(rotation_basis(step), torque)
    assert np.allclose(g.sum(axis=0), 0.0, atol=1e-12)
    # about any point, since the net impulse is zero
    for origin in (np.zeros(dim), np.full(dim, 0.37)):
        assert np.allclose(moment(x - origin, g).sum(axis=0), torque, rtol=1e-12, atol=1e-14)


def test_the_lever_of_a_turning_surface_opposes_its_turn_by_alpha_p_r():
    """A round surface grain turned by α (its sites' displacement α ẑ × r) under impulses p
    pressing on it along −r̂ at radius R, against a still grain's points: each site's
    impulse acts where the surface's material started, at x − α ẑ × r, and the moment
    changes by δ × P = (−α ẑ × r) × (−p r̂) = −α p R (the θ-step's error on such a grain
    is +α p R: ΔL = θΔt² ω Σ P R with α = θΔt ω). A relative motion along the normal
    (δ ∥ P) changes no moment."""
    R, alpha, p, n = 0.02, 1e-3, 5.0, 7
    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    radial = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    x = R * radial
    turn = alpha * np.stack([-x[:, 1], x[:, 0]], axis=1)
    one = np.arange(n)[:, None]
    sides = SurfaceSides(contact=np.arange(n), surface=np.ones(n, np.int64),
                         owner=np.zeros(n, np.int64), surface_rows=one,
                         surface_weights=np.ones((n, 1)), owner_rows=one,
                         owner_weights=np.ones((n, 1)), sign=-np.ones(n))
    # the impulse on α (the owner, outside the surface) pushes it out: P_α = p r̂
    P = p * radial
    still = SimpleNamespace(u=np.zeros((n, 2)))
    moments = lever_moments(sides, {0: still, 1: SimpleNamespace(u=turn)}, P)
    assert moments[1] == pytest.approx(-n * alpha * p * R, rel=1e-12)
    # the owner approaching along the normal: no moment
    approach = SimpleNamespace(u=-1e-4 * radial)
    moments = lever_moments(sides, {0: approach, 1: SimpleNamespace(u=np.zeros((n, 2)))}, P)
    assert moments[1] == pytest.approx(0.0, abs=1e-18)

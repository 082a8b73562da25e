"""The spin energy per body (observe/energies.spin_energies) against rigid motions."""

import numpy as np
import pytest

from softgrains.observe.energies import spin_energies


@pytest.mark.parametrize("dim", [2, 3])
def test_spin_energy_is_the_rigid_spin_and_ignores_translation_and_strain(dim):
    rng = np.random.default_rng(dim)
    n = 200
    x = rng.normal(size=(n, dim))
    mass = rng.uniform(0.5, 2.0, n)
    body = np.r_[np.zeros(n // 2, np.int64), np.ones(n - n // 2, np.int64)]
    omega = np.array([0.0, 0.0, 3.0]) if dim == 2 else np.array([0.5, -1.0, 2.0])
    centre = np.array([(mass[body == b, None] * x[body == b]).sum(0) / mass[body == b].sum()
                       for b in (0, 1)])
    r = x - centre[body]
    spin = np.cross(omega, np.c_[r, np.zeros(n)] if dim == 2 else r)[:, :dim]  # ω × r
    translation = np.ones(dim) * 0.7
    # body 0: spin and translation; body 1: translation and a pure stretch (no spin)
    v = np.where((body == 0)[:, None], spin + translation, translation + 0.4 * r)
    energy = spin_energies(mass, x, v, body, 3)
    expected = 0.5 * (mass[body == 0] * (spin[body == 0] ** 2).sum(1)).sum()
    assert energy[0] == pytest.approx(expected, rel=1e-12)
    assert energy[1] == pytest.approx(0.0, abs=1e-12 * expected)
    assert energy[2] == 0.0  # a body without points

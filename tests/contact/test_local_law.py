"""Local Signorini–Coulomb solution (ALGORITHM.md §5, VALIDATION.md B5)."""

import numpy as np
import pytest

from softgrains.contact.local_law import OPEN, SLIP, STICK, local_impulse

N = np.array([0.6, 0.8])  # unit normal, from β into α
T = np.array([-0.8, 0.6])


def _solve(va, vb, ma, mb, mu=0.3, gap_over_dt=0.0):
    """Apply the impulse to a two-node pair; return the post-contact velocities, P, status."""
    m_star = ma * mb / (ma + mb) if np.isfinite(mb) else ma
    P = np.empty(2)
    status = local_impulse(va - vb, N, m_star, m_star, gap_over_dt, mu, P)
    vb_new = vb - P / mb if np.isfinite(mb) else vb
    return va + P / ma, vb_new, P, status


def test_head_on_frictionless_pair_ends_with_zero_normal_velocity_and_exact_momentum():
    va, vb, ma, mb = -2.0 * N + 0.3 * T, 1.5 * N - 0.2 * T, 3.0, 5.0
    va1, vb1, P, status = _solve(va, vb, ma, mb, mu=0.0)
    assert status in (STICK, SLIP)
    assert (va1 - vb1) @ N == pytest.approx(0.0, abs=1e-15)
    assert np.allclose(ma * va1 + mb * vb1, ma * va + mb * vb, rtol=0, atol=1e-14)
    assert (va1 - vb1) @ T == pytest.approx((va - vb) @ T)  # μ = 0: tangential untouched


def test_separating_pair_gets_no_impulse():
    _, _, P, status = _solve(1.0 * N, -1.0 * N, 2.0, 2.0)
    assert status == OPEN and np.all(P == 0.0)


def test_stick_when_the_trial_friction_is_inside_the_cone():
    va, vb = -2.0 * N + 0.1 * T, np.zeros(2)
    va1, vb1, P, status = _solve(va, vb, 2.0, 3.0, mu=0.5)
    assert status == STICK
    assert np.allclose(va1 - vb1, 0.0, atol=1e-15)  # w_t = 0 and w_n = 0
    assert np.linalg.norm(P - (P @ N) * N) <= 0.5 * (P @ N)


def test_slip_has_coulomb_magnitude_and_opposes_sliding():
    va, vb = -1.0 * N + 3.0 * T, np.zeros(2)
    va1, vb1, P, status = _solve(va, vb, 2.0, 3.0, mu=0.2)
    assert status == SLIP
    pn, pt = P @ N, P @ T
    assert abs(pt) == pytest.approx(0.2 * pn)
    assert pt * ((va - vb) @ T) < 0  # opposes the sliding
    assert (va1 - vb1) @ N == pytest.approx(0.0, abs=1e-15)


def test_kinematic_wall_leaves_the_grain_with_the_wall_normal_velocity():
    wall = 0.5 * N + 1.0 * T
    va1, vb1, _, _ = _solve(-3.0 * N, wall, 4.0, np.inf, mu=0.0)
    assert np.array_equal(vb1, wall)
    assert va1 @ N == pytest.approx(wall @ N)


def test_gap_may_be_closed_within_the_step_but_not_crossed():
    g_over_dt = 0.4  # the gap closes at an approach speed of 0.4
    _, _, P, status = _solve(-0.3 * N, np.zeros(2), 2.0, 2.0, gap_over_dt=g_over_dt)
    assert status == OPEN  # too slow to close the gap this step
    va1, vb1, P, status = _solve(-1.0 * N, np.zeros(2), 2.0, 2.0, gap_over_dt=g_over_dt)
    assert status != OPEN
    assert (va1 - vb1) @ N == pytest.approx(-g_over_dt)  # closes exactly the gap

"""The Newton line search (integrator/implicit.py, line_search)."""

import numpy as np

from softgrains.integrator.implicit import line_search


def _flat_problem(floor: float):
    """A residual at its round-off floor (``floor`` whatever the iterate) and a potential
    that rises along the step by round-off: what a converged body moved by an impulse
    change of ~1e-15 h sees (session 35)."""
    r = np.full(4, floor / 2.0)

    def internal_force(u, want_tangent):
        return np.zeros_like(u), 1.0, 0.0  # f_int, min J (no inverted point), W

    def residual(u, f_int):
        return r.copy()

    def potential(u, w_int):
        return 1e-18 * float(np.sum(u))

    return r, internal_force, residual, potential


def test_a_trial_within_the_stopping_threshold_is_taken_whole():
    """Neither the Armijo nor the residual decrease can hold where the residual is at its
    floor: the step took the trial of lowest potential, 1/256 of itself, and the contact
    loop crept at that rate for ~10 iterations a step (the frictionless pre-compaction).
    A trial whose residual is within the body's stopping threshold is converged there, and
    is taken."""
    r, internal_force, residual, potential = _flat_problem(1e-3)
    u, du = np.zeros(4), np.full(4, 1e-15)
    pi = potential(u, 0.0)
    refused = line_search(u, du, r, pi, internal_force, residual, potential)
    assert np.allclose(refused[0], du / 256.0)  # the lowest potential: the shortest trial
    taken = line_search(u, du, r, pi, internal_force, residual, potential, enough=1e-3)
    assert np.array_equal(taken[0], du)
    # a residual above the threshold still asks for a decrease
    above = line_search(u, du, r, pi, internal_force, residual, potential, enough=1e-4)
    assert np.allclose(above[0], du / 256.0)

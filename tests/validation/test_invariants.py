"""VALIDATION.md A1: a free body conserves linear momentum to round-off; angular momentum drift
stays bounded (exact only with affine transfers, which we do not have yet)."""

import numpy as np
import pytest

CASES = {
    "theta-lumped": {},
    "theta-consistent": {"simulation.mass_matrix": "consistent"},
    "newmark-lumped": {"simulation.integrator": "newmark"},
    "theta-lumped-pic": {"simulation.flip": 0.0},
    "theta-consistent-bspline": {"simulation.mass_matrix": "consistent",
                                 "grid.shape_function": "bspline2"},
}


# the consistent-mass bookkeeping solves M_C v = p at every step: it must converge (with
# B-splines it did not before its CG was preconditioned by the lumped mass, session 10)
@pytest.mark.filterwarnings("error:.*M_C v = p did not converge")
@pytest.mark.parametrize("overrides", CASES.values(), ids=CASES.keys())
def test_linear_momentum_is_conserved_to_round_off(run_example, momentum, overrides):
    """A disk with a non-uniform velocity (shear, spin, breathing and a sine): 40 steps."""
    ov = {"bodies.0.velocity_gradient": [[3.0, -5.0], [1.0, -2.0]],
          "bodies.0.velocity_sine": {"amplitude": [0.3, -0.2], "wavenumber": [20.0, 10.0]},
          "simulation.end_time": 0.04, **overrides}
    sim, record = run_example("free_disk.toml", ov, momentum)
    record = np.array(record)
    scale = float(np.sum(sim.model.mass * np.linalg.norm(sim.state.v, axis=1)))
    assert np.abs(record - record[0]).max() <= 1e-13 * scale


def _angular_momentum(sim):
    x, v, m = sim.state.x, sim.state.v, sim.model.mass
    c = (m[:, None] * x).sum(axis=0) / m.sum()
    r = x - c
    return float(np.sum(m * (r[:, 0] * v[:, 1] - r[:, 1] * v[:, 0])))


@pytest.mark.parametrize(("overrides", "bound"),
                         [({}, 0.10), ({"simulation.mass_matrix": "consistent"}, 1e-3)],
                         ids=["lumped-flip", "consistent"])
def test_angular_momentum_drift_of_a_spinning_disk_is_bounded(run_example, overrides, bound):
    """A disk (h = 0.05, n_pc = 2) spinning at 5 rad/s for 1.4 s (1.1 turns), Δt = 7 ms.

    Measured (2026-11-23): lumped FLIP loses 7.1% of its angular momentum (12.7% of its
    energy: the lumped-mass FLIP dissipation, docs/dev-notes.md); the consistent mass with the
    point-level θ update loses 0.04% (energy 0.08%); PIC (flip = 0) damps the spin entirely.
    Neither transfer is affine, so neither conserves it exactly.
    """
    ov = {"bodies.0.velocity": [0.0, 0.0],
          "bodies.0.velocity_gradient": [[0.0, -5.0], [5.0, 0.0]],
          "simulation.dt": 7e-3, "simulation.end_time": 1.4, **overrides}
    sim, record = run_example("free_disk.toml", ov, _angular_momentum, every=10)
    drift = np.abs(np.array(record) / record[0] - 1.0).max()
    assert drift < bound


def test_the_momentum_form_keeps_a_free_disks_angular_momentum(run_example):
    """θ = 1 (backward Euler) with the consistent mass: a disk spinning at 5 rad/s and
    breathing (velocity gradient [[0.5, −5], [5, 0.5]]), 100 steps of 7 ms. With
    simulation.stress_form = "momentum" the internal forces have no moment about the start
    nodes and the step keeps the angular momentum: measured (2026-12-07) 3.3e-6 relative
    drift; with the consistent form 10.6% is lost (its moment −Σ V⁰ skew(P Fⁿᵀ) under the
    breathing stress)."""
    def drift(form):
        ov = {"bodies.0.velocity": [0.0, 0.0],
              "bodies.0.velocity_gradient": [[0.5, -5.0], [5.0, 0.5]],
              "simulation.dt": 7e-3, "simulation.end_time": 0.7, "simulation.theta": 1.0,
              "simulation.mass_matrix": "consistent", "simulation.stress_form": form}
        _, record = run_example("free_disk.toml", ov, _angular_momentum, every=1)
        return np.abs(np.array(record) / record[0] - 1.0).max()

    assert drift("momentum") < 1e-4
    assert drift("consistent") > 0.05

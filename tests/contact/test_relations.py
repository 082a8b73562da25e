"""The two local relations of the coupling loop (ALGORITHM.md §6), warm start, per-pair
friction and what a loop that does not converge does."""

import numpy as np
import pytest

from softgrains import Simulation, load_case
from softgrains.errors import CaseError, SimulationError


def _disk_dropped_on_slab(relation, dt, end_time=0.1, h=0.04, drop=0.01, **contact):
    """A disk (R = 0.2 m, E = 0.1 MPa, c = 10 m/s; D/h = 10 by default) released ``drop``
    above a kinematic slab (top at y = 0.5) under gravity, θ = 1. Δt = 10 ms is
    Δt c/h = 2.5 at D/h = 10."""
    return Simulation(load_case({
        "simulation": {"dt": dt, "end_time": end_time, "theta": 1.0},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [1.0, 1.0]},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "disk", "shape": "disk", "center": [0.5, 0.7 + drop],
                    "radius": 0.2, "material": "gel"},
                   {"name": "slab", "shape": "rectangle", "lower": [0.1, 0.3],
                    "upper": [0.9, 0.5], "material": "gel", "kind": "kinematic"}],
        "gravity": {"acceleration": [0.0, -10.0]},
        "contact": {"local_relation": relation, **contact},
    }))


def test_delassus_relation_needs_few_iterations_at_large_steps():
    """At Δt c/h = 2.5 the lumped relation needed 190 coupling iterations a step on average
    over the impact (513 at most; it did not converge in 2000 before the warm start), the
    Delassus relation 2.4 (at most 3) — as the 1D prototype of ALGORITHM.md §6 predicts
    (~2). Both converge to the same answer: the contact force histories agree. (2026-12-01,
    complete contact solve per iteration: lumped 98 on average, 244 at most; Delassus 1.7,
    at most 2. The lumped run gets a 2000-iteration limit, so that the step-size controller
    does not shorten its steps.)"""
    iterations, forces = {}, {}
    for relation in ("lumped", "delassus"):
        sim = _disk_dropped_on_slab(relation, dt=0.01, end_time=0.2, max_iterations=2000)
        weight = 10.0 * sim.model.mass[sim.model.bodies[0].points].sum()
        its, f = [], []
        for _ in range(sim.n_steps):
            diag = sim.step()
            its.append(diag.contact.iterations)
            f.append(diag.contact_forces(2, 2, sim.dt)[0, 1] / weight)
        iterations[relation], forces[relation] = np.mean(its), np.array(f)
    assert iterations["delassus"] <= 4.0
    assert iterations["lumped"] > 10 * iterations["delassus"]
    assert forces["delassus"].max() > 1.5  # the impact is in the window
    assert np.abs(forces["delassus"] - forces["lumped"]).max() < 2e-3


def test_warm_start_settles_a_resting_contact_in_a_few_iterations():
    """Measured: 3 coupling iterations a step once resting (2 with tangent = "exact": the
    projected tangent makes Newton converge linearly where it clips)."""
    sim = _disk_dropped_on_slab("delassus", dt=0.002, end_time=0.3)
    iterations = [sim.step().contact.iterations for _ in range(sim.n_steps)]
    assert max(iterations[-20:]) <= 3


def test_a_loop_that_does_not_converge_stops_or_warns():
    with pytest.raises(SimulationError, match="did not converge"):
        sim = _disk_dropped_on_slab("lumped", dt=0.01, max_iterations=2)
        for _ in range(sim.n_steps):
            sim.step()
    sim = _disk_dropped_on_slab("lumped", dt=0.01, max_iterations=2, on_failure="warn")
    flags = [sim.step().contact.converged for _ in range(sim.n_steps)]
    assert not all(flags)
    assert np.all(np.isfinite(sim.state.x))


def _three_bodies(contact):
    block = {"shape": "rectangle", "material": "gel"}
    return load_case({
        "simulation": {"dt": 0.01, "steps": 1},
        "grid": {"cell_size": 0.1, "origin": [0.0, 0.0], "size": [3.0, 2.0]},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{**block, "name": "a", "lower": [0.2, 0.6], "upper": [0.8, 1.0]},
                   {**block, "name": "b", "lower": [1.2, 0.6], "upper": [1.8, 1.0]},
                   {**block, "name": "floor", "lower": [0.1, 0.2], "upper": [2.9, 0.5],
                    "kind": "kinematic"}],
        "contact": contact,
    })


def test_friction_per_body_pair():
    from softgrains.model import build

    model, _ = build(_three_bodies({"friction": 0.3, "wall_friction": 0.5,
                                    "pairs": [{"bodies": ["b", "floor"], "friction": 0.1}]}))
    assert model.friction.tolist() == [[0.3, 0.3, 0.5], [0.3, 0.3, 0.1], [0.5, 0.1, 0.5]]
    model, _ = build(_three_bodies({"friction": 0.3}))
    assert np.all(model.friction == 0.3)
    with pytest.raises(CaseError, match="contact.pairs.0"):
        build(_three_bodies({"pairs": [{"bodies": ["b", "flor"], "friction": 0.1}]}))


@pytest.mark.parametrize("relation", ["lumped", "delassus"])
def test_wall_friction_applies_between_grain_and_wall(relation):
    """Blocks sliding on the floor at 1 m/s, no gravity but pressed by nothing: no normal
    impulse, so no friction either way; with gravity the block on the low-friction pair
    decelerates at μ g."""
    case = _three_bodies({"friction": 0.0, "wall_friction": 0.5, "local_relation": relation,
                          "pairs": [{"bodies": ["b", "floor"], "friction": 0.1}]})
    case.simulation.steps = 1
    sim = Simulation(case)
    sim.state.v[:, 0] = np.where(sim.model.body_id < 2, 1.0, 0.0)
    sim.model.gravity[:] = [0.0, -10.0]
    # let the blocks settle onto the floor first (they start 0.1 m above it)
    sim.state.x[sim.model.body_id < 2, 1] -= 0.1 - 1e-3
    v0 = [sim.state.v[sim.model.bodies[i].points, 0].mean() for i in (0, 1)]
    for _ in range(20):
        sim.step()
    v1 = [sim.state.v[sim.model.bodies[i].points, 0].mean() for i in (0, 1)]
    t = 20 * sim.dt
    decel = [(v0[i] - v1[i]) / t for i in (0, 1)]
    assert decel[0] == pytest.approx(0.5 * 10.0, rel=0.1)
    assert decel[1] == pytest.approx(0.1 * 10.0, rel=0.1)


def _block_striking_slab(integrator, theta):
    """A stiff block (Δt c/h ≈ 13) at 1 m/s onto a kinematic slab, no gravity."""
    return Simulation(load_case({
        "simulation": {"dt": 0.002, "steps": 6, "theta": theta, "integrator": integrator},
        "grid": {"cell_size": 0.05, "origin": [0.0, 0.0], "size": [1.0, 1.0]},
        "materials": {"gel": {"young": 1e8, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "block", "shape": "rectangle", "lower": [0.3, 0.41],
                    "upper": [0.7, 0.61], "material": "gel", "velocity": [0.0, -1.0]},
                   {"name": "slab", "shape": "rectangle", "lower": [0.1, 0.2],
                    "upper": [0.9, 0.4], "material": "gel", "kind": "kinematic"}],
    }))


def test_no_rebound_from_integrator_memory():
    """VALIDATION.md B5. The block's mean vertical velocity after the impact: θ = 1 stops it
    (measured +0.026 m/s); θ = 1/2 and Newmark keep energy, so the elastic energy of the
    impact comes back (+0.22 and +0.20 m/s). Newmark kept the impulse in its stored
    acceleration before, replaying the impact next step: +0.80 m/s."""
    rebound = {}
    for integrator, theta in (("theta", 1.0), ("theta", 0.5), ("newmark", 0.5)):
        sim = _block_striking_slab(integrator, theta)
        block = sim.model.bodies[0].points
        for _ in range(sim.n_steps):
            sim.step()
        rebound[integrator, theta] = float(sim.state.v[block, 1].mean())
        e = sim.series_row()["total_energy"]
        assert e <= 0.5 * sim.model.mass[block].sum() * (1 + 1e-9)
    assert abs(rebound["theta", 1.0]) < 0.05
    assert 0.0 < rebound["newmark", 0.5] <= 1.1 * rebound["theta", 0.5] < 0.3


@pytest.mark.parametrize("gap", [True, False], ids=["gap", "mass-overlap"])
def test_resting_disk_boundary_gap(gap):
    """ALGORITHM.md §4 for a curved boundary: a disk (D/h = 20) resting on a slab. Measured
    (2026-11-23): −0.017 h with the gap treatment, +0.364 h on mass overlap alone (D/h = 40:
    −0.029 h and +0.334 h)."""
    h = 0.02
    sim = _disk_dropped_on_slab("delassus", dt=0.01, end_time=0.6, h=h, drop=0.005, gap=gap)
    for _ in range(sim.n_steps):
        sim.step()
    lowest = sim.state.x[sim.model.bodies[0].points, 1].min() - h / 4  # boundary: δ/2 below
    residual = (lowest - 0.5) / h
    if gap:
        assert abs(residual) < 0.05
    else:
        assert residual > 0.25


def _two_disks_stacked(h, seeding, overlap_removal=0.0, overlap_tolerance=0.0,
                       grain_sites="nodes", shape_function="linear"):
    """Two disks (R = 0.2 m, E = 0.1 MPa) stacked under gravity in a channel of kinematic
    walls barely wider than a diameter, on a slab whose top is at y = 0.5; θ = 1, 0.8 s."""
    wall = {"shape": "rectangle", "material": "gel", "kind": "kinematic"}
    disk = {"shape": "disk", "radius": 0.2, "material": "gel", "seeding": seeding}
    return Simulation(load_case({
        "simulation": {"dt": 0.01, "end_time": 0.8, "theta": 1.0},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [1.0, 1.6],
                 "shape_function": shape_function},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{**disk, "name": "lower", "center": [0.5, 0.705]},
                   {**disk, "name": "upper", "center": [0.5, 1.11]},
                   {**wall, "name": "slab", "lower": [0.1, 0.3], "upper": [0.9, 0.5]},
                   {**wall, "name": "left", "lower": [0.1, 0.5], "upper": [0.298, 1.5]},
                   {**wall, "name": "right", "lower": [0.702, 0.5], "upper": [0.9, 1.5]}],
        "gravity": {"acceleration": [0.0, -10.0]},
        "contact": {"overlap_removal": overlap_removal, "overlap_tolerance": overlap_tolerance,
                    "grain_sites": grain_sites},
    }))


def _column_gap(sim, delta):
    """The two disks' boundary gap along the vertical through their centres (points
    ± δ/2, and ± their deformed cells' half-extent ½δ‖Fᵀe_y‖₁), in the points' spacing."""
    x, F = sim.state.x, sim.state.F
    ends = []
    for body, side in ((0, 1.0), (1, -1.0)):
        points = sim.model.bodies[body].points
        column = np.abs(x[points, 0] - 0.5) <= 0.75 * delta
        y = x[points][column, 1]
        extent = 0.5 * delta * np.abs(F[points][column][:, 1, :]).sum(axis=1)
        ends.append((y + side * 0.5 * delta, y + side * extent))
    return ends[1][0].min() - ends[0][0].max(), ends[1][1].min() - ends[0][1].max()


@pytest.mark.parametrize("d_over_h, seeding, shape_function", [
    (10, "lattice", "linear"), (10, "lattice", "bspline2"), (20, "rings", "bspline2")])
def test_stacked_disks_meet_within_the_bar_with_surface_contacts(d_over_h, seeding,
                                                                 shape_function):
    """Issue #11 item 2 (0.05 h), grain on grain: with point-to-surface contacts
    (contact/surfaces.py) the two stacked disks' boundaries meet within 0.05 h after the
    drop and settling (0.8 s), where the nodal contacts let them into each other (D/h 20
    rings, B-splines: −0.16 h; D/h 10: −0.12 h). Measured (2026-12-02, with
    benchmarks/contact_leak.py to 1.5 s, where they stay): −0.022 / −0.022 / −0.019 h
    (deformed cells −0.012 / −0.017 / −0.009 h)."""
    h = 0.4 / d_over_h
    delta = h / 2
    sim = _two_disks_stacked(h, seeding, grain_sites="surface", shape_function=shape_function)
    for _ in range(sim.n_steps):
        sim.step()
    plain, deformed = _column_gap(sim, delta)
    assert -0.05 < plain / h < 0.05
    assert -0.05 < deformed / h < 0.05


@pytest.mark.parametrize("d_over_h, seeding, removal, tolerance, between_range", [
    (10, "lattice", 0.0, 0.0, (-0.15, 0.15)), (20, "rings", 0.0, 0.0, (-0.15, 0.15)),
    (20, "rings", 0.05, 0.0, (-0.03, 0.03)), (20, "rings", 0.05, 0.1, (-0.13, -0.06))])
def test_stacked_disks_boundary_gap(d_over_h, seeding, removal, tolerance, between_range):
    """ALGORITHM.md §4, two grains pressed together: the boundaries (points ± δ/2 along the
    vertical through the centres) of two stacked disks meet within a small fraction of h.
    Measured (2026-11-23, docs/dev-notes.md): disk–disk −0.046 h (D/h 10, lattice), −0.105 h
    (D/h 20, rings), disk–slab 0.000 / −0.032 h; on mass overlap alone +0.36 / +0.05 h and
    +8.8 / +0.20 h. The overlap grows slowly while the disks rest (D/h 20, rings: −0.12 h
    after 0.5 s, −0.155 h after 1.5 s; with μ = 0.5 it stops at −0.07 h); removing 5% of it
    a step holds both gaps within ±0.015 h (−0.013 h and +0.002 h); with a tolerance of
    0.1 h only the excess is removed: the overlap stays near the tolerance (−0.087 h at
    0.5 s, −0.094 h at 1.5 s, where without removal it reaches −0.155 h)."""
    h = 0.4 / d_over_h
    delta = h / 2
    sim = _two_disks_stacked(h, seeding, removal, tolerance)
    for _ in range(sim.n_steps):
        sim.step()
    x = sim.state.x
    lower, upper = (x[sim.model.bodies[i].points] for i in (0, 1))
    lower, upper = (p[np.abs(p[:, 0] - 0.5) <= 0.5 * delta + 1e-12, 1] for p in (lower, upper))
    between = (upper.min() - lower.max() - delta) / h
    on_slab = (lower.min() - 0.5 * delta - 0.5) / h
    low, high = between_range
    assert low < between < high
    assert abs(on_slab) < min(max(abs(low), abs(high)), 0.05)


def _disk_sliding_on_block(keep_closed=False, grain_sites="nodes", shape_function="linear",
                           wall_sites="nodes", end_gap_check=False, retry_halvings=4):
    """A lattice-seeded disk (R = 0.2 m, D/h = 10, E = 0.1 MPa) launched at 0.5 m/s along a
    frictionless deformable block (held by a kinematic slab, μ = 1 between them) under
    gravity, θ = 1, Δt = 10 ms, 1 s: it slides 0.5 m (12 cells) across the lattice."""
    return Simulation(load_case({
        "simulation": {"dt": 0.01, "end_time": 1.0, "theta": 1.0,
                       "retry_halvings": retry_halvings},
        "grid": {"cell_size": 0.04, "origin": [0.0, 0.0], "size": [2.0, 1.0],
                 "shape_function": shape_function},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "disk", "shape": "disk", "center": [0.4, 0.7], "radius": 0.2,
                    "material": "gel", "velocity": [0.5, 0.0]},
                   {"name": "block", "shape": "rectangle", "lower": [0.1, 0.3],
                    "upper": [1.9, 0.5], "material": "gel"},
                   {"name": "slab", "shape": "rectangle", "lower": [0.05, 0.2],
                    "upper": [1.95, 0.3], "material": "gel", "kind": "kinematic"}],
        "gravity": {"acceleration": [0.0, -10.0]},
        "contact": {"keep_closed": keep_closed, "grain_sites": grain_sites,
                    "wall_sites": wall_sites, "end_gap_check": end_gap_check,
                    "pairs": [{"bodies": ["block", "slab"], "friction": 1.0}]},
    }))


def _least_loaded_gap(sim, steps: int) -> float:
    """Run ``steps`` steps; the least start-of-step gap (in h, ≤ 0) at the contacts that
    carried an impulse."""
    least = 0.0
    for _ in range(steps):
        sim.step()
        loaded = np.any(sim.state.contacts.impulse != 0.0, axis=1)
        least = min(least, float(sim.state.contacts.gap[loaded].min(initial=0.0)))
    return least / sim.model.lattice.h


@pytest.mark.parametrize("shape_function", ["linear", "bspline2"])
def test_a_frictionless_disk_slides_on_a_grain_without_sinking_or_gaining_energy(
        shape_function):
    """Point-to-surface contacts (session 11): a disk launched at 0.5 m/s along a
    frictionless deformable block does not sink into it (the gap along the vertical through
    its centre within 0.05 h, checked every 10 steps), the contacts never put energy in
    (their dissipation −Σ P·(u_α − u_β)/Δt summed from the start ≥ 0 at every step, to
    round-off: −5e-18 J at a step whose contacts do no work) and it keeps sliding: speed
    after 1 s ≥ 0.7 of the start.

    The gap is measured as the contacts hold it (session 16: the edge of each point's
    deformed round cell, x_p ± ½δ‖Fᵀe_y‖), not with undeformed half cells, which count the
    compression of the loaded cells (F_yy ≈ 0.94 under the disk) as overlap. Measured
    (2026-12-03): sink 0.029 h (linear) / 0.032 h (B-splines) with deformed cells, 0.065 /
    0.079 h with undeformed ones (session 15's contacts at the point's own velocity: 0.020 /
    0.033 h, and 0.038 / 0.043 h); speed 0.75 / 0.80 of the start (0.72 / 0.79). With the
    nodal contacts 0.59–0.66 of the speed and 0.07–0.28 h; with point rows on lattice
    columns (session 10) it stopped within 1 s. The remaining loss is a small drag of the
    lattice staircases (μ_eff ≈ 0.01–0.015)."""
    sim = _disk_sliding_on_block(grain_sites="surface", shape_function=shape_function)
    disk, block = (np.arange(len(sim.state.x))[sim.model.bodies[i].points] for i in (0, 1))
    h, delta = sim.model.lattice.h, sim.model.lattice.h / 2
    dissipated = 0.0
    for k in range(sim.n_steps):
        dissipated += sim.step().contact.dissipation
        assert dissipated >= -1e-12  # J (round-off; the disk's kinetic energy is 16 J)
        if (k + 1) % 10 == 0:
            x, F = sim.state.x, sim.state.F
            centre = x[disk, 0].mean()
            near = disk[np.abs(x[disk, 0] - centre) <= 1.5 * delta]
            under = block[np.abs(x[block, 0] - centre) <= 1.5 * delta]
            top = (x[under, 1] + 0.5 * delta * np.linalg.norm(F[under, 1, :], axis=1)).max()
            bottom = (x[near, 1] - 0.5 * delta * np.linalg.norm(F[near, 1, :], axis=1)).min()
            assert top - bottom < 0.05 * h
    assert sim.state.v[disk, 0].mean() >= 0.7 * 0.5


def test_a_fast_sliding_disk_is_held_by_its_true_end_of_step_gaps():
    """The same disk launched at 2 m/s (half a cell a step along the block): the linearised
    end-of-step gap misses the curvature of the block's kernel surface and of the disk
    over that travel, and an overlap that is not removed stays (session 15). With
    ``end_gap_check`` (coupling.py, end_gaps.py) the least gap at the contacts carrying an
    impulse stays within 0.05 h over 20 steps (measured −0.025 h, 6 re-solves); without it,
    −0.072 h (session 15's rows at the point's own velocity: −0.084 h).

    The corrections do work (the force acts along the start-of-step normal while the true
    gap is held): series.csv's gap_correction_work, measured 0.23 J against the disk's
    251 J of kinetic energy (session 23); the energy balance still closes term by term."""
    sim = _disk_sliding_on_block(grain_sites="surface", end_gap_check=True)
    disk = sim.model.bodies[0].points
    sim.state.v[disk, 0] = 2.0
    start = sim.series_row()
    least = _least_loaded_gap(sim, 20)
    assert sim.state.v[disk, 0].mean() > 1.5  # it slid
    assert least > -0.05
    end = sim.series_row()
    kinetic = start["kinetic_energy"]
    assert 0.0 < end["gap_correction_work"] < 0.01 * kinetic
    change = end["total_energy"] - start["total_energy"]
    losses = (end["contact_dissipation"] + end["integrator_dissipation"]
              + end["transfer_dissipation"])
    assert abs(end["wall_work"] - losses - change) < 1e-9 * kinetic


def test_a_step_whose_end_gaps_do_not_settle_is_retried_shorter(monkeypatch):
    """When the end-gap fixed point has not settled within its re-solves (a true end gap
    still below its floor), the step is unconverged: the run stops with a diagnosis that
    names end_gap_check and the contact, or the step-size controller retries it shorter
    (session 23: the pre-compaction's impact at 0.2 h a step, 3 re-solves not enough, at
    Δt/2 none needed). Shown on the fast sliding disk with no re-solve allowed
    (GAP_UPDATES = 0), so that every step needing a correction fails at its Δt: measured
    2 steps retried, down to Δt/4, least gap −0.034 h (with the 3 re-solves: none
    retried, −0.025 h)."""
    from softgrains.contact import coupling
    monkeypatch.setattr(coupling, "GAP_UPDATES", 0)
    sim = _disk_sliding_on_block(grain_sites="surface", end_gap_check=True, retry_halvings=0)
    sim.state.v[sim.model.bodies[0].points, 0] = 2.0
    with pytest.raises(SimulationError, match="end-of-step gaps did not settle") as error:
        for _ in range(20):
            sim.step()
    assert "'disk'" in str(error.value) and "'block'" in str(error.value)
    assert error.value.diagnosis["kind"] == "contact"

    sim = _disk_sliding_on_block(grain_sites="surface", end_gap_check=True)
    sim.state.v[sim.model.bodies[0].points, 0] = 2.0
    least = _least_loaded_gap(sim, 20)
    assert sim.retried_steps > 0 and sim.smallest_dt_factor < 1.0
    assert sim.state.v[sim.model.bodies[0].points, 0].mean() > 1.5  # it slid
    assert least > -0.05


def test_the_end_gap_check_leaves_a_step_alone_whose_true_gaps_hold():
    """``end_gap_check`` re-solves a step only where a true end gap passes below its floor
    (session 16). The disk sliding at 0.5 m/s (B-splines) keeps its true gaps: no re-solve
    in 10 steps. Before, the check also re-solved for open contacts whose error was
    negative (the linearisation errs by up to ±0.4 h far from touching, at the edge of a
    kernel reach): a re-solve in 96 of 100 steps, each one more coupling iteration."""
    sim = _disk_sliding_on_block(grain_sites="surface", shape_function="bspline2",
                                 end_gap_check=True)
    updates = [sim.step().contact.gap_updates for _ in range(10)]
    assert updates == [0] * 10


def test_a_loaded_sliding_contact_is_not_ratcheted_by_the_gap_scatter():
    """contact.keep_closed (session 7): a contact loaded at the previous step starts closed
    (its gap the integrator's prediction, 0) unless the fresh estimate finds an overlap.
    Without it, each step where the estimate's scatter says "open" lets the bodies approach
    by that much, and the clipped overlap is never undone: the sliding disk sinks into the
    block. Measured (2026-12-02): −0.094 h with, −0.189 h without, after 1 s (the boundary
    gap along the vertical through the disk's centre, points ± δ/2). D10's 0.05 h is not met
    by this sliding case yet (docs/dev-notes.md, Known problems); the test asserts the
    mechanism: with keep_closed the sink is at most 0.6 of the sink without it."""
    sink = {}
    for keep in (True, False):
        sim = _disk_sliding_on_block(keep)
        for _ in range(sim.n_steps):
            sim.step()
        h, delta = sim.model.lattice.h, sim.model.lattice.h / 2
        disk, block = (sim.state.x[sim.model.bodies[i].points] for i in (0, 1))
        centre = disk[:, 0].mean()
        bottom = disk[np.abs(disk[:, 0] - centre) <= 1.5 * delta, 1].min() - delta / 2
        top = block[np.abs(block[:, 0] - centre) <= 1.5 * delta, 1].max() + delta / 2
        sink[keep] = (top - bottom) / h
        assert centre > 0.7  # it slid
    # (no lower bound: a contact that held the disk out of the block entirely, sink ≤ 0,
    # is what D10 asks for, not a failure)
    assert sink[False] > 0.0 and sink[True] < 0.6 * sink[False]


def test_a_run_with_unconverged_steps_never_ends_as_plain_completed(tmp_path):
    """on_failure = "warn" keeps an unconverged step; the run's status then says how many
    (summary.json, run.log) and the contact problems are left for replay."""
    case = _disk_dropped_on_slab("lumped", dt=0.01, max_iterations=2, on_failure="warn").case
    sim = Simulation(case, out=tmp_path)
    summary = sim.run()
    n = summary["unconverged_contact_steps"]
    assert n > 0 and summary["status"] == f"completed with {n} unconverged steps"
    assert "contact_converged = 0" in summary["message"]
    assert f"did not converge on {n} steps" in (tmp_path / "run.log").read_text()
    assert len(list((tmp_path / "contact_problems").glob("step_*.npz"))) == n


def test_a_resting_disk_does_not_creep_into_the_slab():
    """Issue 11 item 2: over thousands of steps a resting body keeps its gap. A frictionless
    disk (D/h 10, ring seeding) dropped on a slab, 2000 steps of 10 ms: between steps 1000
    and 2000 its least contact gap and its centre's height move by < 2e-5 h. Measured
    (2026-12-07): 1e-10 h and < 1e-8 h. Before the contact Newton polished every solve
    (solvers.solve) the warm start was accepted step after step with an error of the same
    sign: the gap fell 7e-4 h and the centre 4e-4 h per 1000 steps, the disk spinning
    slowly (benchmarks/long_rest_creep.py)."""
    h = 0.04
    sim = Simulation(load_case({
        "simulation": {"dt": 0.01, "end_time": 20.0, "theta": 1.0},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [1.0, 1.0]},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "disk", "shape": "disk", "center": [0.5, 0.705], "radius": 0.2,
                    "material": "gel", "seeding": "rings"},
                   {"name": "slab", "shape": "rectangle", "lower": [0.1, 0.3],
                    "upper": [0.9, 0.5], "material": "gel", "kind": "kinematic"}],
        "gravity": {"acceleration": [0.0, -10.0]},
        "output": {"progress": False},
    }))
    points = sim.model.bodies[0].points
    mass = sim.model.mass[points]
    record = {}
    for k in range(sim.n_steps):
        sim.step()
        if k + 1 in (1000, 2000):
            height = float(mass @ sim.state.x[points, 1] / mass.sum())
            record[k + 1] = (sim.series_row()["least_contact_gap"], height)
    (gap_a, height_a), (gap_b, height_b) = record[1000], record[2000]
    assert gap_a > -0.01 * h  # resting, not overlapping
    assert abs(gap_b - gap_a) < 2e-5 * h
    assert abs(height_b - height_a) < 2e-5 * h

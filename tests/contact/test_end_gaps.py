"""The point contacts' gaps at the end of the step (contact/end_gaps.py): the points moved
as G2P moves them, the gaps against moved walls and moved grain surfaces."""

import numpy as np
import pytest

from softgrains import Simulation, load_case
from softgrains.contact import end_gaps, surfaces
from softgrains.contact.sites import point_blocks
from softgrains.geometry import Rectangle
from softgrains.integrator.implicit import BodyStep

H = 0.1


def _steps(shape_function: str, bodies: list[dict]) -> dict:
    """The steps of deformable bodies at rest, not yet solved."""
    sim = Simulation(load_case({
        "simulation": {"dt": 1e-3, "steps": 1},
        "grid": {"cell_size": H, "origin": [0.0, 0.0], "size": [2.0, 2.0],
                 "shape_function": shape_function},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": f"body{i}", "material": "gel", **b} for i, b in enumerate(bodies)],
        "output": {"progress": False},
    }))
    solver = sim.solver
    return {i: BodyStep(solver.steppers[i], solver.body_points(sim.state, i), np.zeros(2),
                        1e-3, 0) for i in range(len(bodies))}


def _set_displacement(step: BodyStep, field) -> None:
    """u_I = field(X_I) at the step's active nodes."""
    nodes = step.stepper.lattice.node_positions(step.box)[step.active]
    step.u = field(nodes)


DISK = {"shape": "disk", "center": [1.013, 1.3], "radius": 0.4}
BLOCK = {"shape": "rectangle", "lower": [0.4, 0.5], "upper": [1.6, 0.9]}


@pytest.mark.parametrize("shape_function", ["linear", "bspline2"])
def test_moved_points_follow_a_linear_displacement_exactly(shape_function):
    """u_I = G X_I + t: x⁺ = x + G x + t, F⁺ = (I + G) F, V⁺ = det(I + G) V at the points
    whose whole stencil is active (linear completeness of the shape functions)."""
    step = _steps(shape_function, [DISK])[0]
    rng = np.random.default_rng(3)
    G, t = 0.05 * rng.normal(size=(2, 2)), rng.normal(size=2) * H
    step.pts.F[:] = np.eye(2) + 0.1 * rng.normal(size=(len(step.pts.F), 2, 2))
    _set_displacement(step, lambda X: X @ G.T + t)
    moved = end_gaps.moved_points(step)
    inner = np.all(step.active_row[step.nodes] >= 0, axis=1)
    assert inner.sum() > 100
    x, F, V = step.pts.x[inner], step.pts.F[inner], step.pts.vol[inner]
    assert np.allclose(moved.x[inner], x + x @ G.T + t, atol=1e-12)
    assert np.allclose(moved.F[inner], (np.eye(2) + G) @ F, atol=1e-12)
    assert np.allclose(moved.vol[inner], np.linalg.det(np.eye(2) + G) * V, rtol=1e-12)


def test_end_gaps_against_a_moving_wall_and_a_translated_grain():
    """A disk above a block, the block above a kinematic slab. (1) Both grains translated
    by t and the slab by Δt v: every gap between the grains is unchanged (the geometry is
    translated), every gap of the block against the slab changes by n·t − n·Δt v (flat
    face). (2) The disk alone moved down by s: the disk's points against the block's flat
    top change by −s (to the calibrated distance's accuracy)."""
    steps = _steps("linear", [DISK, BLOCK])
    spacing, reach, dt = H / 2, H, 1e-3
    slab = Rectangle(lower=np.array([0.0, 0.3]), upper=np.array([2.0, 0.5]))
    v_slab = np.array([0.0, 20.0])  # Δt v = 0.02 = 0.2 h up
    walls = {2: (v_slab, slab)}
    found = surfaces.merge([
        surfaces.surface_contacts([(0, 1)], steps, spacing, reach),
        surfaces.wall_contacts([(1, 2)], steps, {2: slab}, spacing, reach)])
    at_wall = found.beta == 2
    assert at_wall.sum() > 10 and (~at_wall).sum() > 10
    t = np.array([0.013, -0.031])
    for s in steps.values():
        _set_displacement(s, lambda X: np.broadcast_to(t, X.shape).copy())
    after = end_gaps.end_gaps(found, steps, walls, spacing, dt)
    assert np.allclose(after[~at_wall], found.gap[~at_wall], atol=1e-9)
    expected = found.gap[at_wall] + found.normal[at_wall] @ (t - dt * v_slab)
    assert np.allclose(after[at_wall], expected, atol=1e-12)
    # the disk alone moved down by s: its points against the block's flat top
    sink = 0.02
    _set_displacement(steps[0], lambda X: np.broadcast_to([0.0, -sink], X.shape).copy())
    _set_displacement(steps[1], lambda X: np.zeros_like(X))
    after = end_gaps.end_gaps(found, steps, walls, spacing, dt)
    disk_on_top = (~at_wall) & (found.owner_is_alpha) & (np.abs(found.position[:, 0] - 1.013)
                                                          < 0.1)
    assert disk_on_top.sum() >= 2
    # the calibrated distance of a lattice body's kernel surface is exact to ~1e-3 h here
    # (surfaces.calibrated_distance; measured 1.3e-3 h)
    assert np.allclose(after[disk_on_top], found.gap[disk_on_top] - sink, atol=5e-3 * H)


def _linear_change(sc, steps: dict) -> np.ndarray:
    """Each contact's gap change predicted through its rows (sites.py's point blocks),
    n·(v_α − v_β) with the displacements u the steps carry in place of the velocities."""
    out = np.zeros(len(sc))
    for sign, rows, weights, body, surface_side in (
            (1.0, sc.rows_alpha, sc.weights_alpha, sc.alpha, ~sc.owner_is_alpha),
            (-1.0, sc.rows_beta, sc.weights_beta, sc.beta, sc.owner_is_alpha)):
        rate_rows = np.where(surface_side[:, None], sc.rate_rows, -1)
        r, B = point_blocks(rows, weights, rate_rows, sc.rate_vec, sc.rate_normal)
        for c in range(len(sc)):
            u = steps[int(body[c])].u
            v = sum(B[c, k] @ u[r[c, k]] for k in range(r.shape[1]) if r[c, k] >= 0)
            out[c] += sign * sc.normal[c] @ v
    return out


@pytest.mark.parametrize("shape_function", ["linear", "bspline2"])
@pytest.mark.parametrize("deformation", ["stretch", "shear"])
def test_grain_contact_rows_see_their_cell_edge_move(shape_function, deformation):
    """The block under the disk deformed by 10%, its top row of points under the disk's
    lowest point staying:

    - stretched vertically, the top cells grow by ½δ·0.1 = 0.025 h towards the disk; the
      true end gap of the block's points against the disk falls by that much, and the
      contact's rows predict it (the own side moves with its cell edge,
      Σ_I u_I [N_I + ∇N_I·r_p]; session 16) within 0.003 h (measured 0.0015 h). At the
      point's own velocity (sessions 11–15) the rows predicted no change, 0.024 h off: a
      first-order error, which a loaded point sliding on a soft block met at every step
      (0.014 h a step) and which the end-gap check could only correct by doing work;
    - sheared (u_y = γ x, F_yx = γ), the round cell's extent ½δ‖Fᵀn‖ changes at second
      order (¼δγ² = 0.0006 h under the disk's lowest point), as the rows predict; the
      lattice square's ½δ Σ_j |(Fᵀn)_j| has its kink at this vertical normal and grows by
      ½δ|γ| = 0.025 h where the edge's linear rate says 0: why the cells are round
      between grains too."""
    steps = _steps(shape_function, [DISK, BLOCK])
    spacing, reach, dt, strain = H / 2, H, 1e-3, 0.1
    found = surfaces.surface_contacts([(0, 1)], steps, spacing, reach)
    top = steps[1].pts.x[:, 1].max()
    _set_displacement(steps[0], lambda X: np.zeros_like(X))
    if deformation == "stretch":
        _set_displacement(steps[1], lambda X: np.stack([0.0 * X[:, 0],
                                                        strain * (X[:, 1] - top)], axis=1))
    else:
        _set_displacement(steps[1], lambda X: np.stack([0.0 * X[:, 0],
                                                        strain * (X[:, 0] - 1.013)], axis=1))
    true = end_gaps.end_gaps(found, steps, {}, spacing, dt)
    under = ((~found.owner_is_alpha) & (np.abs(found.gap) < 0.1 * H)
             & (np.abs(found.position[:, 0] - 1.013) < 1.5 * H)
             & np.all(steps[1].active_row[steps[1].nodes[found.point]] >= 0, axis=1))
    assert under.sum() >= 3
    if deformation == "stretch":  # the cells grew towards the disk
        assert np.all((true - found.gap)[under] < -0.8 * strain * spacing / 2)
    error = np.abs(true - found.gap - _linear_change(found, steps))[under]
    assert error.max() < 0.003 * H


@pytest.mark.parametrize("slope", [-1.0, -2.0, -0.5])
def test_the_end_gap_fixed_point_settles_where_the_true_gap_outruns_its_linearisation(
        slope):
    """The loop's end-gap fixed point (coupling._end_gap_offsets) on a model contact: its
    linearised end gap is held at its bound, g_lin = −o (start gap 0, offset o), and its
    true end gap moves with the offset at a slope σ, g⁺(o) = c + σ o, aim A. The plain
    update o ← o + (g⁺ − A) settles in one update where g⁺ moves as g_lin does (σ = −1)
    and swings for ever where it moves twice as fast (σ = −2: 0 ↔ A − c), as between two
    grains at seed 6's step 301 of the frictional example (session 47). With the secant on
    the last two updates each σ settles within three updates."""
    from softgrains.contact.coupling import _end_gap_offsets

    h = 1e-3
    aim, c = -0.025 * h, -0.05 * h
    slack = np.array([0.0 - aim])  # between the linear bound (0) and the aim
    corrected = np.array([True])
    offset, before = np.zeros(1), None
    for _ in range(3):
        true = c + slope * offset
        step = _end_gap_offsets(true, -offset, slack, corrected, (offset, before))
        before, offset = (offset, true), step
    assert c + slope * offset[0] == pytest.approx(aim, abs=1e-6 * h)

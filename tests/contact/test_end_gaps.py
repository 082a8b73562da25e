"""The point contacts' gaps at the end of the step (contact/end_gaps.py): the points moved
as G2P moves them, the gaps against moved walls and moved grain surfaces."""

import numpy as np
import pytest

from softgrains import Simulation, load_case
from softgrains.contact import end_gaps, surfaces
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

"""The pydantic models of the case file: defaults, strictness, geometry helpers."""

from __future__ import annotations

import math

import pytest
from case_dicts import minimal_case
from pydantic import ValidationError

from softgrains.case import Case, estimate_points
from softgrains.case.schema import Body, GridSettings


def test_minimal_case_gets_the_documented_defaults() -> None:
    case = Case.model_validate(minimal_case())
    sim = case.simulation
    assert (sim.dimension, sim.steps, sim.integrator, sim.theta) == (2, None, "theta", 1.0)
    assert (sim.newmark_beta, sim.newmark_gamma, sim.flip) == (0.25, 0.5, 1.0)
    assert (sim.seed, sim.threads, sim.linear_solver) == (0, 0, "auto")
    assert (sim.newton_tolerance, sim.newton_max_iterations) == (1e-8, 25)
    assert case.grid.origin == [0.0, 0.0]
    assert (case.grid.shape_function, case.grid.points_per_cell) == ("bspline2", 2)
    assert case.materials["rubber"].law == "neo-hookean"
    body = case.bodies[0]
    assert (body.name, body.kind, body.velocity) == ("body0", "deformable", [0.0, 0.0])
    assert body.velocity_gradient is None and body.velocity_sine is None
    assert body.lower is None and body.upper is None and body.vertices is None
    assert case.boundary == []
    assert case.gravity.acceleration == [0.0, 0.0]
    assert (case.output.interval, case.output.snapshot_interval, case.output.progress) == (
        10,
        100,
        True,
    )


def test_integers_are_accepted_as_floats_but_strings_are_not() -> None:
    data = minimal_case()
    data["materials"]["rubber"]["young"] = 1_000_000
    young = Case.model_validate(data).materials["rubber"].young
    assert young == 1e6 and isinstance(young, float)
    data["materials"]["rubber"]["young"] = "1e6"
    with pytest.raises(ValidationError):
        Case.model_validate(data)


def test_floats_are_not_accepted_as_integers() -> None:
    data = minimal_case()
    data["grid"]["points_per_cell"] = 2.0
    with pytest.raises(ValidationError):
        Case.model_validate(data)


def test_body_names_default_to_their_index() -> None:
    data = minimal_case()
    data["bodies"].append(dict(data["bodies"][0], name="second", radius=0.1))
    data["bodies"].append(dict(data["bodies"][0], radius=0.1))
    assert [b.name for b in Case.model_validate(data).bodies] == ["body0", "second", "body2"]


@pytest.mark.parametrize(
    ("duration", "n_steps"),
    [({"end_time": 0.1}, 100), ({"end_time": 0.0105}, 11), ({"steps": 7, "end_time": None}, 7)],
)
def test_number_of_steps(duration: dict, n_steps: int) -> None:
    data = minimal_case()
    data["simulation"].update(duration)
    data["simulation"] = {k: v for k, v in data["simulation"].items() if v is not None}
    assert Case.model_validate(data).simulation.n_steps == n_steps


def test_grid_nodes_and_upper_corner() -> None:
    grid = GridSettings(cell_size=0.05, origin=[-0.5, 0.0], size=[1.0, 2.0])
    assert grid.node_counts() == [21, 41]
    assert grid.upper == [0.5, 2.0]


@pytest.mark.parametrize(
    ("geometry", "area", "centroid", "bounds"),
    [
        (
            {"shape": "disk", "center": [0.5, 0.4], "radius": 0.1},
            math.pi * 0.01,
            [0.5, 0.4],
            ([0.4, 0.3], [0.6, 0.5]),
        ),
        (
            {"shape": "rectangle", "lower": [0.0, 0.1], "upper": [1.0, 0.3]},
            0.2,
            [0.5, 0.2],
            ([0.0, 0.1], [1.0, 0.3]),
        ),
        (  # clockwise: the area is still positive
            {"shape": "polygon", "vertices": [[0.0, 0.0], [0.0, 0.3], [0.3, 0.0]]},
            0.045,
            [0.1, 0.1],
            ([0.0, 0.0], [0.3, 0.3]),
        ),
    ],
)
def test_body_geometry(geometry: dict, area: float, centroid: list, bounds: tuple) -> None:
    body = Body(material="m", **geometry)
    assert body.area() == pytest.approx(area)
    assert body.centroid() == pytest.approx(centroid)
    lower, upper = body.bounds()
    assert (lower, upper) == (pytest.approx(bounds[0]), pytest.approx(bounds[1]))


def test_estimate_points_is_area_over_point_spacing_squared() -> None:
    body = Body(material="m", shape="rectangle", lower=[0.0, 0.0], upper=[1.0, 0.5])
    grid = GridSettings(cell_size=0.1, size=[1.0, 1.0], points_per_cell=3)
    assert estimate_points(body, grid) == pytest.approx(0.5 / (0.1 / 3) ** 2)


def test_shape_keys_must_match_the_shape() -> None:
    with pytest.raises(ValidationError, match="only for shape = 'disk'"):
        Body(material="m", shape="rectangle", lower=[0, 0], upper=[1, 1], radius=0.1)

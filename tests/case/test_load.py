"""Loading cases: error messages, overrides, round trips, and robustness against junk input."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path

import numpy as np
import pytest
from case_dicts import minimal_case
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from softgrains.case import Case, case_to_toml, load_case, summarize
from softgrains.case.schema import SHAPE_KEYS, Body, Boundary, GridSettings, SimulationSettings
from softgrains.errors import CaseError

EXAMPLE = Path(__file__).parents[2] / "examples" / "free_disk.toml"


def rich_case() -> dict:
    """A case that sets every optional section and every shape."""
    data = minimal_case()
    data["simulation"] = {"dt": 1e-3, "steps": 20, "integrator": "newmark", "seed": 3}
    data["bodies"][0]["velocity_sine"] = {"amplitude": [0.1, 0.0], "wavenumber": [6.28, 0.0]}
    data["bodies"] += [
        {
            "name": "floor",
            "shape": "rectangle",
            "lower": [0.0, 0.0],
            "upper": [1.0, 0.1],
            "material": "rubber",
            "kind": "kinematic",
            "velocity": [0.0, 0.5],
        },
        {
            "shape": "polygon",
            "vertices": [[0.1, 0.8], [0.3, 0.8], [0.2, 0.95]],
            "material": "rubber",
            "velocity_gradient": [[0.0, 1.0], [0.0, 0.0]],
        },
    ]
    data["boundary"] = [{"lower": [-1, -1], "upper": [0, 2], "components": ["x"]}]
    data["gravity"] = {"acceleration": [0.0, -9.81]}
    data["output"] = {"interval": 2, "progress": False}
    return data


def message_of(data: dict, overrides: object = None) -> str:
    with pytest.raises(CaseError) as caught:
        load_case(data, overrides)
    return str(caught.value)


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        ({"grid.cel_size": 0.05}, "[grid.cel_size]: unknown key; did you mean 'cell_size'?"),
        ({"simulation.dt": "0.001"}, '[simulation.dt] = "0.001": must be a number, not a string'),
        ({"materials.rubber.young": -1.0}, "[materials.rubber.young] = -1.0: must be > 0"),
        (
            {"materials.rubber.poisson": 0.5},
            "[materials.rubber.poisson] = 0.5: must be in (-1, 0.5)",
        ),
        ({"simulation.dt": 0}, "[simulation.dt] = 0: must be > 0"),
        ({"simulation.dt": -1e-3}, "[simulation.dt] = -0.001: must be > 0"),
        ({"bodies.0.center": [0.9, 0.5]}, "[bodies.0.center] = [0.9, 0.5]: the disk reaches"),
        ({"bodies.0.material": "rubbr"}, '[bodies.0.material] = "rubbr": no such material; did'),
        ({"simulation.steps": 100}, "[simulation.steps] = 100: give either end_time or steps"),
        ({"grid.cell_size": 1e-6}, "[grid.cell_size] = 1e-06: too many grid nodes"),
        ({"grid.cell_size": 1e-6}, "[grid.cell_size] = 1e-06: too many points"),
        (
            {"grid.cell_size": 1e-3, "grid.points_per_cell": 6, "bodies.0.radius": 0.45},
            "[grid.cell_size] = 0.001: too many points: about 2.29e+07",
        ),
        ({"simulation.end_time": None}, "[simulation.end_time]: required: give end_time"),
        ({"simulation.end_time": 1e-4}, "[simulation.end_time] = 0.0001: must be >= dt"),
        ({"simulation.end_time": 1e7}, "[simulation.end_time] = 10000000.0: gives 1e+10 steps"),
        ({"simulation.dimension": 3}, "[simulation.dimension] = 3: must be 2"),
        ({"simulation.integrator": "euler"}, "must be 'theta' or 'newmark'"),
        ({"simulation.newton_max_iterations": 0}, "must be in [1, 200]"),
        ({"grid.size": [1.0, -1.0]}, "[grid.size.1] = -1.0: must be > 0"),
        ({"grid.origin": [0.0]}, "[grid.origin] = [0.0]: must have 2 entries (one per axis)"),
        ({"output.progress": 1}, "[output.progress] = 1: must be true or false, not an integer"),
        ({"samples": {"count": 30}}, "[samples]: unknown key; did you mean 'sample'?"),
        ({"sample": {"count": 30}}, "[sample.mean_diameter]: required"),
        ({"protocol": {"kind": "uniaxial-compaction", "sigma0": 1.0}},
         '[protocol.kind] = "uniaxial-compaction": needs a [sample]'),
        ({"bodies.0.radius": None}, "[bodies.0.radius]: required for shape = 'disk'"),
        ({"bodies.0.lower": [0, 0]}, "[bodies.0.lower] = [0.0, 0.0]: only for shape = 'rectangle'"),
        (
            {"bodies.0.kind": "kinematic", "bodies.0.velocity_gradient": [[0, 0], [0, 0]]},
            "[bodies.0.velocity_gradient] = [[0.0, 0.0], [0.0, 0.0]]: only for kind = 'deformable'",
        ),
        ({"bodies.0.material": None}, "[bodies.0.material]: required key is missing"),
        ({"contact": {"grain_sites": "nodes", "grain_passes": "one"}},
         '[contact.grain_passes] = "one": one pass is a choice of the point-to-surface'),
        ({"bodies": []}, "[bodies]: required: give [[bodies]] or a [sample]"),
        ({"bodies": [1]}, "[bodies.0] = 1: must be a table, not an integer"),
        ({"gravity": {"acceleration": [0, float("inf")]}}, "must be a finite number"),
        (
            {"boundary": [{"lower": [0, 0], "upper": [1, 1], "components": ["z"]}]},
            "[boundary.0.components] = [\"z\"]: must be distinct entries of ['x', 'y']",
        ),
        (
            {
                "boundary": [
                    {"lower": [0, 0], "upper": [1, 1], "components": ["x"], "bodies": ["a"]}
                ]
            },
            '[boundary.0.bodies.0] = "a": no such body',
        ),
    ],
)
def test_invalid_case_names_key_value_and_rule(overrides: dict, expected: str) -> None:
    data = minimal_case()
    for key, value in overrides.items():  # None removes a key
        *parents, last = key.split(".")
        node = data
        for segment in parents:
            node = node[int(segment)] if isinstance(node, list) else node.setdefault(segment, {})
        node.pop(last) if value is None else node.__setitem__(last, value)
    message = message_of(data)
    assert expected in message
    assert "pydantic" not in message and "errors.pydantic.dev" not in message


def test_every_problem_gets_its_own_line() -> None:
    data = minimal_case()
    data["simulation"]["dt"] = -1.0
    data["grid"]["cel_size"] = data["grid"].pop("cell_size")
    lines = message_of(data).splitlines()
    assert lines[0] == "invalid case (3 problems):"
    assert sorted(line.strip() for line in lines[1:]) == [
        "[grid.cel_size]: unknown key; did you mean 'cell_size'?",
        "[grid.cell_size]: required key is missing",
        "[simulation.dt] = -1.0: must be > 0",
    ]


@pytest.mark.parametrize(
    ("shape", "geometry", "key"),
    [
        ("rectangle", {"lower": [0.5, 0.5], "upper": [0.6, 0.5]}, "[bodies.0.upper]"),
        ("rectangle", {"lower": [-0.1, 0.5], "upper": [0.6, 0.7]}, "[bodies.0.lower]"),
        ("polygon", {"vertices": [[0, 0], [0.5, 0.5], [1, 1]]}, "[bodies.0.vertices]"),
        ("polygon", {"vertices": [[0, 0], [0.5, 1.5], [1, 0]]}, "[bodies.0.vertices]"),
    ],
)
def test_bad_shapes(shape: str, geometry: dict, key: str) -> None:
    data = minimal_case()
    data["bodies"][0] = {"shape": shape, "material": "rubber", **geometry}
    assert key in message_of(data)


def test_missing_file_and_toml_syntax_errors(tmp_path: Path) -> None:
    with pytest.raises(CaseError, match="case file not found"):
        load_case(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[simulation]\ndt = 1e-3\nend_time = \n")
    with pytest.raises(CaseError, match=r"not valid TOML.*line 3"):
        load_case(bad)
    with pytest.raises(CaseError, match="cannot read"):
        load_case(tmp_path)


def test_example_loads() -> None:
    case = load_case(EXAMPLE)
    assert case.bodies[0].velocity == [0.1, 0.0]
    assert case.materials["rubber"].young == 1e6
    assert case.simulation.n_steps == 100


def test_overrides_as_strings_are_parsed_as_toml() -> None:
    case = load_case(
        EXAMPLE,
        [
            "simulation.dt=1e-4",
            "bodies.0.velocity=[1,0]",
            "simulation.integrator=newmark",  # not TOML: taken as a bare string
            'bodies.0.name="ball"',
            "gravity.acceleration = [0, -9.81]",  # creates the [gravity] table
            "output.progress=false",
        ],
    )
    assert case.simulation.dt == 1e-4
    assert case.bodies[0].velocity == [1.0, 0.0]
    assert case.simulation.integrator == "newmark"
    assert case.bodies[0].name == "ball"
    assert case.gravity.acceleration == [0.0, -9.81]
    assert case.output.progress is False


def test_overrides_as_a_dict_take_python_values_without_mutating_the_input() -> None:
    data = minimal_case()
    before = copy.deepcopy(data)
    case = load_case(data, {"bodies.0.velocity": (1, np.float64(2.0)), "simulation.seed": 4})
    assert case.bodies[0].velocity == [1.0, 2.0]
    assert case.simulation.seed == 4
    assert data == before


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("simulation.dtt=1", "[simulation.dtt]: unknown key; did you mean 'dt'?"),
        ("samples.count=30", "[samples]: unknown key"),
        ("bodies.1.radius=0.1", "'1' is not an index of [bodies], an array of length 1"),
        ("bodies.x.radius=0.1", "'x' is not an index of [bodies]"),
        ("simulation.dt.x=1", "[simulation.dt] = 0.001 is not a table or an array"),
        ("simulation.dt", "expected KEY=VALUE"),
        ("simulation..dt=1", "expected a dotted key"),
        ("simulation.dt=", '[simulation.dt] = "": must be a number, not a string'),
    ],
)
def test_bad_overrides(override: str, expected: str) -> None:
    with pytest.raises(CaseError) as caught:
        load_case(EXAMPLE, [override])
    assert expected in str(caught.value)


@pytest.mark.parametrize("make", [minimal_case, rich_case])
def test_case_to_toml_round_trips(make: object) -> None:
    case = load_case(make())
    text = case_to_toml(case)
    again = load_case(tomllib.loads(text))
    assert again == case
    assert case_to_toml(again) == text


def test_summary_lists_bodies_points_grid_and_time() -> None:
    text = summarize(load_case(rich_case()))
    assert "floor" in text and "kinematic" in text and "polygon" in text
    assert "~201 points" in text  # pi 0.2^2 / (0.05 / 2)^2
    assert "21 x 21 = 441 nodes" in text
    assert "dt = 0.001 s, 20 steps" in text and "newmark" in text


# --- robustness: anything gives a Case or a CaseError -------------------------------------------

KNOWN_KEYS = sorted(
    {"simulation", "grid", "materials", "bodies", "boundary", "gravity", "output", "rubber"}
    | set(SimulationSettings.model_fields)
    | set(GridSettings.model_fields)
    | set(Body.model_fields)
    | set(Boundary.model_fields)
    | {key for keys in SHAPE_KEYS.values() for key in keys}
    | {"young", "poisson", "density", "law", "acceleration", "amplitude", "wavenumber"}
)
scalars = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats()
    | st.text(max_size=6)
    | st.sampled_from(["disk", "rectangle", "polygon", "rubber", "kinematic", "x"])
)
keys = st.sampled_from(KNOWN_KEYS) | st.text(max_size=6)
junk = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(keys, children, max_size=4),
    max_leaves=16,
)
FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def loads_or_case_error(data: object, overrides: object = None) -> None:
    try:
        assert isinstance(load_case(data, overrides), Case)
    except CaseError as error:
        assert str(error)


@FAST
@given(st.dictionaries(keys, junk, max_size=8))
def test_junk_gives_a_case_or_a_case_error(data: dict) -> None:
    loads_or_case_error(data)


def paths(node: object, prefix: tuple = ()) -> list[tuple]:
    """Every path into the nested dicts and lists of ``node``."""
    children = (
        node.items()
        if isinstance(node, dict)
        else enumerate(node)
        if isinstance(node, list)
        else []
    )
    found = [prefix] if prefix else []
    for key, child in children:
        found += paths(child, (*prefix, key))
    return found


@FAST
@given(st.data())
def test_mutated_valid_cases_give_a_case_or_a_case_error(data: st.DataObject) -> None:
    case = rich_case()
    for _ in range(data.draw(st.integers(1, 3))):
        *parents, last = data.draw(st.sampled_from(paths(case)))
        node = case
        for segment in parents:
            node = node[segment]
        action = data.draw(st.sampled_from(["replace", "delete", "add"]))
        if action == "replace":
            node[last] = data.draw(junk)
        elif action == "delete":
            del node[last]
        elif isinstance(node[last], dict):
            node[last][data.draw(keys)] = data.draw(junk)
    loads_or_case_error(case)


@FAST
@given(
    st.lists(st.text(max_size=30) | st.sampled_from(KNOWN_KEYS).map(lambda k: f"{k}=1"), max_size=3)
)
def test_junk_overrides_give_a_case_or_a_case_error(overrides: list[str]) -> None:
    loads_or_case_error(rich_case(), overrides)


def test_consistent_mass_with_one_point_per_cell_is_refused() -> None:
    case = minimal_case()
    case["simulation"]["mass_matrix"] = "consistent"
    case["grid"]["points_per_cell"] = 1
    with pytest.raises(CaseError, match=r"\[simulation.mass_matrix\].*points_per_cell"):
        load_case(case)


@pytest.mark.parametrize("change", [{"theta": 0.5}, {"integrator": "newmark"}])
def test_the_momentum_form_needs_theta_one(change) -> None:
    """stress_form = "momentum" balances moments about the start nodes, which only the
    θ = 1 step does: another θ or Newmark is refused with the fix, not silently run with
    the consistent form."""
    case = minimal_case()
    case["simulation"].update(stress_form="momentum", **change)
    with pytest.raises(CaseError, match=r"\[simulation.stress_form\].*theta = 1.0"):
        load_case(case)
    case["simulation"]["stress_form"] = "consistent"
    load_case(case)

"""Reading a case (TOML file or dict) with overrides, writing it back, and summarising it.

Every failure is a :class:`~softgrains.errors.CaseError` whose message has one line per problem,
``[dotted.key] = value: what is allowed``.
"""

from __future__ import annotations

import json
import math
import os
import tomllib
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo
from pydantic_core import ErrorDetails

from softgrains.case.schema import MISSING, Case, Problem, Problems, estimate_points, suggest
from softgrains.errors import CaseError

Overrides = Mapping[str, object] | Sequence[str]
"""``{"simulation.dt": 1e-4}`` or ``["simulation.dt=1e-4"]`` (values parsed as TOML)."""

_TYPE_ERRORS = {
    "float_type": "must be a number",
    "int_type": "must be an integer",
    "bool_type": "must be true or false",
    "string_type": "must be a string",
    "list_type": "must be an array",
    "dict_type": "must be a table",
    "model_type": "must be a table",
}
_SYMBOLS = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}
_MAX_SHOWN = 60
MAX_CASE_BYTES = 16 * 2**20
"""Largest case file read (bytes)."""


def load_case(
    source: str | os.PathLike[str] | Mapping[str, Any], overrides: Overrides | None = None
) -> Case:
    """Read and validate a case from a TOML file or a dict, after applying ``overrides``.

    An override key is a dotted path (``bodies.0.velocity``, list entries by index); in the
    ``"KEY=VALUE"`` form the value is read as TOML (``1e-4``, ``[1, 0]``, ``"theta"``), or taken
    as a bare string when it is not valid TOML. Raises CaseError on any problem.
    """
    if isinstance(source, Mapping):
        what, data = "case", _plain(source)
    else:
        what, data = f"case file '{source}'", _read_toml(Path(source))
    for key, value in _parse_overrides(overrides):
        _apply_override(data, key, value)
    try:
        return Case.model_validate(data)
    except ValidationError as error:
        problems = [line for details in error.errors() for line in _describe(details)]
        count = f"{len(problems)} problem{'s' if len(problems) > 1 else ''}"
        raise CaseError(f"invalid {what} ({count}):\n  " + "\n  ".join(problems)) from None
    except (ArithmeticError, RecursionError) as error:  # a last guard: absurd magnitudes
        raise CaseError(f"invalid {what}: a value is out of range ({error}); check the "
                        "magnitudes of sizes, counts and material constants") from None


def case_to_toml(case: Case) -> str:
    """The fully resolved case (defaults filled in) as TOML text, readable by load_case."""
    header = "# Fully resolved softgrains case: every default filled in.\n"
    data = case.model_dump()
    data["bodies"] = [table for table, body in zip(data["bodies"], case.bodies, strict=True)
                      if not body.generated]  # [sample] makes them again, the same
    return header + tomli_w.dumps(_without_none(data))


def summarize(case: Case) -> str:
    """A short human summary: bodies and their point estimates, grid, time stepping."""
    sim, grid = case.simulation, case.grid
    points = [estimate_points(body, grid) for body in case.bodies]
    rows = [
        (body.name, body.shape, body.kind, body.material, f"~{n:,.0f} points")
        for body, n in zip(case.bodies, points, strict=True)
    ]
    widths = [max(len(row[column]) for row in rows) for column in range(5)]
    lines = [f"bodies ({len(rows)}):"]
    lines += [
        "  " + "  ".join(f"{cell:<{w}}" for cell, w in zip(row, widths, strict=True))
        for row in rows
    ]
    lines.append(f"material points: ~{sum(points):,.0f} in total")
    counts = grid.node_counts()
    lines.append(
        f"grid: {' x '.join(map(str, counts))} = {math.prod(counts):,} nodes, cell_size = "
        f"{grid.cell_size:g} m, {grid.shape_function} shape functions, "
        f"{grid.points_per_cell} points per cell per axis"
    )
    steps = f"{sim.n_steps:,} steps"
    if sim.end_time is not None:
        steps += f" (end_time = {sim.end_time:g} s)"
    if sim.integrator == "theta":
        scheme = f"theta (theta = {sim.theta:g})"
    else:
        scheme = f"newmark (beta = {sim.newmark_beta:g}, gamma = {sim.newmark_gamma:g})"
    lines.append(f"time: dt = {sim.dt:g} s, {steps}, integrator {scheme}")
    lines.append(
        f"boundary conditions: {len(case.boundary)}, gravity: {case.gravity.acceleration} m/s^2"
    )
    return "\n".join(lines)


def _read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file, turning every failure into a CaseError. At most MAX_CASE_BYTES are
    read (a case is a few kB; /dev/zero or a huge file must not fill the memory)."""
    try:
        with path.open("rb") as stream:
            raw = stream.read(MAX_CASE_BYTES + 1)
        if len(raw) > MAX_CASE_BYTES:
            raise CaseError(f"case file '{path}' is larger than {MAX_CASE_BYTES // 2**20} MiB: "
                            "not a case file")
        return tomllib.loads(raw.decode("utf-8"))
    except FileNotFoundError:
        raise CaseError(f"case file not found: '{path}'") from None
    except OSError as error:
        raise CaseError(f"cannot read case file '{path}': {error.strerror or error}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise CaseError(f"case file '{path}' is not valid TOML: {error}") from None
    except RecursionError:
        raise CaseError(f"case file '{path}' is not valid TOML: arrays or tables nested too "
                        "deeply") from None


def _plain(value: object) -> object:
    """A deep copy with tuples and numpy arrays/scalars turned into lists and Python numbers."""
    if isinstance(value, Mapping):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    return value


def _parse_overrides(overrides: Overrides | None) -> list[tuple[str, object]]:
    """``(dotted key, value)`` pairs from a mapping or from ``KEY=VALUE`` strings."""
    if overrides is None:
        return []
    if isinstance(overrides, Mapping):
        return [(str(key), _plain(value)) for key, value in overrides.items()]
    if isinstance(overrides, str):
        overrides = [overrides]
    pairs = []
    for item in overrides:
        key, equals, text = str(item).partition("=")
        if not equals:
            raise CaseError(f"override '{item}': expected KEY=VALUE, e.g. simulation.dt=1e-4")
        pairs.append((key.strip(), _parse_value(text.strip())))
    return pairs


def _parse_value(text: str) -> object:
    """The TOML value written in ``text``, or ``text`` itself when it is not one TOML value."""
    try:
        parsed = tomllib.loads(f"value = {text}")
    except (tomllib.TOMLDecodeError, RecursionError):
        return text
    return parsed["value"] if len(parsed) == 1 else text


def _apply_override(data: dict[str, Any], key: str, value: object) -> None:
    """Set the entry at dotted ``key`` in ``data`` (creating missing tables) to ``value``."""
    segments = key.split(".")
    if not all(segments):
        raise CaseError(f"override '{key}': expected a dotted key such as simulation.dt")
    node: object = data
    for depth, segment in enumerate(segments):
        parent = ".".join(segments[:depth])
        last = depth == len(segments) - 1
        if isinstance(node, dict):
            if last:
                node[segment] = value
            else:
                node = node.setdefault(segment, {})
        elif isinstance(node, list):
            if not segment.isdigit() or int(segment) >= len(node):
                message = (
                    f"'{segment}' is not an index of [{parent}], an array of length {len(node)}"
                )
                raise CaseError(f"override '{key}': {message}")
            if last:
                node[int(segment)] = value
            else:
                node = node[int(segment)]
        else:
            message = f"[{parent}] = {_show(node)} is not a table or an array"
            raise CaseError(f"override '{key}': {message}")


def _describe(details: ErrorDetails) -> list[str]:
    """Message lines ``[key] = value: what is allowed`` for one pydantic error."""
    loc, kind, value = tuple(details["loc"]), details["type"], details["input"]
    context = details.get("ctx", {})
    error = context.get("error")
    if kind == "value_error" and isinstance(error, Problems):
        return [_line(Problem(loc + p.loc, p.value, p.message)) for p in error.problems]
    if kind == "missing":
        value, message = MISSING, "required key is missing"
    elif kind == "extra_forbidden":
        value, message = MISSING, "unknown key" + suggest(str(loc[-1]), _keys_at(loc[:-1]))
    elif kind in _TYPE_ERRORS:
        message = f"{_TYPE_ERRORS[kind]}, not {_type_name(value)}"
    elif kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        message = _bounds(loc, context)
    elif kind == "literal_error":
        message = f"must be {context['expected']}"
    elif kind == "too_short":
        count = context["min_length"]
        message = f"must have at least {count} entr{'y' if count == 1 else 'ies'}"
    elif kind == "finite_number":
        message = "must be a finite number"
    elif kind == "value_error":
        message = str(error)
    else:
        message = details["msg"]
    return [_line(Problem(loc, value, message))]


def _line(problem: Problem) -> str:
    """``[a.0.b] = value: message``, without the value part when the key is absent."""
    key = ".".join(map(str, problem.loc)) or "case"
    shown = "" if problem.value is MISSING else f" = {_show(problem.value)}"
    return f"[{key}]{shown}: {problem.message}"


def _show(value: object) -> str:
    """``value`` written as in TOML, shortened to at most about 60 characters."""
    if isinstance(value, BaseModel):
        value = value.model_dump()
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, str):
        text = json.dumps(value)
    elif isinstance(value, Mapping):
        text = "{" + ", ".join(f"{key} = {_show(item)}" for key, item in value.items()) + "}"
    elif isinstance(value, list | tuple):
        text = "[" + ", ".join(_show(item) for item in value) + "]"
    else:
        text = repr(value)
    return text if len(text) <= _MAX_SHOWN else text[: _MAX_SHOWN - 3] + "..."


def _type_name(value: object) -> str:
    """The TOML name of the kind of ``value``: "a string", "an array"..."""
    names = [(bool, "a boolean"), (int, "an integer"), (float, "a float"), (str, "a string")]
    names += [(list, "an array"), (Mapping, "a table")]
    return next((name for kind, name in names if isinstance(value, kind)), type(value).__name__)


def _bounds(loc: tuple[str | int, ...], context: dict[str, Any]) -> str:
    """``must be > 0``, or ``must be in (-1, 0.5)`` when the key has two bounds."""
    field = _field_at(loc)
    bounds: dict[str, Any] = {}
    for constraint in field.metadata if field is not None else []:
        bounds |= {
            name: getattr(constraint, name) for name in _SYMBOLS if hasattr(constraint, name)
        }
    bounds = bounds or {name: limit for name, limit in context.items() if name in _SYMBOLS}
    lower = next((name for name in ("gt", "ge") if name in bounds), None)
    upper = next((name for name in ("lt", "le") if name in bounds), None)
    if lower and upper:
        opening, closing = "(" if lower == "gt" else "[", ")" if upper == "lt" else "]"
        return f"must be in {opening}{bounds[lower]:g}, {bounds[upper]:g}{closing}"
    name = lower or upper
    return f"must be {_SYMBOLS[name]} {bounds[name]:g}"


def _field_at(loc: tuple[str | int, ...]) -> FieldInfo | None:
    """The model field validating the key at ``loc``, if ``loc`` names a field of a table."""
    model = _model_at(loc[:-1])
    return model.model_fields.get(loc[-1]) if model and isinstance(loc[-1], str) else None


def _keys_at(loc: tuple[str | int, ...]) -> list[str]:
    """The keys allowed in the table at ``loc``."""
    model = _model_at(loc)
    return list(model.model_fields) if model else []


def _model_at(loc: tuple[str | int, ...]) -> type[BaseModel] | None:
    """The model validating the table at ``loc`` (None when ``loc`` is not a table of Case)."""
    annotation: object = Case
    for segment in loc:
        model = _as_model(annotation)
        if model is not None:
            field = model.model_fields.get(segment) if isinstance(segment, str) else None
            if field is None:
                return None
            annotation = field.annotation
        elif typing.get_origin(annotation) in (list, dict):
            annotation = typing.get_args(annotation)[-1]  # the type of the entries
        else:
            return None
    return _as_model(annotation)


def _as_model(annotation: object) -> type[BaseModel] | None:
    """The model class of a ``Model`` or ``Model | None`` annotation, else None."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        options = [option for option in typing.get_args(annotation) if option is not type(None)]
        annotation = options[0] if len(options) == 1 else annotation
    is_class = typing.get_origin(annotation) is None and isinstance(annotation, type)
    return annotation if is_class and issubclass(annotation, BaseModel) else None


def _without_none(value: object) -> object:
    """``value`` without the None entries of its tables (TOML has no null)."""
    if isinstance(value, dict):
        return {key: _without_none(item) for key, item in value.items() if item is not None}
    if isinstance(value, list):
        return [_without_none(item) for item in value]
    return value

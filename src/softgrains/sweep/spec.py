"""Sweep files (issue #12): a base case and the parameters to vary, expanded into members.

    base = "compaction_frictionless.toml"   # relative to the sweep file
    combine = "product"                      # or "zip": the lists below, element by element
    [parameters]
    "contact.friction" = [0.0, 0.25, 0.5]    # a list of values per dotted case key
    "simulation.seed" = {count = 4}          # replicates: seeds 0..3 (start = 0 by default)
    [set]
    "protocol.stop_stress_ratio" = 100.0     # applied to every member

The lists are combined by ``combine``; seed tables are crossed with the result (every
combination runs with every seed). Every member is a normal case: the base with its
overrides, validated before anything runs (a bad value stops with exit 2 naming the member
and the key).
"""

from __future__ import annotations

import itertools
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from softgrains.case import load_case
from softgrains.errors import CaseError

TOP_KEYS = {"base", "combine", "parameters", "set"}


@dataclass(frozen=True)
class Member:
    """One run of the sweep: its folder name, its overrides of the base case, and the
    values of the swept keys that are not seeds (what groups replicates together)."""

    name: str
    overrides: dict
    group: tuple


@dataclass(frozen=True)
class Sweep:
    """A validated sweep: the base case file and its members."""

    path: Path
    base: Path
    members: list[Member]
    swept: list[str]  # the varied keys, seeds excluded
    seed_key: str | None


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file and every member's case; CaseError names the key."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise CaseError(f"sweep file {path} not found") from None
    except tomllib.TOMLDecodeError as error:
        raise CaseError(f"{path}: not valid TOML ({error})") from None
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise CaseError(f"{path}: unknown key(s) {unknown}; a sweep file has "
                        f"{sorted(TOP_KEYS)}")
    if "base" not in data or not isinstance(data["base"], str):
        raise CaseError(f'{path}: [base] missing: name the base case file, e.g. base = '
                        '"case.toml" (relative to the sweep file)')
    base = (path.parent / data["base"]).resolve()
    if not base.is_file():
        raise CaseError(f"{path}: base = {data['base']!r}: no such file ({base})")
    combine = data.get("combine", "product")
    if combine not in ("product", "zip"):
        raise CaseError(f'{path}: combine = {combine!r}: use "product" or "zip"')
    fixed = data.get("set", {})
    parameters = data.get("parameters", {})
    if not isinstance(parameters, dict) or not parameters:
        raise CaseError(f"{path}: [parameters] missing or empty: give at least one key with "
                        'a list of values, e.g. "contact.friction" = [0.0, 0.5]')
    lists, seed_key, seeds = {}, None, [None]
    for key, values in parameters.items():
        if isinstance(values, dict):
            seed_key, seeds = key, _seeds(path, key, values)
        elif isinstance(values, list) and values:
            lists[key] = values
        else:
            raise CaseError(f"[parameters] {key} = {values!r}: give a non-empty list of "
                            "values or a seed table {count = N}")
    if combine == "zip" and len({len(v) for v in lists.values()}) > 1:
        lengths = {k: len(v) for k, v in lists.items()}
        raise CaseError(f'{path}: combine = "zip" needs lists of one length; got {lengths}')
    keys = list(lists)
    rows = (zip(*lists.values(), strict=True) if combine == "zip"
            else itertools.product(*lists.values()))
    labels = _labels(keys + ([seed_key] if seed_key else []))
    members = []
    for row in rows:
        for seed in seeds:
            values = dict(zip(keys, row, strict=True))
            if seed_key is not None:
                values[seed_key] = seed
            name = "_".join(f"{labels[k]}-{_text(v)}" for k, v in values.items())
            members.append(Member(name, {**fixed, **values}, tuple(_text(v) for v in row)))
    names = [m.name for m in members]
    if len(set(names)) != len(names):
        raise CaseError(f"{path}: two members would have the same folder name; values "
                        "differing only in characters not kept in names? ({names})")
    for member in members:
        try:
            load_case(base, dict(member.overrides))
        except CaseError as error:
            raise CaseError(f"{path}: member {member.name}: {error}") from None
    return Sweep(path, base, members, keys, seed_key)


def _seeds(path: Path, key: str, table: dict) -> list[int]:
    unknown = sorted(set(table) - {"count", "start"})
    count, start = table.get("count"), table.get("start", 0)
    if unknown or not isinstance(count, int) or count < 1 or not isinstance(start, int):
        raise CaseError(f"{path}: [parameters] {key} = {table!r}: a seed table is "
                        "{count = N} or {count = N, start = S} with integers N ≥ 1, S ≥ 0")
    return list(range(start, start + count))


def _labels(keys: list[str]) -> dict[str, str]:
    """Short labels for folder names: the last part of each key, the whole key (dots as
    dashes) where two keys share their last part."""
    last = [k.rsplit(".", 1)[-1] for k in keys]
    return {k: (s if last.count(s) == 1 else k.replace(".", "-"))
            for k, s in zip(keys, last, strict=True)}


def _text(value) -> str:
    """A value as it appears in a folder name (letters, digits, '.', '-', ',' only)."""
    if isinstance(value, list):
        return ",".join(_text(v) for v in value)
    return re.sub(r"[^A-Za-z0-9.\-,]+", "", str(value))

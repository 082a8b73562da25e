"""Hostile case files (issue #5): random bytes, broken TOML, wrong types, NaN/inf, huge or
negative numbers, unknown keys and absurd sizes all end in exit status 2 with a message from
`softgrains check` / `run`, never a traceback, a hang or a huge allocation. TOML is data:
a case file never executes code."""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path

import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from reliability_cases import COMPACTION, FREE_DISK

from softgrains.case import case_to_toml, load_case
from softgrains.cli import main

SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
VALID = {"free_disk": FREE_DISK, "compaction": COMPACTION}


def check(tmp_path: Path, text: str | bytes, capsys, *args: str) -> tuple[int, str]:
    """`softgrains check` of a case file holding ``text``: (status, stderr)."""
    path = tmp_path / "case.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    capsys.readouterr()
    status = main(["check", str(path), *args])
    return status, capsys.readouterr().err


def key_paths(value: object, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a nested dict/list (tables, arrays and their entries)."""
    paths = [prefix] if prefix else []
    if isinstance(value, dict):
        for key, item in value.items():
            paths += key_paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            paths += key_paths(item, (*prefix, index))
    return paths


def replaced(data: dict, path: tuple, value: object) -> dict:
    data = copy.deepcopy(data)
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return data


HOSTILE = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, -1, 0, -1.0, 0.0, 1e300, -1e300, 1e-300,
                     10**30, -(10**30), 2**63, 2**64 + 1, "", "nan", "1e-3", True, False, [],
                     {}, [[1, 2], [3]], {"x": 1}, "__import__('os').system('false')"]),
    st.integers(), st.floats(), st.text(max_size=20),
    st.lists(st.floats(allow_nan=True), max_size=4),
)


@SETTINGS
@given(data=st.binary(max_size=300))
def test_random_bytes(tmp_path, capsys, data):
    status, err = check(tmp_path, data, capsys)
    assert status == 2 and err.startswith("softgrains: error:")


@SETTINGS
@given(text=st.text(max_size=300))
def test_random_text(tmp_path, capsys, text):
    status, err = check(tmp_path, text, capsys)
    assert status == 2 and err.startswith("softgrains: error:")


@SETTINGS
@given(case=st.sampled_from(sorted(VALID)), where=st.integers(0, 10**6), value=HOSTILE)
def test_mutated_values(tmp_path, capsys, case, where, value):
    """Any entry of a valid case replaced by a hostile value: valid (0) or exit 2 with a
    message naming the key; never an exception."""
    data = VALID[case]
    paths = key_paths(data)
    path = paths[where % len(paths)]
    mutated = replaced(data, path, value)
    try:
        text = _toml(mutated)
    except (TypeError, ValueError):  # not expressible in TOML
        return
    status, err = check(tmp_path, text, capsys)
    assert status in (0, 2)
    if status == 2:
        assert err.startswith("softgrains: error:") and "Traceback" not in err
        assert "[" in err  # names the key


@SETTINGS
@given(case=st.sampled_from(sorted(VALID)), where=st.integers(0, 10**6),
       name=st.from_regex(r"[a-z_]{1,12}", fullmatch=True))
def test_unknown_keys(tmp_path, capsys, case, where, name):
    data = copy.deepcopy(VALID[case])
    tables = [p for p in key_paths(data) if isinstance(_at(data, p), dict)] + [()]
    path = tables[where % len(tables)]
    table = _at(data, path)
    if name in table or (path == () and name in ("gravity", "contact", "output", "boundary",
                                                 "bodies", "sample", "protocol")):
        return
    table[name] = 1
    status, err = check(tmp_path, _toml(data), capsys)
    # an unknown key of a table, or under [materials] a "material" that is no table
    assert status == 2 and f"{name}]" in err


@SETTINGS
@given(cell=st.floats(1e-12, 2e-4), per_cell=st.integers(1, 6), radius=st.floats(0.3, 1e6))
def test_absurd_sizes_are_refused_before_allocation(tmp_path, capsys, cell, per_cell, radius):
    """10⁶ to 10³⁶ points or nodes: refused from the estimate, in check and in run."""
    data = copy.deepcopy(FREE_DISK)
    data["grid"] = {"cell_size": cell, "size": [2 * radius + 1, 2 * radius + 1],
                    "points_per_cell": per_cell}
    data["bodies"][0].update(center=[radius + 0.5, radius + 0.5], radius=radius)
    path = _write(tmp_path, data)
    for command in (["check", str(path)], ["run", str(path), "--out", str(tmp_path / "o")]):
        capsys.readouterr()
        assert main(command) == 2
        assert "too many" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@SETTINGS
@given(count=st.integers(1, 10**12), diameter=st.floats(1e-9, 1e3), width=st.floats(1e-9, 1e6))
def test_absurd_samples(tmp_path, capsys, count, diameter, width):
    data = copy.deepcopy(COMPACTION)
    data["sample"].update(count=count, mean_diameter=diameter, box_width=width)
    status, err = check(tmp_path, _toml(data), capsys)
    assert status in (0, 2)
    if status == 2:
        assert "[sample" in err or "[grid" in err or "[protocol" in err


def test_a_billion_points_is_refused_at_once(tmp_path, capsys):
    data = copy.deepcopy(FREE_DISK)
    data["grid"]["cell_size"] = 2e-5  # a disk of radius 0.3 m: ~1e9 points
    status, err = check(tmp_path, _toml(data), capsys)
    assert status == 2 and "too many points" in err and "e+09" in err


def test_a_case_file_never_executes_code(tmp_path, capsys):
    marker = tmp_path / "pwned"
    text = _toml(FREE_DISK) + f'\n[evil]\ncode = "__import__(\'pathlib\').Path(\'{marker}\')' \
        '.touch()"\n'
    status, err = check(tmp_path, text, capsys)
    assert status == 2 and "unknown key" in err and not marker.exists()


def _at(data: object, path: tuple) -> object:
    for key in path:
        data = data[key]
    return data


def _toml(data: dict) -> str:
    return tomli_w.dumps(data)


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "case.toml"
    path.write_text(_toml(data))
    return path


def test_valid_cases_are_valid():
    for data in VALID.values():
        case = load_case(data)
        assert tomllib.loads(case_to_toml(case))



@pytest.mark.parametrize("text", [
    "x = " + "[" * 100_000 + "]" * 100_000,  # tomllib recursed to a RecursionError
    "x = " + "{a = " * 5000 + "1" + "}" * 5000,
    "x = 1\n" * 10 + "y = " + "9" * 5000,  # a 5000-digit integer
])
def test_pathological_toml(tmp_path, capsys, text):
    status, err = check(tmp_path, text, capsys)
    assert status == 2 and err.startswith("softgrains: error:")


def test_a_float_overflow_in_the_estimates_is_a_case_error(tmp_path, capsys):
    """(d/spacing) ** 2 raised OverflowError for d = 1e151 before (found by hypothesis)."""
    data = copy.deepcopy(COMPACTION)
    data["sample"]["mean_diameter"] = 1.3407807929942597e151
    status, err = check(tmp_path, _toml(data), capsys)
    assert status == 2 and "[sample.count]" in err


def test_huge_files_and_devices_are_not_read_whole(tmp_path, capsys):
    status, err = check(tmp_path, b"# " + b"x" * (17 * 2**20), capsys)
    assert status == 2 and "larger than 16 MiB" in err
    if Path("/dev/zero").exists():
        assert main(["check", "/dev/zero"]) == 2

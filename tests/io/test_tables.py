"""CsvTable / read_table: exact floats, flush on append, validation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from softgrains.io import CsvTable, read_table


def test_round_trip_is_exact(tmp_path: Path) -> None:
    path = tmp_path / "series.csv"
    values = [0.1 + 0.2, 1e-300, -2.5e300, np.pi, np.float32(0.1), float("nan"), float("inf")]
    with CsvTable(path, ["step", "value"]) as table:
        for step, value in enumerate(values):
            table.append({"step": step, "value": value})
    table_read = read_table(path)
    assert table_read["step"].tolist() == list(range(len(values)))
    expected = np.array([float(v) for v in values])
    assert np.array_equal(table_read["value"], expected, equal_nan=True)
    lines = path.read_text().splitlines()
    assert lines[0] == "step,value"
    assert lines[1] == "0,0.30000000000000004"
    assert lines[2] == "1,1e-300"


def test_ints_written_as_ints_and_sequences_accepted(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    with CsvTable(path, ["a", "b", "c"]) as table:
        table.append([np.int64(3), True, 2.0])
    assert path.read_text().splitlines()[1] == "3,1,2.0"


def test_rows_are_on_disk_before_close(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    table = CsvTable(path, ["step", "time"])
    assert path.read_text() == "step,time\n"
    table.append({"step": 1, "time": 0.5})
    assert read_table(path)["time"].tolist() == [0.5]
    table.close()


def test_missing_and_unknown_columns_are_named(tmp_path: Path) -> None:
    with CsvTable(tmp_path / "t.csv", ["step", "time", "dt"]) as table:
        with pytest.raises(ValueError, match="time, dt"):
            table.append({"step": 1})
        with pytest.raises(ValueError, match="tmie"):
            table.append({"step": 1, "time": 0.0, "dt": 1.0, "tmie": 2.0})
        with pytest.raises(ValueError, match="2 values"):
            table.append([1, 2])


def test_string_columns_and_empty_table(tmp_path: Path) -> None:
    path = tmp_path / "bodies.csv"
    with CsvTable(path, ["body", "kind", "x"]) as table:
        assert read_table(path)["x"].shape == (0,)
        table.append({"body": 0, "kind": "wall, top", "x": 1.5})
        table.append({"body": 1, "kind": "grain", "x": -0.25})
    read = read_table(path)
    assert read["kind"].tolist() == ["wall, top", "grain"]
    assert read["x"].tolist() == [1.5, -0.25]


def test_unfinished_last_line_is_ignored(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    path.write_text("step,time\n1,0.5\n2,0.7")
    assert read_table(path)["step"].tolist() == [1.0]


def test_bad_header_and_values_rejected(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="duplicate"):
        CsvTable(tmp_path / "t.csv", ["a", "a"])
    with CsvTable(tmp_path / "u.csv", ["a"]) as table, pytest.raises(TypeError):
        table.append([object()])


def test_resuming_a_table_of_an_older_version_adds_the_new_columns(tmp_path: Path) -> None:
    """A series.csv written before a column was added (session 45: least_unsampled_gap,
    between others) is resumed: its rows kept, the new column empty (nan) up to the
    checkpoint's step, later rows dropped."""
    from softgrains.io import truncate_after_step

    path = tmp_path / "series.csv"
    with CsvTable(path, ["step", "wall_work", "phase"]) as table:
        table.append({"step": 1, "wall_work": 0.5, "phase": "compaction"})
        table.append({"step": 2, "wall_work": 0.75, "phase": "compaction"})
    columns = ["step", "wall_work", "least_unsampled_gap", "phase"]
    assert truncate_after_step(path, columns, 1) == 1
    with CsvTable(path, columns, append=True) as table:
        table.append({"step": 2, "wall_work": 0.7, "least_unsampled_gap": -1e-5,
                      "phase": "compaction"})
    series = read_table(path)
    assert list(series) == columns
    assert np.array_equal(series["wall_work"], [0.5, 0.7])
    assert np.isnan(series["least_unsampled_gap"][0])
    assert series["least_unsampled_gap"][1] == -1e-5


def test_resuming_a_table_of_another_case_names_the_columns(tmp_path: Path) -> None:
    """A table whose columns are not an older version's (some not written any more, or in
    another order) cannot be appended to: the error names what differs and what to do."""
    from softgrains.io import truncate_after_step

    path = tmp_path / "series.csv"
    with CsvTable(path, ["step", "wall_work", "other"]) as table:
        table.append({"step": 1, "wall_work": 0.5, "other": 1.0})
    with pytest.raises(ValueError, match=r"missing: gap_correction_work.*not written any "
                       r"more: other.*without --resume"):
        truncate_after_step(path, ["step", "wall_work", "gap_correction_work"], 1)
    with pytest.raises(ValueError, match="without --resume"):
        truncate_after_step(path, ["wall_work", "step", "other"], 1)
    assert truncate_after_step(path, ["step", "wall_work", "other"], 1) == 1  # row kept

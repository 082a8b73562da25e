"""plot_run draws the energy and Newton figures of a run folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from softgrains.errors import CaseError
from softgrains.io import CsvTable
from softgrains.viz import plot_run

COLUMNS = ["step", "time", "dt", "newton_iterations", "kinetic_energy", "strain_energy"]


def test_plot_run_writes_figures(tmp_path: Path) -> None:
    with CsvTable(tmp_path / "series.csv", [*COLUMNS, "phi"]) as table:
        for step in range(20):
            time = step * 1e-3
            table.append(
                [step, time, 1e-3, 2 + step % 3, np.sin(time) ** 2, np.cos(time) ** 2, 0.8]
            )
    paths = plot_run(tmp_path)
    assert paths == [tmp_path / "figures" / "energy.png", tmp_path / "figures" / "newton.png"]
    for path in paths:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert path.stat().st_size > 1000


def test_plot_run_with_header_only(tmp_path: Path) -> None:
    CsvTable(tmp_path / "series.csv", COLUMNS).close()
    assert all(path.is_file() for path in plot_run(tmp_path))


def test_missing_series_is_a_case_error(tmp_path: Path) -> None:
    with pytest.raises(CaseError, match="no series.csv"):
        plot_run(tmp_path)


def test_missing_columns_are_named(tmp_path: Path) -> None:
    CsvTable(tmp_path / "series.csv", ["step", "time"]).close()
    with pytest.raises(CaseError, match="dt, newton_iterations"):
        plot_run(tmp_path)

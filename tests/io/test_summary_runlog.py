"""write_json_atomic, software_versions, the run log and the progress bar."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from softgrains.io import (
    Progress,
    close_run_log,
    open_run_log,
    software_versions,
    write_json_atomic,
)


def test_json_converts_numpy_and_replaces_atomically(tmp_path: Path) -> None:
    path = tmp_path / "summary.json"
    path.write_text("old")
    obj = {
        "steps": np.int64(12),
        "phi": np.float32(0.5),
        "energy": np.float64(0.1 + 0.2),
        "stress": np.array([[1.0, 2.0], [3.0, 4.0]]),
        "out": tmp_path,
    }
    write_json_atomic(path, obj)
    assert json.loads(path.read_text()) == {
        "steps": 12,
        "phi": 0.5,
        "energy": 0.1 + 0.2,
        "stress": [[1.0, 2.0], [3.0, 4.0]],
        "out": str(tmp_path),
    }
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]


def test_failed_json_write_keeps_old_file(tmp_path: Path) -> None:
    path = tmp_path / "summary.json"
    write_json_atomic(path, {"a": 1})
    with pytest.raises(TypeError):
        write_json_atomic(path, {"a": object()})
    assert json.loads(path.read_text()) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]


def test_software_versions() -> None:
    versions = software_versions()
    assert set(versions) == {"softgrains", "python", "numpy", "scipy", "numba"}
    assert versions["numpy"] == np.__version__
    assert all(isinstance(v, str) and v for v in versions.values())


def test_run_log_writes_file_and_console(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    logger = open_run_log(tmp_path, verbose_console=True)
    assert logger.name.startswith("softgrains.run.")
    logger.info("step 10 t=0.1")
    assert "step 10 t=0.1" in (tmp_path / "run.log").read_text()
    logger.warning("contact did not converge")
    close_run_log(logger)
    assert not logger.handlers
    log = (tmp_path / "run.log").read_text()
    assert "INFO" in log and "WARNING" in log and "contact did not converge" in log
    err = capsys.readouterr().err
    assert "step 10 t=0.1\n" in err
    assert "WARNING: contact did not converge" in err


def test_quiet_console_shows_only_warnings(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    logger = open_run_log(tmp_path, verbose_console=False)
    other = open_run_log(tmp_path / "other", verbose_console=False)
    assert other.name != logger.name
    logger.info("hidden on console")
    logger.error("shown")
    close_run_log(logger)
    close_run_log(other)
    err = capsys.readouterr().err
    assert "hidden on console" not in err and "ERROR: shown" in err
    assert "hidden on console" in (tmp_path / "run.log").read_text()
    assert not (tmp_path / "other" / "run.log").read_text()
    assert not logging.getLogger("softgrains").handlers


def test_progress_off_without_terminal(capsys: pytest.CaptureFixture) -> None:
    with Progress(100, enabled=True) as progress:  # pytest's stderr is not a terminal
        assert not progress.active
        progress.update(1, 0.01, phi=0.8)
    with Progress(None, enabled=False) as progress:
        assert not progress.active
    assert capsys.readouterr().err == ""


def test_progress_bar_on_terminal(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    monkeypatch.setattr("sys.stderr.isatty", lambda: True)
    with Progress(10, enabled=True) as progress:
        assert progress.active
        progress.update(5, 0.25, phi=np.float64(0.812345), phase="loading")
    err = capsys.readouterr().err
    assert "5/10" in err and "t=0.25 s" in err and "phi=0.8123" in err and "loading" in err
    assert not progress.active


def test_a_long_run_logs_its_progress_at_least_every_minute(tmp_path, monkeypatch) -> None:
    """Without a terminal (no progress bar) run.log gets a progress line every twentieth of
    the steps and at least every PROGRESS_LOG_SECONDS: a 1000-grain compaction takes
    10–20 s a step, a twentieth of its steps hours. Here (40 steps, the interval made 0
    s) every step has its line; with the interval of an hour, every second step (40/20)."""
    import softgrains.simulation as simulation
    from softgrains import Simulation, load_case

    def logged_steps(seconds: float, out: Path) -> list[int]:
        monkeypatch.setattr(simulation, "PROGRESS_LOG_SECONDS", seconds)
        Simulation(load_case({
            "simulation": {"dt": 1e-3, "steps": 40},
            "grid": {"cell_size": 0.25, "origin": [0.0, 0.0], "size": [2.0, 2.0]},
            "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
            "bodies": [{"name": "disk", "shape": "disk", "center": [1.0, 1.0],
                        "radius": 0.5, "material": "gel"}],
            "output": {"progress": False},
        }), out=out).run()
        lines = (out / "run.log").read_text().splitlines()
        return [int(line.split("step ")[1].split("/")[0]) for line in lines
                if " step " in line and "/40" in line]

    assert logged_steps(0.0, tmp_path / "often") == list(range(1, 41))
    assert logged_steps(3600.0, tmp_path / "hourly") == list(range(2, 41, 2))

"""Checkpoints and resume (issue #5): a run killed (SIGKILL) or stopped (SIGTERM) mid-way and
resumed gives the same series.csv rows, bodies.csv rows and final state as an uninterrupted
run, bit for bit: the same thread count, and everything carried between steps is restored."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np
import pytest
from reliability_cases import COMPACTION, FREE_DISK, case_dict, write_case

from softgrains.cli import main
from softgrains.io import read_checkpoint, read_table


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> tuple[Path, Path]:
    """The case file and the output folder of an uninterrupted run."""
    root = tmp_path_factory.mktemp("reference")
    case = write_case(root / "case.toml", COMPACTION)
    assert main(["run", str(case), "--out", str(root / "out"), "--no-figures"]) == 0
    return case, root / "out"


def start(case: Path, out: Path) -> subprocess.Popen:
    """`softgrains run` in another process, with this process's thread count."""
    env = dict(os.environ, NUMBA_NUM_THREADS=str(numba.get_num_threads()))
    return subprocess.Popen([sys.executable, "-m", "softgrains", "run", str(case), "--out",
                             str(out), "--no-figures"], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


def wait_for_row(process: subprocess.Popen, out: Path, step: int) -> None:
    """Wait until series.csv holds a row at ``step`` or later (a checkpoint is then on disk:
    they are written every 10 steps, rows every 3)."""
    deadline = time.monotonic() + 300.0  # a bound for a hang, not a timing assertion
    while time.monotonic() < deadline:
        assert process.poll() is None, f"the run ended before step {step}: {process.stderr}"
        path = out / "series.csv"
        if path.is_file():
            rows = path.read_text().splitlines()[1:]
            if any(r.count(",") > 2 and int(r.split(",")[0]) >= step for r in rows[:-1]):
                return
        time.sleep(0.01)
    raise AssertionError("no progress within 300 s")


def assert_same_run(out: Path, reference: Path) -> None:
    """series.csv and bodies.csv rows (but the wall time) and the final state identical."""
    a, b = read_table(out / "series.csv"), read_table(reference / "series.csv")
    assert a.keys() == b.keys()
    for column in a:
        if column != "wall_time":  # (least_contact_gap is NaN where no contact is active)
            assert np.array_equal(a[column], b[column],
                                  equal_nan=a[column].dtype.kind == "f"), column
    assert (out / "bodies.csv").read_text() == (reference / "bodies.csv").read_text()
    final, meta = read_checkpoint(out / "checkpoint.h5")
    expected, meta_ref = read_checkpoint(reference / "checkpoint.h5")
    assert meta["step"] == meta_ref["step"] == COMPACTION["simulation"]["steps"]
    assert meta["protocol"] == meta_ref["protocol"]
    assert final.keys() == expected.keys()
    for name in final:
        assert np.array_equal(final[name], expected[name]), name


def test_sigkill_then_resume_repeats_the_uninterrupted_run(reference, tmp_path):
    case, ref_out = reference
    out = tmp_path / "out"
    process = start(case, out)
    wait_for_row(process, out, 22)
    process.kill()
    process.wait(timeout=30)
    assert not (out / "summary.json").exists()  # killed mid-way, not finished
    _, meta = read_checkpoint(out / "checkpoint.h5")
    killed_at = meta["step"]
    assert 0 < killed_at < COMPACTION["simulation"]["steps"]
    assert read_table(out / "series.csv")["step"].max() > killed_at  # rows to drop

    assert main(["run", str(case), "--out", str(out), "--resume", "--no-figures"]) == 0
    assert_same_run(out, ref_out)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["resumed_from_step"] == killed_at
    assert f"resumed from step {killed_at}" in (out / "run.log").read_text()


def test_sigterm_stops_cleanly_with_a_checkpoint_then_resumes(reference, tmp_path):
    case, ref_out = reference
    out = tmp_path / "out"
    process = start(case, out)
    wait_for_row(process, out, 12)
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=300) == 128 + signal.SIGTERM
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and "SIGTERM" in summary["message"]
    _, meta = read_checkpoint(out / "checkpoint.h5")
    assert meta["step"] == summary["steps"] == summary["last_checkpoint_step"]
    assert meta["step"] < COMPACTION["simulation"]["steps"]
    assert "--resume" in process.stderr.read()

    assert main(["run", str(case), "--out", str(out), "--resume", "--no-figures"]) == 0
    assert_same_run(out, ref_out)


def test_resume_with_another_case_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    disk = write_case(tmp_path / "disk.toml", FREE_DISK)
    assert main(["run", str(disk), "--out", str(out), "--no-figures"]) == 0
    bigger = case_dict(FREE_DISK)
    bigger["bodies"][0]["radius"] = 0.4
    other = write_case(tmp_path / "other.toml", bigger)
    assert main(["run", str(other), "--out", str(out), "--resume", "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert "does not match the checkpoint" in err and "bodies" in err


def test_resume_may_change_dt_and_extend_the_run(tmp_path):
    """What a failed run needs: the same bodies and grid with a smaller dt, further on."""
    out = tmp_path / "out"
    disk = write_case(tmp_path / "disk.toml", FREE_DISK)
    assert main(["run", str(disk), "--out", str(out), "--no-figures"]) == 0
    longer = write_case(tmp_path / "longer.toml",
                        case_dict(FREE_DISK, simulation={"dt": 5e-4, "steps": 8}))
    assert main(["run", str(longer), "--out", str(out), "--resume", "--no-figures"]) == 0
    series = read_table(out / "series.csv")
    assert series["step"].tolist() == list(range(9))  # no row twice, none missing
    assert series["dt"][-1] == 5e-4
    log = (out / "run.log").read_text()
    assert "resumed from step 4" in log and "simulation.dt: 0.001 → 0.0005" in log


def test_a_compaction_stopped_at_its_stress_goes_on_when_resumed_with_a_higher_one(tmp_path):
    """A finished compaction resumed with a raised stop_stress_ratio continues to the new
    stop (it reported "completed" at once, without a step, until session 40)."""
    import copy

    first = copy.deepcopy(COMPACTION)
    first["protocol"]["stop_stress_ratio"] = 3.0
    out = tmp_path / "out"
    assert main(["run", str(write_case(tmp_path / "a.toml", first)), "--out", str(out),
                 "--no-figures"]) == 0
    stopped = json.loads((out / "summary.json").read_text())
    assert "σ_yy/σ0" in stopped["protocol"]["stop_reason"] and stopped["steps"] < 60
    assert main(["run", str(write_case(tmp_path / "b.toml", COMPACTION)), "--out", str(out),
                 "--resume", "--no-figures"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] > stopped["steps"]
    series = read_table(out / "series.csv")
    steps = series["step"]
    assert np.all(np.diff(steps) > 0) and steps[-1] == summary["steps"]  # no row twice
    assert series["phase"][-1] == "compaction"
    assert "goes on past its stop" in (out / "run.log").read_text()


def test_checkpoint_is_replaced_atomically(tmp_path, monkeypatch):
    """A failure while writing leaves the previous checkpoint whole and no temporary file."""
    from softgrains.io import checkpoint as module

    path = tmp_path / "checkpoint.h5"
    module.write_checkpoint(path, {"state/x": np.arange(3.0)}, {"step": 1})

    def broken(*args, **kwargs):
        raise OSError("disk full")

    from softgrains.io import summary

    monkeypatch.setattr(summary.os, "replace", broken)
    with pytest.raises(OSError):
        module.write_checkpoint(path, {"state/x": np.arange(4.0)}, {"step": 2})
    arrays, meta = module.read_checkpoint(path)
    assert meta["step"] == 1 and arrays["state/x"].tolist() == [0.0, 1.0, 2.0]
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_sigterm_to_a_run_of_several_cases_stops_every_worker_cleanly(tmp_path):
    """`softgrains run A B` killed with SIGTERM (the parent only, as kill or a batch system
    does) passes the signal on: each case stops after its step with a checkpoint and the
    status "interrupted", and the command exits with 128 + SIGTERM. (Before, the parent
    died at once and its workers ran on to the end.)"""
    cases = [write_case(tmp_path / f"{name}.toml", COMPACTION) for name in ("a", "b")]
    root = tmp_path / "out"
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    process = subprocess.Popen(
        [sys.executable, "-m", "softgrains", "run", *map(str, cases), "--out", str(root),
         "--no-figures", "--jobs", "2"], env=env, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True)
    for name in ("a", "b"):
        wait_for_row(process, root / name, 3)
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=300) == 128 + signal.SIGTERM
    for name in ("a", "b"):
        summary = json.loads((root / name / "summary.json").read_text())
        assert summary["status"] == "interrupted" and "SIGTERM" in summary["message"]
        assert summary["steps"] < COMPACTION["simulation"]["steps"]
        assert (root / name / "checkpoint.h5").is_file()


def test_resume_with_surface_contacts_repeats_the_uninterrupted_run(tmp_path):
    """Point-to-surface grain contacts (``grain_sites = "surface"``) carry their point sites
    and positions in the checkpoint: a run stopped at step 30 and resumed to step 60 repeats
    the uninterrupted run bit for bit (warm start of the same contacts included)."""
    surface = {"grain_sites": "surface"}
    whole = write_case(tmp_path / "whole.toml", case_dict(COMPACTION, contact=surface))
    assert main(["run", str(whole), "--out", str(tmp_path / "whole"), "--no-figures"]) == 0
    half = write_case(tmp_path / "half.toml", case_dict(COMPACTION, contact=surface,
                                                       simulation={"steps": 30}))
    out = tmp_path / "resumed"
    assert main(["run", str(half), "--out", str(out), "--no-figures"]) == 0
    _, meta = read_checkpoint(out / "checkpoint.h5")
    assert meta["step"] == 30
    assert main(["run", str(whole), "--out", str(out), "--resume", "--no-figures"]) == 0
    assert_same_run(out, tmp_path / "whole")
    arrays, _ = read_checkpoint(out / "checkpoint.h5")
    assert "contacts/site" in arrays and (arrays["contacts/site"] >= 0).any()

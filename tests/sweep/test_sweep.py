"""Sweeps on Dask (issue #12, items 1–3): the sweep file, its members, a real LocalCluster run
with a member that fails on purpose, skipping finished members and resuming an interrupted
one."""

import json
import re
import signal
from pathlib import Path

import numpy as np
import pytest

from softgrains import Simulation, load_case
from softgrains.errors import CaseError
from softgrains.io import read_table
from softgrains.sweep import load_sweep, run_sweep

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _write(tmp_path: Path, text: str) -> Path:
    base = (EXAMPLES / "free_disk.toml").read_text().replace("end_time = 0.1 ",
                                                             "end_time = 0.01")
    (tmp_path / "base.toml").write_text(base)
    path = tmp_path / "sweep.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, expected", [
    ('base = "base.toml"\nbogus = 1\n[parameters]\n"simulation.dt" = [1e-3]\n',
     "unknown key(s) ['bogus']"),
    ('[parameters]\n"simulation.dt" = [1e-3]\n', "[base] missing"),
    ('base = "nothere.toml"\n[parameters]\n"simulation.dt" = [1e-3]\n', "no such file"),
    ('base = "base.toml"\n', "[parameters] missing or empty"),
    ('base = "base.toml"\ncombine = "zip"\n[parameters]\n"simulation.dt" = [1e-3, 2e-3]\n'
     '"simulation.theta" = [1.0]\n', 'combine = "zip" needs lists of one length'),
    ('base = "base.toml"\n[parameters]\n"simulation.seed" = {count = 0}\n',
     "a seed table is {count = N}"),
    ('base = "base.toml"\n[parameters]\n"simulation.dt" = []\n', "non-empty list"),
    ('base = "base.toml"\n[parameters]\n"simulation.dt" = [1e-3, -1.0]\n',
     "member dt--1.0: "),
])
def test_a_bad_sweep_file_is_a_case_error_naming_the_key(tmp_path, text, expected):
    with pytest.raises(CaseError) as error:
        load_sweep(_write(tmp_path, text))
    assert expected in str(error.value)


def test_members_are_the_product_or_the_zip_of_the_lists_times_the_seeds(tmp_path):
    product = load_sweep(_write(tmp_path, 'base = "base.toml"\n[parameters]\n'
                                '"simulation.theta" = [0.5, 1.0]\n'
                                '"simulation.dt" = [1e-3, 5e-4]\n'
                                '"simulation.seed" = {count = 3, start = 1}\n'
                                '[set]\n"output.interval" = 2\n'))
    assert len(product.members) == 2 * 2 * 3
    assert product.swept == ["simulation.theta", "simulation.dt"]
    assert product.seed_key == "simulation.seed"
    first = product.members[0]
    assert first.name == "theta-0.5_dt-0.001_seed-1"
    assert first.overrides == {"output.interval": 2, "simulation.theta": 0.5,
                               "simulation.dt": 1e-3, "simulation.seed": 1}
    assert len({m.group for m in product.members}) == 4  # replicates share their group
    zipped = load_sweep(_write(tmp_path, 'base = "base.toml"\ncombine = "zip"\n'
                               '[parameters]\n"simulation.theta" = [0.5, 1.0]\n'
                               '"simulation.dt" = [1e-3, 5e-4]\n'))
    assert [m.name for m in zipped.members] == ["theta-0.5_dt-0.001", "theta-1.0_dt-0.0005"]


def _interrupted_after(case, out: Path, steps: int) -> None:
    """Run ``case`` into ``out`` and stop it cleanly (SIGINT) after ``steps`` steps."""
    sim = Simulation(case, out=out)
    step = sim.step

    def stepping(*args, **kwargs):
        result = step(*args, **kwargs)
        if sim.state.step == steps:
            signal.raise_signal(signal.SIGINT)
        return result

    sim.step = stepping
    assert sim.run()["status"] == "interrupted"


def test_a_sweep_runs_on_a_local_cluster_and_a_rerun_skips_and_resumes(tmp_path):
    """Two workers; one member leaves the grid on purpose (exit 3) without stopping the
    others; a re-run skips the finished members, resumes an interrupted one from its
    checkpoint and retries the failed one; sweep.json and the exit codes say so."""
    path = _write(tmp_path, 'base = "base.toml"\n[parameters]\n'
                  '"bodies.0.velocity" = [[0.1, 0.0], [1000.0, 0.0], [0.2, 0.0]]\n'
                  '[set]\n"output.snapshot_interval" = 0\n"output.interval" = 1\n')
    sweep = load_sweep(path)
    out = tmp_path / "out"
    names = [m.name for m in sweep.members]
    assert names == ["velocity-0.1,0.0", "velocity-1000.0,0.0", "velocity-0.2,0.0"]
    # the third member was interrupted after 4 of its 10 steps by an earlier sweep
    third = sweep.members[2]
    _interrupted_after(load_case(sweep.base, dict(third.overrides)), out / third.name, 4)
    lines = []
    outcomes = run_sweep(sweep, out, workers=2, echo=lines.append)
    assert [o.status for o in outcomes] == ["done", "failed", "done"]
    assert outcomes[1].code == 3 and "left the grid" in outcomes[1].message
    assert any(line.startswith("Dask dashboard: ") for line in lines)
    assert any("[3/3]" in line and "1 failed" in line for line in lines)
    resumed = read_table(out / third.name / "series.csv")["step"]
    assert np.array_equal(resumed, np.arange(resumed[0], 11))  # no step twice, none lost
    assert "resumed" in (out / third.name / "run.log").read_text().lower()
    report = json.loads((out / "sweep.json").read_text())
    assert [m["status"] for m in report["members"]] == ["done", "failed", "done"]

    lines.clear()
    again = run_sweep(sweep, out, workers=2, echo=lines.append)
    assert [o.status for o in again] == ["skipped (done before)", "failed",
                                         "skipped (done before)"]
    assert "3 members, 2 done before, 1 to run" in lines[0]
    # the skipped members keep the wall times of the run that did them
    walls = [m["wall_time_s"] for m in json.loads((out / "sweep.json").read_text())["members"]]
    assert walls[0] == report["members"][0]["wall_time_s"] > 0
    assert walls[2] == report["members"][2]["wall_time_s"] > 0


def test_the_sweep_command_prints_the_table_and_exits_non_zero_on_a_failed_member(
        tmp_path, capsys):
    from softgrains.cli import main

    path = _write(tmp_path, 'base = "base.toml"\n[parameters]\n'
                  '"bodies.0.velocity" = [[0.1, 0.0], [1000.0, 0.0]]\n'
                  '[set]\n"output.snapshot_interval" = 0\n')
    status = main(["sweep", str(path), "--out", str(tmp_path / "out"), "--workers", "1"])
    captured = capsys.readouterr()
    assert status == 3
    assert re.search(r"^velocity-0\.1,0\.0 +done", captured.out, re.M)
    assert re.search(r"^velocity-1000\.0,0\.0 +failed", captured.out, re.M)
    assert "1 of 2 members did not complete" in captured.err
    assert main(["sweep", str(tmp_path / "missing.toml")]) == 2


def test_a_killed_workers_member_is_rescheduled_and_resumes_from_its_checkpoint(tmp_path):
    """Issue #12, item 3: the worker running a member is killed (SIGKILL, as by the
    kernel's OOM killer or a lost node); Dask reschedules the member on a worker its nanny
    restarts, the member resumes from its last checkpoint, and the sweep ends with every
    member done."""
    import os
    import threading
    import time

    from dask.distributed import Client, LocalCluster

    from softgrains.sweep.runner import QUIET_WORKERS

    path = _write(tmp_path, 'base = "base.toml"\n[parameters]\n'
                  '"bodies.0.velocity" = [[0.1, 0.0], [0.2, 0.0]]\n'
                  '[set]\n"simulation.end_time" = 0.6\n"output.snapshot_interval" = 0\n'
                  '"output.interval" = 1\n"output.checkpoint_interval" = 20\n')
    sweep = load_sweep(path)
    out = tmp_path / "out"
    import dask

    with dask.config.set(QUIET_WORKERS):
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                               dashboard_address=":0")
    client = Client(cluster)
    try:
        result = {}
        thread = threading.Thread(target=lambda: result.update(outcomes=run_sweep(
            sweep, out, scheduler=cluster.scheduler_address, echo=lambda line: None)))
        thread.start()
        victim = sweep.members[0].name
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # until the member has passed a checkpoint
            series = out / victim / "series.csv"
            if (out / victim / "checkpoint.h5").is_file() and series.is_file() \
                    and len(series.read_text().splitlines()) > 60:
                break
            time.sleep(0.05)
        else:
            pytest.fail("the member never reached its first checkpoint")
        worker = next((address for address, keys in client.processing().items()
                       if f"member-{victim}" in keys), None)
        if worker is None:
            thread.join(timeout=300)
            pytest.fail("the member ended before its worker could be killed")
        pid = client.run(os.getpid, workers=[worker])[worker]
        os.kill(pid, signal.SIGKILL)
        thread.join(timeout=300)
        if thread.is_alive():
            pytest.fail("the sweep did not end within 5 minutes of the kill")
    finally:
        client.close()
        cluster.close()
    assert [o.status for o in result["outcomes"]] == ["done", "done"]
    assert "resumed" in (out / victim / "run.log").read_text().lower()
    steps = read_table(out / victim / "series.csv")["step"]
    assert np.array_equal(steps, np.arange(steps[0], 601))  # no step twice, none lost

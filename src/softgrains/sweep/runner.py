"""Run the members of a sweep as Dask tasks (issue #12), on a LocalCluster of single-threaded
worker processes by default or on an existing scheduler.

Each member runs into DIR/<member name> as a normal run (case.toml, series.csv, checkpoint.h5,
summary.json …). A member whose summary.json says it completed is skipped; one with a
checkpoint resumes from it (also when Dask reschedules the task of a killed worker); a failing
member (exit 3 or a crash) is reported and the others go on. DIR/sweep.json lists the members
and their outcome.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

from softgrains.batch import run_case
from softgrains.errors import EXIT_FAILED, EXIT_INVALID, EXIT_OK
from softgrains.io import CHECKPOINT_NAME
from softgrains.sweep.spec import Member, Sweep

QUIET_WORKERS = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.system-monitor.gil.enabled": False}


@dataclass
class Outcome:
    """What became of one member."""

    name: str
    status: str  # "done", "skipped (done before)", "failed", "invalid", "interrupted"
    code: int
    message: str = ""
    wall_s: float = 0.0


def completed(folder: Path) -> bool:
    """Whether the run in ``folder`` finished (its summary.json says completed)."""
    try:
        summary = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return False
    return str(summary.get("status", "")).startswith("completed")


def run_member(base: str, overrides: dict, folder: str, threads: int) -> tuple[int, str, float]:
    """One member, in a worker: (exit status, message, wall seconds). Resumes from the
    folder's checkpoint when there is one; its log goes to its run.log only."""
    start = time.perf_counter()
    resume = (Path(folder) / CHECKPOINT_NAME).is_file()
    code, message = run_case(base, overrides, folder, threads, resume=resume, quiet=True)
    return code, message, time.perf_counter() - start


def run_sweep(sweep: Sweep, out: Path, workers: int = 0, scheduler: str | None = None,
              threads: int = 1, echo=print) -> list[Outcome]:
    """Run the sweep's members into ``out``; returns their outcomes (also in sweep.json)."""
    import dask
    from dask.distributed import Client, LocalCluster

    out.mkdir(parents=True, exist_ok=True)
    before = _earlier_walls(out)
    outcomes = {m.name: Outcome(m.name, "skipped (done before)", EXIT_OK,
                                wall_s=before.get(m.name, 0.0))
                for m in sweep.members if completed(out / m.name)}
    todo = [m for m in sweep.members if m.name not in outcomes]
    echo(f"sweep {sweep.path.name}: {len(sweep.members)} members, {len(outcomes)} done "
         f"before, {len(todo)} to run; results in {out}")
    if todo:
        if scheduler:
            client, cluster = Client(scheduler), None
        else:
            n = workers or min(len(todo), os.cpu_count() or 1)
            # the workers' statistical profiler (every 10 ms) and GIL monitor (every 1 ms)
            # slowed our Python-heavy steps by a third (benchmarks/sweep_speedup.py)
            with dask.config.set(QUIET_WORKERS):
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                       dashboard_address=":0")
            client = Client(cluster)
        try:
            echo(f"Dask dashboard: {client.dashboard_link}")
            _run_todo(client, sweep, todo, out, threads, outcomes, echo)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    ordered = [outcomes[m.name] for m in sweep.members]
    _write_report(out, sweep, ordered)
    _ensemble(out, echo)
    return ordered


def _earlier_walls(out: Path) -> dict[str, float]:
    """The wall times of the members an earlier run of the sweep recorded in sweep.json
    (kept for the members it skips now)."""
    try:
        report = json.loads((out / "sweep.json").read_text())
        return {m["name"]: float(m["wall_time_s"]) for m in report["members"]
                if m.get("wall_time_s")}
    except (OSError, ValueError, KeyError, TypeError):
        return {}


def _ensemble(out: Path, echo) -> None:
    """The ensemble statistics of a compaction sweep (nothing for other protocols)."""
    from softgrains.sweep.ensemble import ensemble_statistics

    try:
        result = ensemble_statistics(out)
    except (OSError, ValueError, KeyError) as error:
        echo(f"ensemble statistics not drawn: {error!r}")
        return
    if result["groups"]:
        echo(f"ensemble statistics of {len(result['groups'])} group(s) in {out / 'ensemble'}")


def _run_todo(client, sweep: Sweep, todo: list[Member], out: Path, threads: int,
              outcomes: dict, echo) -> None:
    """Submit the members, then report each as it ends with the counts and the time left."""
    from dask.distributed import as_completed

    futures = {client.submit(run_member, str(sweep.base), m.overrides, str(out / m.name),
                             threads, key=f"member-{m.name}", pure=False): m for m in todo}
    started, walls, total = time.perf_counter(), [], len(todo)
    workers = max(1, len(client.scheduler_info().get("workers", {})))
    for future in as_completed(futures):
        member = futures[future]
        if future.status == "error":
            outcomes[member.name] = Outcome(member.name, "failed", EXIT_FAILED,
                                            f"crashed: {future.exception()!r}")
        else:
            code, message, wall = future.result()
            status = ("done" if code == EXIT_OK else "invalid" if code == EXIT_INVALID
                      else "interrupted" if code > 128 else "failed")
            outcomes[member.name] = Outcome(member.name, status, code, message, wall)
            walls.append(wall)
        ended = [outcomes[m.name] for m in todo if m.name in outcomes]
        finished = len(ended)
        failed = sum(1 for o in ended if o.status != "done")
        left = total - finished
        eta = (sum(walls) / len(walls)) * left / min(workers, max(left, 1)) if walls else 0.0
        echo(f"[{finished}/{total}] {member.name}: {outcomes[member.name].status}"
             f" — {finished - failed} done, {min(left, workers)} running, {failed} failed; "
             f"about {_duration(eta)} left ({_duration(time.perf_counter() - started)} so far)")


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60} min {seconds % 60:02d} s" if seconds >= 60 else f"{seconds} s"


def _write_report(out: Path, sweep: Sweep, outcomes: list[Outcome]) -> None:
    """sweep.json: the base case, the swept keys and every member's outcome."""
    report = {
        "sweep": str(sweep.path), "base": str(sweep.base), "swept": sweep.swept,
        "seed_key": sweep.seed_key,
        "members": [{"name": o.name, "status": o.status, "exit_status": o.code,
                     "message": o.message, "wall_time_s": o.wall_s,
                     "overrides": m.overrides, "group": list(m.group)}
                    for o, m in zip(outcomes, sweep.members, strict=True)],
    }
    tmp = out / "sweep.json.tmp"
    tmp.write_text(json.dumps(report, indent=2, default=str))
    tmp.replace(out / "sweep.json")


def table(outcomes: list[Outcome]) -> str:
    """The members and their outcome, one line each."""
    width = max((len(o.name) for o in outcomes), default=6)
    lines = [f"{'member':<{width}}  status                 wall"]
    for o in outcomes:
        wall = _duration(o.wall_s) if o.wall_s else "-"
        lines.append(f"{o.name:<{width}}  {o.status:<22} {wall}"
                     + (f"\n{'':<{width}}  {o.message.splitlines()[0][:160]}"
                        if o.code not in (EXIT_OK,) and o.message else ""))
    return "\n".join(lines)

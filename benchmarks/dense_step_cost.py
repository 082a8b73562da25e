"""Cost of dense compaction steps (issue 11, cost bar): resume a run's checkpoint and time
the same steps under several settings, in one process, one after the other.

    python benchmarks/dense_step_cost.py RUN_DIR [--steps 5] \
        [--variant default] [--variant "exact:simulation.tangent=exact"] ...

RUN_DIR is a run folder with checkpoint.h5 and case.toml (e.g. a compaction example
stopped past 100 σ0). A variant is LABEL or LABEL:KEY=VALUE,KEY=VALUE (case overrides).
Prints, per variant, seconds a step (mean, median, max), the process's CPU time over its
wall time (above 1: the share of the step that ran on a second thread), coupling
iterations and contact-solver iterations a step, and the ratio of its time to the first
variant's.
To compare code versions, run the script from each checkout on the same RUN_DIR, side
by side with NUMBA_NUM_THREADS=1 (docs/dev-notes.md, "Speed, session 17").
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from softgrains import Simulation, load_case


def _variant(text: str) -> tuple[str, list[str]]:
    label, _, overrides = text.partition(":")
    return label, [o for o in overrides.split(",") if o]


@contextmanager
def resumed(run: Path, overrides: list[str] | None = None) -> Iterator[Simulation]:
    """A Simulation resumed from ``run``'s checkpoint (with ``overrides`` to its case), in a
    scratch copy of the run folder (without its snapshots, figures, contacts and grains)
    that is removed afterwards."""
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "run"
        shutil.copytree(run, out, ignore=shutil.ignore_patterns(
            "snapshots", "figures", "contacts", "grains"))
        sim = Simulation(load_case(out / "case.toml", overrides), out=out)
        sim.resume(out / "checkpoint.h5")
        yield sim


def time_steps(run: Path, overrides: list[str], steps: int) -> dict:
    """Resume ``run`` in a scratch copy and time ``steps`` steps (after one untimed step,
    which pays any JIT compilation)."""
    with resumed(run, overrides) as sim:
        sim.step()
        seconds, iterations, sweeps = [], [], []
        cpu = time.process_time()
        for _ in range(steps):
            start = time.perf_counter()
            diag = sim.step()
            seconds.append(time.perf_counter() - start)
            iterations.append(diag.contact.iterations)
            sweeps.append(diag.contact.sweeps)
        cpu = time.process_time() - cpu
    return {"seconds": seconds, "iterations": iterations, "sweeps": sweeps,
            "cpu_over_wall": cpu / sum(seconds)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, help="run folder with checkpoint.h5, case.toml")
    parser.add_argument("--steps", type=int, default=5, help="timed steps per variant")
    parser.add_argument("--variant", action="append", default=None,
                        help="LABEL or LABEL:KEY=VALUE,... (default: the run's settings)")
    args = parser.parse_args()
    variants = [_variant(v) for v in (args.variant or ["default"])]
    print("| variant | s/step mean | median | max | CPU/wall | coupling its/step "
          "| solver its/step | time ratio |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    first = None
    for label, overrides in variants:
        r = time_steps(args.run, overrides, args.steps)
        mean = statistics.fmean(r["seconds"])
        first = first or mean
        print(f"| {label} | {mean:.3f} | {statistics.median(r['seconds']):.3f} | "
              f"{max(r['seconds']):.3f} | {r['cpu_over_wall']:.2f} | "
              f"{statistics.fmean(r['iterations']):.1f} | "
              f"{statistics.fmean(r['sweeps']):.0f} | {mean / first:.2f} |", flush=True)


if __name__ == "__main__":
    main()

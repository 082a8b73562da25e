"""The cost of finished compaction runs (issue 4, item 8), as a Markdown table.

Reads each run folder's summary.json (and series.csv for the compaction's end state):
points, steps, wall time, time per step (without the first, JIT-compiling step), point
updates per second, threads, peak resident memory, and where the run ended (σ_yy/σ0, φ).
Run the example cases first (README main job, and the full-resolution recipe), then:

    python benchmarks/example_runs_table.py results/compaction/* results/compaction-fine/*
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from softgrains.io import read_table


def row(run: Path) -> str:
    summary = json.loads((run / "summary.json").read_text())
    protocol = summary.get("protocol") or {}
    final = summary.get("final") or {}
    sigma0 = protocol.get("sigma0")
    end = (f"{final['stress_yy'] / sigma0:.0f} σ0, φ = {final['phi']:.3f}"
           if sigma0 and "stress_yy" in final else "—")
    series = read_table(run / "series.csv")
    comp_steps = int((series["phase"] == "compaction").sum()) if "phase" in series else 0
    memory = summary.get("peak_memory_mib")
    return (f"| {run.name} | {summary['points']} | {summary['steps']} ({comp_steps}) | "
            f"{summary['wall_time_s']:.0f} | {summary['time_per_step_s']:.3f} | "
            f"{summary['point_updates_per_second']:.3g} | {summary['threads']} | "
            f"{f'{memory:.0f}' if memory is not None else '—'} | {summary['status']}, {end} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+", help="run folders (with summary.json)")
    args = parser.parse_args()
    print("| run | points | steps (compaction) | wall time [s] | s/step | point updates/s | "
          "threads | peak memory [MiB] | end |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for run in args.runs:
        if (run / "summary.json").is_file():
            print(row(run))


if __name__ == "__main__":
    main()

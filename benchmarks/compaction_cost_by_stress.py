"""Cost of compaction steps by stress band, from finished (or stopped) run folders (issue 11,
cost bar; the dense steps are the high-stress bands).

For each run folder (series.csv and case.toml), the compaction rows are grouped by the
wall stress σ_yy/σ0 of the step; per band: steps, seconds a step (mean, median, max, from
the cumulative ``wall_time``), coupling iterations a step, and the ratio of the mean to
the first run's in the same band; then per run its slowest compaction step over the
compaction's median (#11's tail bar). Runs of different code versions are compared this way:
start the same example from each checkout side by side with NUMBA_NUM_THREADS=1 (a run
stopped early, e.g. with SIGTERM, covers the bands it reached).
Run:  python benchmarks/compaction_cost_by_stress.py RUN_A RUN_B ... [--bands 0 2 10 40 100 200 400]
"""

from __future__ import annotations

import argparse
import statistics
import tomllib
from pathlib import Path

import numpy as np

from softgrains.io import read_table


def _sigma0(case_file: Path) -> float:
    """The protocol's σ0 from a run's case.toml (as compaction_overlap.py reads it)."""
    protocol = tomllib.loads(case_file.read_text()).get("protocol", {})
    if "sigma0" not in protocol:
        raise SystemExit(f"{case_file}: no [protocol] sigma0 (not a compaction run)")
    return float(protocol["sigma0"])


def band_costs(run: Path, bands: list[float]) -> list[dict | None]:
    """Per band [bands[i], bands[i+1]) of σ_yy/σ0: steps, s/step stats, coupling its/step."""
    table = read_table(run / "series.csv")
    wall = np.asarray(table["wall_time"], float)
    seconds = np.diff(wall, prepend=wall[0])
    phase = np.asarray(table["phase"])
    ratio = np.asarray(table["stress_yy"], float) / _sigma0(run / "case.toml")
    its = np.asarray(table["contact_iterations"], float)
    rows = []
    for lower, upper in zip(bands[:-1], bands[1:], strict=False):
        chosen = (phase == "compaction") & (ratio >= lower) & (ratio < upper)
        if not chosen.any():
            rows.append(None)
            continue
        s = seconds[chosen]
        rows.append({"steps": int(chosen.sum()), "mean": float(s.mean()),
                     "median": statistics.median(s), "max": float(s.max()),
                     "its": float(its[chosen].mean())})
    return rows


def slowest_step(run: Path) -> tuple[float, int, float, int]:
    """The slowest compaction step over the compaction's median (#11's "no step above 10×
    the median"): (ratio, its step number, its σ_yy/σ0, its coupling iterations). Its time
    includes any failed attempt the step-size controller undid."""
    table = read_table(run / "series.csv")
    wall = np.asarray(table["wall_time"], float)
    seconds = np.diff(wall, prepend=0.0)
    chosen = np.flatnonzero(np.asarray(table["phase"]) == "compaction")
    worst = chosen[np.argmax(seconds[chosen])]
    ratio = np.asarray(table["stress_yy"], float) / _sigma0(run / "case.toml")
    return (float(seconds[worst] / statistics.median(seconds[chosen])),
            int(table["step"][worst]), float(ratio[worst]),
            int(table["contact_iterations"][worst]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--bands", type=float, nargs="+",
                        default=[0.0, 2.0, 10.0, 40.0, 100.0, 200.0, 400.0])
    args = parser.parse_args()
    costs = [band_costs(run, args.bands) for run in args.runs]
    print("| run | σ/σ0 | steps | s/step mean | median | max | coupling its/step "
          "| time ratio |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for run, rows in zip(args.runs, costs, strict=True):
        for i, row in enumerate(rows):
            if row is None:
                continue
            first = costs[0][i]
            ratio = f"{row['mean'] / first['mean']:.2f}" if first else "—"
            print(f"| {run} | {args.bands[i]:g}–{args.bands[i + 1]:g} | {row['steps']} "
                  f"| {row['mean']:.2f} | {row['median']:.2f} | {row['max']:.2f} "
                  f"| {row['its']:.1f} | {ratio} |")
    print("\n| run | slowest compaction step / median | step | σ/σ0 | coupling its |")
    print("| --- | --- | --- | --- | --- |")
    for run in args.runs:
        over, at, stress, its = slowest_step(run)
        print(f"| {run} | {over:.1f}× | {at} | {stress:.0f} | {its} |")


if __name__ == "__main__":
    main()

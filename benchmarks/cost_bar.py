"""Issue 11's cost bar in one benchmark run: the frictional compaction example to a stress
ratio, run by this checkout and by a reference checkout (e.g. a worktree of bacc7c3), one
after the other, alternating, each alone on one thread; then the compaction steps' cost
by stress band, the ratio of the means and of the medians and the neighbouring runs'
ratios (the machine's speed drifts by ±10% over minutes: alternating runs see the same
drift).

    git worktree add /tmp/bacc bacc7c3
    python benchmarks/cost_bar.py /tmp/bacc --out /tmp/bar [--rounds 3] [--stop 200]

Each side runs its own copy of the example (``--case`` is relative to each checkout: the
reference's case as it was then, e.g. bacc7c3's with its overlap removal; an absolute
path gives both the same file). A warm-up run of each checkout comes first (Numba's
compilation). Each run writes its folder under --out (ours_k, reference_k); a folder
whose run completed (summary.json) is reused, not run again, so a stopped benchmark goes
on where it stopped (an unfinished folder is run again) — reused runs are no longer
neighbours in time of the others. The table gives per band the range of the runs' mean
s a step, the ratio of the means over the runs, the neighbouring runs' ratios, and the
ratio of the runs' medians averaged.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from compaction_cost_by_stress import band_costs

from softgrains.sweep.runner import completed

HERE = Path(__file__).resolve().parent.parent  # this checkout


def run_case(checkout: Path, case: str, out: Path, stop: float) -> float:
    """The example ``case`` of ``checkout`` (its own code: ``checkout/src`` first on the
    path) to σ_yy/σ0 = ``stop``, on one Numba thread; returns the wall time."""
    if completed(out):
        return float("nan")
    shutil.rmtree(out, ignore_errors=True)  # (an unfinished run: again)
    env = dict(os.environ, NUMBA_NUM_THREADS="1", PYTHONPATH=str(checkout / "src"))
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "softgrains", "run", case, "--out",
                           str(out), "--set", f"protocol.stop_stress_ratio={stop:g}",
                           "--no-figures"], cwd=checkout, env=env, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise SystemExit(f"{out}: the run failed (exit {done.returncode}):\n"
                         + (done.stdout + done.stderr)[-2000:])
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("reference", type=Path, help="the reference checkout (with src/)")
    parser.add_argument("--out", type=Path, required=True, help="folder for the runs")
    parser.add_argument("--case", default="examples/compaction_frictional.toml")
    parser.add_argument("--stop", type=float, default=200.0, help="σ_yy/σ0 to stop at")
    parser.add_argument("--rounds", type=int, default=3, help="runs of each checkout")
    parser.add_argument("--bands", type=float, nargs="+", default=[40.0, 100.0, 200.0])
    args = parser.parse_args()
    if args.rounds < 1:
        raise SystemExit("--rounds: at least 1")
    reference = args.reference.resolve()
    if not (reference / "src" / "softgrains").is_dir():
        raise SystemExit(f"{reference}: no src/softgrains (a checkout of softgrains?)")
    args.out.mkdir(parents=True, exist_ok=True)
    run_case(HERE, args.case, args.out / "warm_up", args.stop)
    run_case(reference, args.case, args.out / "reference_warm_up", args.stop)
    order = []  # (label, folder) in the order run: ours, reference, ours, ...
    for k in range(1, args.rounds + 1):
        order.append(("ours", args.out / f"ours_{k}"))
        order.append(("reference", args.out / f"reference_{k}"))
    order.append(("ours", args.out / f"ours_{args.rounds + 1}"))
    for label, folder in order:
        seconds = run_case(HERE if label == "ours" else reference, args.case, folder,
                           args.stop)
        print(f"{folder.name}: " + ("reused" if seconds != seconds else f"{seconds:.0f} s"),
              flush=True)
    print("\n| σ/σ0 | ours s/step (the runs' means) | reference s/step (the runs' means) "
          "| ratio of the means | neighbouring pairs | ratio of the medians |")
    print("| --- | --- | --- | --- | --- | --- |")
    for lower, upper in zip(args.bands[:-1], args.bands[1:], strict=False):
        costs = [(label, band_costs(folder, [lower, upper])[0]) for label, folder in order]
        if any(c is None for _, c in costs):
            print(f"| {lower:g}–{upper:g} | (a run did not reach the band) | | | | |")
            continue
        ours = [c for label, c in costs if label == "ours"]
        ref = [c for label, c in costs if label == "reference"]
        means = [c["mean"] for _, c in costs]
        pairs = [means[i + 1] / means[i] if costs[i][0] == "ours" else means[i] / means[i + 1]
                 for i in range(len(means) - 1)]
        ratio = statistics.fmean(c["mean"] for c in ref) / statistics.fmean(
            c["mean"] for c in ours)
        medians = statistics.fmean(c["median"] for c in ref) / statistics.fmean(
            c["median"] for c in ours)
        print(f"| {lower:g}–{upper:g} | {min(c['mean'] for c in ours):.3f}–"
              f"{max(c['mean'] for c in ours):.3f} | {min(c['mean'] for c in ref):.3f}–"
              f"{max(c['mean'] for c in ref):.3f} | {ratio:.2f} | {min(pairs):.2f}–"
              f"{max(pairs):.2f} | {medians:.2f} |")


if __name__ == "__main__":
    main()

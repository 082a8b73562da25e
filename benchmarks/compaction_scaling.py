"""Cost of compaction steps against the number of grains, by stress band (issue 14, item 3):
the dense states (the high-stress bands) of finished (or stopped) runs of one case with
different [sample] counts.

Per run and band of σ_yy/σ0: grains, steps, s/step (mean), ms per grain and step, the
exponent a of cost ∝ N^a against the first run in the same band (a = 1: linear; the issue's
bar is a ≤ 1.1), and the run's peak memory and threads (summary.json). The runs of session
31 (one thread each; examples/compaction_1000.toml, box width ∝ √N as in it):
    NUMBA_NUM_THREADS=1 softgrains run examples/compaction_1000.toml --out runs/g100 \
        --set sample.count=100 --set sample.box_width=0.09 --no-figures
(300: 0.16 m; 30: 0.05 m; 1000: the example as it is).
Run:  python benchmarks/compaction_scaling.py RUN_30 RUN_100 ... [--bands 0 2 10 40 100 200]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tomllib
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compaction_cost_by_stress import band_costs  # noqa: E402


def _grains(run: Path) -> int:
    """The [sample] count of a run's case.toml."""
    case = tomllib.loads((run / "case.toml").read_text())
    if "sample" not in case:
        raise SystemExit(f"{run}: no [sample] in case.toml (not a compaction run)")
    return int(case["sample"]["count"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--bands", type=float, nargs="+",
                        default=[0.0, 2.0, 10.0, 40.0, 100.0, 200.0])
    args = parser.parse_args()
    runs = sorted(args.runs, key=_grains)
    grains = [_grains(run) for run in runs]
    costs = [band_costs(run, args.bands) for run in runs]
    print("| grains | σ/σ0 | steps | s/step | ms/(grain·step) | a (cost ∝ N^a) "
          "| coupling its/step | peak MiB | threads |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for run, n, rows in zip(runs, grains, costs, strict=True):
        summary_file = run / "summary.json"
        summary = json.loads(summary_file.read_text()) if summary_file.exists() else {}
        memory = summary.get("peak_memory_mib", math.nan)
        threads = summary.get("threads", "?")
        for i, row in enumerate(rows):
            if row is None:
                continue
            first = costs[0][i]
            exponent = (math.log(row["mean"] / first["mean"]) / math.log(n / grains[0])
                        if first and n != grains[0] else math.nan)
            print(f"| {n} | {args.bands[i]:g}–{args.bands[i + 1]:g} | {row['steps']} "
                  f"| {row['mean']:.2f} | {1e3 * row['mean'] / n:.1f} | {exponent:.2f} "
                  f"| {row['its']:.1f} | {memory:.0f} | {threads} |")


if __name__ == "__main__":
    main()

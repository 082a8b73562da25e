"""The two regimes of finished compaction runs (VALIDATION.md C9): break and slopes.

For each run folder, φ/φ0 against log10(σ_yy/σ0) over the compaction rows between
``--lower`` and ``--upper`` σ0 is fitted with two joined lines (observe/regimes.py); the
table gives the break (in σ0), the slopes before and after (per decade) and the rms
residual. The paper's curve changes near 30 σ0, the second regime steeper.
Run:  python benchmarks/compaction_regimes.py results/compaction/* [--lower 5 --upper 300]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from softgrains.io import read_table
from softgrains.observe.regimes import fit_two_regimes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--lower", type=float, default=5.0)
    parser.add_argument("--upper", type=float, default=300.0)
    args = parser.parse_args()
    print(f"fit over {args.lower:g}–{args.upper:g} σ0")
    print("| run | break [σ0] | slope before [1/decade] | slope after [1/decade] | rms | rows |")
    print("| --- | --- | --- | --- | --- | --- |")
    for run in args.runs:
        series = read_table(run / "series.csv")
        protocol = json.loads((run / "summary.json").read_text())["protocol"]
        comp = series["phase"] == "compaction"
        fit = fit_two_regimes(series["stress_yy"][comp] / protocol["sigma0"],
                              series["phi"][comp] / protocol["phi0"], args.lower, args.upper)
        print(f"| {run.name} | {fit.break_ratio:.0f} | {fit.slope_before:.3f} | "
              f"{fit.slope_after:.3f} | {fit.rms:.4f} | {fit.samples} |")


if __name__ == "__main__":
    main()

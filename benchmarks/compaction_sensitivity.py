"""Sensitivity of the compaction curve φ(σ) to the resolution (VALIDATION.md C9, issue 4).

Reads the series.csv of finished compaction runs (e.g. the example at its Δt and h, with
Δt halved, with h halved) and prints φ and φ/φ0 where σ_yy/σ0 first reaches each level
(linear interpolation between the two rows around the crossing), and the differences
from the first run.
Run:  python benchmarks/compaction_sensitivity.py REF_DIR OTHER_DIR [...] [--levels 2 5 ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from softgrains.io import read_table
from softgrains.observe.compaction import phi_at_stress_ratios


def phi_at_levels(run: Path, levels: list[float]) -> tuple[float, dict[float, float]]:
    """φ0 and φ where σ_yy/σ0 first reaches each level in the compaction phase (nan if never)."""
    series = read_table(run / "series.csv")
    protocol = json.loads((run / "summary.json").read_text())["protocol"]
    sigma0, phi0 = protocol["sigma0"], protocol["phi0"]
    comp = series["phase"] == "compaction"
    values = phi_at_stress_ratios(series["stress_yy"][comp] / sigma0, series["phi"][comp],
                                  levels)
    return phi0, {level: float(v) for level, v in zip(levels, values, strict=True)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--levels", type=float, nargs="+", default=[2, 5, 10, 20, 50, 100])
    args = parser.parse_args()
    results = [phi_at_levels(run, args.levels) for run in args.runs]
    ref_phi0, ref = results[0]
    print("| run | φ0 | " + " | ".join(f"φ at {lv:g} σ0" for lv in args.levels) + " |")
    print("| --- | --- | " + " | ".join("---" for _ in args.levels) + " |")
    for run, (phi0, found) in zip(args.runs, results, strict=True):
        cells = []
        for lv in args.levels:
            delta = found[lv] - ref[lv]
            cells.append(f"{found[lv]:.4f}" if run == args.runs[0]
                         else f"{found[lv]:.4f} ({delta:+.4f})")
        print(f"| {run.name} | {phi0:.4f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()

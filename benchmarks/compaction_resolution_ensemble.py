"""The packing fraction of seed ensembles at two or more resolutions (VALIDATION.md C9's
"< 1% when h is halved", issue 11 item 8): a single compaction path is chaotic (two runs
differing in round-off end 2% apart), so the effect of h is told from the seeds' spread.

Reads the completed members of a sweep (``softgrains sweep``) over ``grid.cell_size`` and
``simulation.seed`` (and ``contact.friction``), and prints per
friction and cell size: the members, the mean of φ0 (the pre-compacted φ at σ0) and of φ
where σ_yy/σ0 first reaches each level, their standard deviation, and the change of the mean
from the coarsest cell with its 95% band (t quantile × the two means' combined standard
error, Welch). A change whose band holds 0 is not told from the sample spread.

Run:  python benchmarks/compaction_resolution_ensemble.py SWEEP_DIR [--levels 1 3 10]
The sweep of session 25 (φ0 only: the compaction stops at 1.5 σ0):

    [parameters]
    "contact.friction" = [0.0, 0.5]
    "grid.cell_size" = [1e-3, 5e-4]
    "simulation.seed" = {count = 4}
    [set]
    "protocol.stop_stress_ratio" = 1.5
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).parent))
from compaction_sensitivity import phi_at_levels  # noqa: E402


def collect(sweep: Path, levels: list[float]) -> dict:
    """{(friction, cell size): [(φ0, {level: φ}), ...]} over the completed members, read
    from each member's resolved case.toml (the sweep may still be running)."""
    found = defaultdict(list)
    for summary in sorted(sweep.glob("*/summary.json")):
        member = summary.parent
        if json.loads(summary.read_text()).get("status") != "completed":
            continue
        case = tomllib.loads((member / "case.toml").read_text())
        key = (case["contact"]["friction"], case["grid"]["cell_size"])
        found[key].append(phi_at_levels(member, levels))
    return found


def band(a: np.ndarray, b: np.ndarray) -> float:
    """Half-width of the 95% band of mean(b) − mean(a) (Welch)."""
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    dof = (va + vb) ** 2 / (va**2 / (a.size - 1) + vb**2 / (b.size - 1))
    return float(stats.t.ppf(0.975, dof) * np.sqrt(va + vb))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweep", type=Path)
    parser.add_argument("--levels", type=float, nargs="*", default=[])
    args = parser.parse_args()
    found = collect(args.sweep, args.levels)
    groups = sorted({g for g, _ in found})
    print("| friction | cell size | members | quantity | mean | sd | change of the mean "
          "from the coarsest (95% band) |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for group in groups:
        cells = sorted((c for g, c in found if g == group), reverse=True)
        label = f"μ {group:g}"
        for quantity in ["phi0", *args.levels]:
            def values(cell, q=quantity, g=group):
                return np.array([p0 if q == "phi0" else at[q] for p0, at in found[g, cell]])
            coarse = values(cells[0])
            for cell in cells:
                v = values(cell)
                name = "φ0" if quantity == "phi0" else f"φ at {quantity:g} σ0"
                change = ""
                if cell != cells[0] and v.size > 1 and coarse.size > 1:
                    d = v.mean() - coarse.mean()
                    change = (f"{d:+.4f} ({100 * d / coarse.mean():+.1f}%) "
                              f"± {band(coarse, v):.4f}")
                print(f"| {label} | {cell:g} | {v.size} | {name} | {v.mean():.4f} | "
                      f"{v.std(ddof=1) if v.size > 1 else float('nan'):.4f} | {change} |")


if __name__ == "__main__":
    main()

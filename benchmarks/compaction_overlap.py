"""Grain–grain overlap and packing fraction against stress in compaction runs (issue 11,
item 8): the table that compares contact treatments on the reference compaction.

Reads each run folder's series.csv and prints, at the first compaction step where
σ_yy/σ0 reaches each level: the raster overlap fraction (observe/coverage.py, % of the box),
φ = Σ V_p / A_box, and the contact's own least gap at the active contacts (cells h); then
the mean coupling iterations per compaction step. Run the variants first, e.g. (1 thread
each, side by side on 2 cores):

    S="--set grid.shape_function=bspline2 --set contact.overlap_removal=0
       --set contact.overlap_tolerance=0 --set contact.on_failure=stop
       --set protocol.stop_stress_ratio=60 --no-figures"
    NUMBA_NUM_THREADS=1 softgrains run examples/compaction_frictionless.toml $S --out /tmp/a
    NUMBA_NUM_THREADS=1 softgrains run examples/compaction_frictionless.toml $S \\
        --set grid.cell_size=5e-4 --set simulation.dt=1e-5 --out /tmp/b
    python benchmarks/compaction_overlap.py /tmp/a /tmp/b
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import numpy as np

from softgrains.io import read_table

LEVELS = (1, 5, 10, 20, 40, 60, 100, 200, 300)


def row(run: Path, levels: tuple[int, ...]) -> str:
    """One table row: the run's cells at each σ_yy/σ0 level and its mean iterations."""
    with open(run / "case.toml", "rb") as f:
        case = tomllib.load(f)
    sigma0, h = case["protocol"]["sigma0"], case["grid"]["cell_size"]
    series = read_table(run / "series.csv")
    compaction = series["phase"] == "compaction"
    stress = series["stress_yy"][compaction] / sigma0
    overlap = series["overlap_fraction"][compaction]
    phi = series["phi"][compaction]
    gap = series["least_contact_gap"][compaction]
    its = series["contact_iterations"][compaction]
    cells = []
    for level in levels:
        reached = np.flatnonzero(stress >= level)
        if reached.size:
            i = reached[0]
            cells.append(f"{100 * overlap[i]:.3f}% / {phi[i]:.3f} / {gap[i] / h:.2f}")
        else:
            cells.append("—")
    mean_its = f"{its.mean():.1f}" if its.size else "—"
    return f"| {run.name} | " + " | ".join(cells) + f" | {mean_its} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+", help="run folders (with series.csv)")
    parser.add_argument("--levels", type=int, nargs="+", default=list(LEVELS),
                        help="σ_yy/σ0 levels (default: %(default)s)")
    args = parser.parse_args()
    print("cells: overlap % of the box / φ / least gap at the active contacts [h]\n")
    print("| run | " + " | ".join(f"{v} σ0" for v in args.levels) + " | its/step |")
    print("| --- |" + " --- |" * (len(args.levels) + 1))
    for run in args.runs:
        print(row(run, tuple(args.levels)))


if __name__ == "__main__":
    main()

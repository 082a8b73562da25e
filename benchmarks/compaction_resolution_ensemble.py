"""The packing fraction of seed ensembles at two or more resolutions (VALIDATION.md C9's
"< 1% when h is halved", issue 11 item 8): a single compaction path is chaotic (two runs
differing in round-off end 2% apart), so the effect of h is told from the seeds' spread.

Reads completed compaction runs — the members of a sweep (``softgrains sweep``) over
``grid.cell_size`` and ``simulation.seed`` (and ``contact.friction``), or run folders given
one by one — and prints per friction and resolution (cell size, points per cell per axis,
the grains' outer ring density): the members, the mean of φ0 (the pre-compacted φ at σ0)
and of φ where σ_yy/σ0 first reaches each level, their standard deviation, and the change
of the mean from the coarsest (the largest point spacing) with its 95% band (t quantile
× the two means' combined standard error, Welch). A change whose band holds 0 is not told
from the sample spread. With ``--response`` also the compaction's own response φ − φ0 at
each level (the pre-compacted state's spread taken out), and where the same seeds ran at
both cells the mean of their paired differences with its 95% band (t, n − 1 degrees).

Run:  python benchmarks/compaction_resolution_ensemble.py SWEEP_OR_RUN_DIR [...] \
          [--levels 1 3 10] [--response]
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


def resolution(case: dict) -> tuple[float, int, int]:
    """A run's resolution: (cell size, points per cell per axis, the grains' outer ring
    density), from its resolved case.toml (defaults where a key is absent)."""
    density = case.get("sample", {}).get("outer_ring_density", 1)
    return (case["grid"]["cell_size"], case["grid"].get("points_per_cell", 2), density)


def coarse_first(key: tuple[float, int, int]) -> tuple[float, int]:
    """Sort key of resolutions: the largest point spacing first, then the sparsest outer
    ring."""
    cell, per_cell, density = key
    return (-cell / per_cell, density)


def collect(paths: list[Path], levels: list[float]) -> dict:
    """{(friction, resolution): {seed: (φ0, {level: φ})}} over the completed runs: each path
    a run folder or a sweep's folder of members, each read from its resolved case.toml (a
    sweep may still be running)."""
    found = defaultdict(dict)
    for path in paths:
        summaries = ([path / "summary.json"] if (path / "summary.json").exists()
                     else sorted(path.glob("*/summary.json")))
        for summary in summaries:
            member = summary.parent
            if json.loads(summary.read_text()).get("status") != "completed":
                continue
            case = tomllib.loads((member / "case.toml").read_text())
            key = (case["contact"]["friction"], resolution(case))
            found[key][case["simulation"]["seed"]] = phi_at_levels(member, levels)
    return found


def band(a: np.ndarray, b: np.ndarray) -> float:
    """Half-width of the 95% band of mean(b) − mean(a) (Welch)."""
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    dof = (va + vb) ** 2 / (va**2 / (a.size - 1) + vb**2 / (b.size - 1))
    return float(stats.t.ppf(0.975, dof) * np.sqrt(va + vb))


def paired_band(d: np.ndarray) -> float:
    """Half-width of the 95% band of the mean of paired differences d (t, n − 1)."""
    return float(stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size))


def value(run: tuple[float, dict], quantity) -> float:
    """φ0 ("phi0"), φ at a level (a number), or φ − φ0 at a level (("response", level))."""
    phi0, at = run
    if quantity == "phi0":
        return phi0
    if isinstance(quantity, tuple):
        return at[quantity[1]] - phi0
    return at[quantity]


def name(quantity) -> str:
    if quantity == "phi0":
        return "φ0"
    if isinstance(quantity, tuple):
        return f"φ − φ0 at {quantity[1]:g} σ0"
    return f"φ at {quantity:g} σ0"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+", help="sweep folders or run folders")
    parser.add_argument("--levels", type=float, nargs="*", default=[])
    parser.add_argument("--response", action="store_true",
                        help="also φ − φ0 and the differences paired by seed")
    args = parser.parse_args()
    found = collect(args.runs, args.levels)
    groups = sorted({g for g, _ in found})
    quantities = ["phi0", *args.levels]
    if args.response:
        quantities += [("response", level) for level in args.levels]
    print("| friction | cell size / points per cell / outer ring | members | quantity | mean "
          "| sd | change of the mean from the coarsest (95% band) | paired by seed: seeds, "
          "mean change (95% band) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for group in groups:
        cells = sorted((c for g, c in found if g == group), key=coarse_first)
        label = f"μ {group:g}"
        for quantity in quantities:
            coarse_runs = found[group, cells[0]]
            coarse = np.array([value(r, quantity) for r in coarse_runs.values()])
            for cell in cells:
                runs = found[group, cell]
                v = np.array([value(r, quantity) for r in runs.values()])
                change = paired = ""
                if cell != cells[0] and v.size > 1 and coarse.size > 1:
                    d = v.mean() - coarse.mean()
                    # in % of φ itself (for φ − φ0: of φ at that level), as C9's bar reads
                    of = (np.mean([value(r, quantity[1]) for r in coarse_runs.values()])
                          if isinstance(quantity, tuple) else coarse.mean())
                    change = (f"{d:+.4f} ({100 * d / of:+.1f}%) "
                              f"± {band(coarse, v):.4f}")
                    seeds = sorted(set(runs) & set(coarse_runs))
                    if len(seeds) > 1:
                        pairs = np.array([value(runs[s], quantity)
                                          - value(coarse_runs[s], quantity) for s in seeds])
                        paired = f"{len(seeds)}, {pairs.mean():+.4f} ± {paired_band(pairs):.4f}"
                print(f"| {label} | {cell[0]:g} / {cell[1]} / {cell[2]} | {v.size} | "
                      f"{name(quantity)} | {v.mean():.4f} | "
                      f"{v.std(ddof=1) if v.size > 1 else float('nan'):.4f} | {change} | "
                      f"{paired} |")


if __name__ == "__main__":
    main()

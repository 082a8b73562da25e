"""Ensemble statistics of a compaction sweep (issue #12, item 4).

Members that differ only by their seed form a group. For every member, each observable is
taken at the first compaction row where the stress ratio s = σ/σ0 reaches each level of a
common log-spaced grid (linear interpolation between that row and the one before: the curve
a loading experiment records, unaffected by the stress drops of collapses), then
    mean_k = (1/n) Σ_i y_ik,   band_k = mean_k ± t_{0.975, n−1} s_k / √n
(s_k the sample standard deviation over the n members that reach level k; no band for n = 1).
The grid spans [1, the smallest of the members' largest s]. Against the top wall's σ_yy and
against the volume-averaged σ_yy (both over σ0). The two-regime fit (observe/regimes.py) is
made on the mean φ/φ0 and on every member, whose breaks give the scatter.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from softgrains.io import read_table
from softgrains.observe.regimes import fit_two_regimes

OBSERVABLES = ("phi", "phi_ratio", "coordination")
STRESSES = {"wall": "stress_yy", "average": "stress_yy_avg"}
GRID_POINTS = 40


@dataclass(frozen=True)
class GroupCurves:
    """One group's mean curves: stress levels (σ/σ0), members reaching each, and per
    observable the mean and the 95% band."""

    label: str
    stress: str
    levels: np.ndarray
    count: np.ndarray
    mean: dict[str, np.ndarray]
    low: dict[str, np.ndarray]
    high: dict[str, np.ndarray]


def loading_rows(series: dict[str, np.ndarray]) -> np.ndarray:
    """The compaction rows, preceded by the row before them (the pre-compacted state, whose
    φ is φ0) when there is one; empty without a compaction."""
    comp = np.flatnonzero(series["phase"] == "compaction")
    return np.r_[comp[0] - 1, comp] if comp.size and comp[0] > 0 else comp


def member_curve(series: dict[str, np.ndarray], sigma0: float, stress: str,
                 levels: np.ndarray) -> dict[str, np.ndarray]:
    """A member's observables at the first compaction row where stress/σ0 reaches each
    level (NaN beyond its largest stress); phi_ratio = φ/φ0 with φ0 the φ of the row before
    the compaction."""
    rows = loading_rows(series)
    if rows.size == 0:
        return {name: np.full(levels.size, np.nan) for name in OBSERVABLES}
    s = series[stress][rows] / sigma0
    values = {"phi": series["phi"][rows], "coordination": series["coordination"][rows]}
    values["phi_ratio"] = values["phi"] / series["phi"][rows[0]]
    out = {name: np.full(levels.size, np.nan) for name in OBSERVABLES}
    for k, level in enumerate(levels):
        reached = np.flatnonzero(s >= level)
        if reached.size == 0:
            continue
        j = reached[0]
        if j == 0 or s[j] == s[j - 1]:
            t, i = 1.0, max(j - 1, 0)
        else:
            i = j - 1
            t = (level - s[i]) / (s[j] - s[i])
        for name in OBSERVABLES:
            out[name][k] = values[name][i] + t * (values[name][j] - values[name][i])
    return out


def group_curves(label: str, members: list[tuple[dict, float]], stress: str,
                 levels: np.ndarray) -> GroupCurves:
    """Mean and 95% band over the members (series, σ0) of one group."""
    curves = [member_curve(series, sigma0, STRESSES[stress], levels)
              for series, sigma0 in members]
    mean, low, high = {}, {}, {}
    count = np.zeros(levels.size, dtype=int)
    for name in OBSERVABLES:
        y = np.array([c[name] for c in curves])  # (members, levels)
        m, half = np.full(levels.size, np.nan), np.full(levels.size, np.nan)
        for k in range(levels.size):
            col = y[np.isfinite(y[:, k]), k]
            count[k] = col.size
            if col.size:
                m[k] = col.mean()
            if col.size > 1:
                half[k] = stats.t.ppf(0.975, col.size - 1) * col.std(ddof=1) / np.sqrt(
                    col.size)
        mean[name], low[name], high[name] = m, m - half, m + half
    return GroupCurves(label, stress, levels, count, mean, low, high)


def stress_levels(members: list[tuple[dict, float]], stress: str) -> np.ndarray:
    """GRID_POINTS log-spaced levels from 1 to the smallest of the members' largest
    stress ratio during the compaction."""
    tops = []
    for series, sigma0 in members:
        comp = series["phase"] == "compaction"
        tops.append(float(np.max(series[STRESSES[stress]][comp]) / sigma0) if comp.any()
                    else 1.0)
    top = max(min(tops), 1.0 + 1e-9)
    return np.logspace(0.0, np.log10(top), GRID_POINTS)


def ensemble_statistics(sweep_dir: str | Path) -> dict[str, object]:
    """Write DIR/ensemble/: per group and stress measure a CSV of the mean curves with
    their bands, summary.json with the two-regime fits, and the figures. Returns the
    summary (groups with no completed compaction member are listed as skipped)."""
    sweep_dir = Path(sweep_dir)
    report = json.loads((sweep_dir / "sweep.json").read_text())
    groups: dict[tuple, list] = {}
    for m in report["members"]:
        folder = sweep_dir / m["name"]
        if m["status"] not in ("done", "skipped (done before)"):
            continue
        summary = json.loads((folder / "summary.json").read_text())
        protocol = summary.get("protocol") or {}
        if protocol.get("kind") != "uniaxial-compaction":
            continue
        groups.setdefault(tuple(m["group"]), []).append(
            (read_table(folder / "series.csv"), float(protocol["sigma0"]), m["name"]))
    out = sweep_dir / "ensemble"
    out.mkdir(exist_ok=True)
    result: dict[str, object] = {"swept": report["swept"], "groups": []}
    all_curves = []
    for key, members in groups.items():
        label = ", ".join(f"{k} = {v}" for k, v in zip(report["swept"], key, strict=True))
        slug = "_".join(f"{k.rsplit('.', 1)[-1]}-{v}" for k, v in
                        zip(report["swept"], key, strict=True)) or "all"
        pairs = [(series, sigma0) for series, sigma0, _ in members]
        entry: dict[str, object] = {"label": label, "members": [n for *_, n in members]}
        for stress in STRESSES:
            levels = stress_levels(pairs, stress)
            curves = group_curves(label, pairs, stress, levels)
            all_curves.append(curves)
            _write_csv(out / f"{slug}_{stress}.csv", curves)
            entry[f"fit_{stress}"] = _fits(curves, pairs, stress)
        result["groups"].append(entry)
    (out / "summary.json").write_text(json.dumps(result, indent=2, default=float))
    if all_curves:
        from softgrains.viz.ensemble import draw_ensemble

        draw_ensemble(all_curves, out)
    return result


def _fits(curves: GroupCurves, pairs: list, stress: str) -> dict[str, object]:
    """The two-regime fit of the mean φ/φ0 and the scatter of the members' breaks."""
    fit: dict[str, object] = {}
    finite = np.isfinite(curves.mean["phi_ratio"])
    try:
        mean_fit = fit_two_regimes(curves.levels[finite], curves.mean["phi_ratio"][finite])
        fit["mean"] = mean_fit.__dict__
    except ValueError as error:
        fit["mean"] = str(error)
    breaks = []
    for series, sigma0 in pairs:
        rows = loading_rows(series)
        if rows.size == 0:
            continue
        phi = series["phi"][rows] / series["phi"][rows[0]]
        try:
            breaks.append(fit_two_regimes(series[STRESSES[stress]][rows] / sigma0,
                                          phi).break_ratio)
        except ValueError:
            pass
    fit["member_breaks"] = breaks
    if len(breaks) > 1:
        fit["break_mean"], fit["break_std"] = float(np.mean(breaks)), float(
            np.std(breaks, ddof=1))
    return fit


def _write_csv(path: Path, curves: GroupCurves) -> None:
    columns = ["sigma_ratio", "members"] + [f"{name}_{part}" for name in OBSERVABLES
                                            for part in ("mean", "low", "high")]
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        for k, level in enumerate(curves.levels):
            writer.writerow([f"{level:.6g}", int(curves.count[k])]
                            + [f"{getattr(curves, part)[name][k]:.8g}"
                               for name in OBSERVABLES for part in ("mean", "low", "high")])

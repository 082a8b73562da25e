"""Figures of a sweep's ensemble statistics (issue #12): per stress measure, φ/φ0, φ and the
coordination number Z against σ/σ0, each group's mean with its 95% band, on one plot per
observable (e.g. one curve per friction, as in the reference paper's Fig. 3A)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

TITLES = {"phi_ratio": "φ/φ0", "phi": "φ", "coordination": "Z (grain–grain)"}
STRESS_LABELS = {"wall": "top wall σ_yy / σ0", "average": "volume-averaged σ_yy / σ0"}


def draw_ensemble(curves: list, out: Path) -> list[Path]:
    """One PNG per stress measure (ensemble_<stress>.png); returns the files written."""
    written = []
    for stress in sorted({c.stress for c in curves}):
        mine = [c for c in curves if c.stress == stress]
        fig, axes = plt.subplots(1, len(TITLES), figsize=(4.2 * len(TITLES), 3.8),
                                 constrained_layout=True)
        for ax, (name, title) in zip(axes, TITLES.items(), strict=True):
            for c in mine:
                n = int(c.count.max()) if c.count.size else 0
                line, = ax.plot(c.levels, c.mean[name], label=f"{c.label} (n = {n})")
                ax.fill_between(c.levels, c.low[name], c.high[name], alpha=0.25,
                                color=line.get_color(), linewidth=0)
            ax.set_xscale("log")
            ax.set_xlabel(STRESS_LABELS[stress])
            ax.set_ylabel(title)
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=8)
        fig.suptitle("ensemble mean, shaded: 95% confidence band of the mean "
                     "(Student t over the seeds)", fontsize=9)
        path = out / f"ensemble_{stress}.png"
        fig.savefig(path, dpi=130)
        plt.close(fig)
        written.append(path)
    return written

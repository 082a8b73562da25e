"""Figures drawn from a run's ``series.csv``: energies and Newton iterations over time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from softgrains.errors import CaseError
from softgrains.io.tables import read_table

_REQUIRED = ("step", "time", "dt", "newton_iterations", "kinetic_energy", "strain_energy")
_DPI = 150
_FIGSIZE = (5.0, 3.5)


def _new_axes(xlabel: str, ylabel: str) -> tuple[Figure, Axes]:
    """A figure with one axes, labelled and lightly gridded (no pyplot, no global state)."""
    figure = Figure(figsize=_FIGSIZE, layout="tight")
    axes = figure.add_subplot()
    axes.set_xlabel(xlabel)
    axes.set_ylabel(ylabel)
    axes.grid(True, linewidth=0.5, alpha=0.3)
    return figure, axes


def read_run_series(run_dir: Path, required: tuple[str, ...] | list[str],
                    what: str = "") -> dict[str, np.ndarray]:
    """``run_dir/series.csv`` as columns; CaseError when it is absent or lacks a column."""
    path = run_dir / "series.csv"
    if not path.is_file():
        raise CaseError(f"{run_dir}: no series.csv (is this a softgrains output folder?)")
    series = read_table(path)
    missing = [name for name in required if name not in series]
    if missing:
        raise CaseError(f"{path}: missing {what}columns {', '.join(missing)}")
    return series


def plot_run(run_dir: str | Path) -> list[Path]:
    """Draw ``figures/energy.png`` and ``figures/newton.png`` from ``run_dir/series.csv``.

    Works on a finished or a running run; returns the paths of the files written.
    """
    run_dir = Path(run_dir)
    series = read_run_series(run_dir, _REQUIRED)
    figures_dir = run_dir / "figures"
    figures_dir.mkdir(exist_ok=True)
    time = series["time"]

    energy, axes = _new_axes("time [s]", "energy [J/m]")
    kinetic, strain = series["kinetic_energy"], series["strain_energy"]
    axes.plot(time, kinetic, label="kinetic")
    axes.plot(time, strain, label="strain")
    total = kinetic + strain
    if "gravity_energy" in series and np.any(series["gravity_energy"] != 0.0):
        axes.plot(time, series["gravity_energy"], label="gravity (potential)")
        total = total + series["gravity_energy"]
    axes.plot(time, total, label="total", color="black", linestyle="--")
    axes.legend(frameon=False)

    newton, axes = _new_axes("time [s]", "Newton iterations per step")
    axes.plot(time, series["newton_iterations"], marker=".", linewidth=0.8)
    axes.yaxis.set_major_locator(MaxNLocator(integer=True))

    paths = [figures_dir / "energy.png", figures_dir / "newton.png"]
    for figure, path in zip((energy, newton), paths, strict=True):
        figure.savefig(path, dpi=_DPI)
    return paths

"""Figures of a run's outputs."""

from softgrains.viz.figures import draw_figures
from softgrains.viz.series import plot_run

__all__ = ["draw_figures", "plot_run"]

"""Figures of a run's outputs."""

from softgrains.viz.series import plot_run

__all__ = ["plot_run"]

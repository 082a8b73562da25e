"""Ensembles and parameter sweeps on Dask (issue #12)."""

from softgrains.sweep.runner import Outcome, run_sweep, table
from softgrains.sweep.spec import Member, Sweep, load_sweep

__all__ = ["Member", "Outcome", "Sweep", "load_sweep", "run_sweep", "table"]

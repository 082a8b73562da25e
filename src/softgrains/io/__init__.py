"""Output files of a run: CSV tables, VTK snapshots, JSON summary, log and progress bar."""

from softgrains.io.checkpoint import CHECKPOINT_NAME, read_checkpoint, write_checkpoint
from softgrains.io.runlog import Progress, close_run_log, open_run_log
from softgrains.io.summary import (
    peak_memory_mib,
    software_versions,
    write_bytes_atomic,
    write_json_atomic,
)
from softgrains.io.tables import CsvTable, read_table, truncate_after_step
from softgrains.io.vtk import PvdSeries, read_points_vtu, read_pvd, write_points_vtu

__all__ = [
    "CHECKPOINT_NAME",
    "CsvTable",
    "Progress",
    "PvdSeries",
    "close_run_log",
    "open_run_log",
    "read_points_vtu",
    "read_pvd",
    "read_checkpoint",
    "read_table",
    "peak_memory_mib",
    "software_versions",
    "truncate_after_step",
    "write_bytes_atomic",
    "write_checkpoint",
    "write_json_atomic",
    "write_points_vtu",
]

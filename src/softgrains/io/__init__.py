"""Output files of a run: CSV tables, VTK snapshots, JSON summary, log and progress bar."""

from softgrains.io.runlog import Progress, close_run_log, open_run_log
from softgrains.io.summary import software_versions, write_bytes_atomic, write_json_atomic
from softgrains.io.tables import CsvTable, read_table
from softgrains.io.vtk import PvdSeries, read_points_vtu, read_pvd, write_points_vtu

__all__ = [
    "CsvTable",
    "Progress",
    "PvdSeries",
    "close_run_log",
    "open_run_log",
    "read_points_vtu",
    "read_pvd",
    "read_table",
    "software_versions",
    "write_bytes_atomic",
    "write_json_atomic",
    "write_points_vtu",
]

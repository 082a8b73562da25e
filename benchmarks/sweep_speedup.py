"""Speed-up of a sweep on Dask (issue 12, item 6): the same members run one after another in
this process, then by `run_sweep` on a LocalCluster of 1 and of 2 workers (each member one
Numba thread), from empty output folders; prints a Markdown table of wall times, the
speed-up against one after another and Dask's overhead per member.

The default sweep: a small compaction (6 grains, D/h 5, to 30 σ0, as in
tests/protocol/test_compaction.py) × 4 seeds. Another sweep file can be given:

    python benchmarks/sweep_speedup.py [SWEEP.toml] [--workers 1 2]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import tomli_w

SMALL_COMPACTION = {
    "simulation": {"dt": 1e-4, "end_time": 0.2, "theta": 1.0, "threads": 1},
    "grid": {"cell_size": 2e-3},
    "materials": {"gel": {"young": 1e7, "poisson": 0.4, "density": 100.0}},
    "sample": {"count": 6, "mean_diameter": 0.01, "polydispersity": 0.2,
               "box_width": 0.02, "material": "gel"},
    "protocol": {"kind": "uniaxial-compaction", "sigma0": 5e3, "wall_speed": 0.5,
                 "precompaction_dt": 5e-4, "precompaction_speed": 0.5,
                 "stop_stress_ratio": 30.0},
    "output": {"interval": 1, "snapshot_interval": 0, "progress": False},
}


def default_sweep(folder: Path) -> Path:
    """The small compaction × 4 seeds, written into ``folder``."""
    (folder / "small.toml").write_bytes(tomli_w.dumps(SMALL_COMPACTION).encode())
    path = folder / "sweep.toml"
    path.write_text('base = "small.toml"\n[parameters]\n"simulation.seed" = {count = 4}\n')
    return path


def main() -> None:
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    from softgrains.sweep import load_sweep, run_sweep
    from softgrains.sweep.runner import run_member

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweep", nargs="?", type=Path)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sweep = load_sweep(args.sweep or default_sweep(tmp))
        n = len(sweep.members)
        # warm the JIT cache once so that no variant pays the compilation alone
        run_member(str(sweep.base), {**sweep.members[0].overrides, "simulation.end_time":
                                     1e-3}, str(tmp / "warm"), 1)
        start = time.perf_counter()
        for m in sweep.members:
            run_member(str(sweep.base), m.overrides, str(tmp / "serial" / m.name), 1)
        serial = time.perf_counter() - start
        rows = [("one after another (this process)", serial, 1.0, "—")]
        for workers in args.workers:
            start = time.perf_counter()
            outcomes = run_sweep(sweep, tmp / f"dask{workers}", workers=workers,
                                 echo=lambda line: None)
            wall = time.perf_counter() - start
            failed = [o.name for o in outcomes if o.code != 0]
            overhead = (wall * workers - serial) / n if workers == 1 else None
            rows.append((f"Dask LocalCluster, {workers} worker(s)" + (
                f" ({len(failed)} failed)" if failed else ""), wall, serial / wall,
                f"{overhead:.1f} s" if overhead is not None else "—"))
    print(f"sweep: {n} members ({sweep.path.name}), {os.cpu_count()} cores\n")
    print("| how | wall [s] | speed-up | Dask overhead per member |")
    print("| --- | --- | --- | --- |")
    for how, wall, speedup, overhead in rows:
        print(f"| {how} | {wall:.1f} | {speedup:.2f} | {overhead} |")


if __name__ == "__main__":
    main()

"""The ``softgrains`` command line: ``run``, ``check``, ``plot`` and ``info``.

Exit statuses: 0 success; 2 invalid case or arguments; 3 the simulation failed; 128 + the
signal number (130 SIGINT, 143 SIGTERM) when a run was interrupted (after a final checkpoint).
"""

from __future__ import annotations

import argparse
import os
import platform
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

from softgrains.batch import run_case
from softgrains.case import load_case, summarize
from softgrains.errors import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_INVALID,
    EXIT_OK,
    CaseError,
    SimulationError,
)
from softgrains.threads import PARALLEL_MIN_POINTS

if TYPE_CHECKING:
    from softgrains.viz.compaction import AnimationQueue


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # argparse exits on --help (0) and on bad arguments (2)
        return stop.code if isinstance(stop.code, int) else EXIT_INVALID
    command: Callable[[argparse.Namespace], int] = args.command
    try:
        return command(args)
    except CaseError as error:
        _error(str(error))
        return EXIT_INVALID
    except KeyboardInterrupt:
        _error("interrupted")
        return EXIT_INTERRUPTED


def _parser() -> argparse.ArgumentParser:
    """The argument parser, one subcommand per command."""
    parser = argparse.ArgumentParser(
        prog="softgrains", description="Implicit MPM simulator for assemblies of soft grains."
    )
    commands = parser.add_subparsers(title="commands", required=True, metavar="COMMAND")

    run = commands.add_parser(
        "run", help="run one case, or several in parallel processes (then compared)")
    run.add_argument("cases", type=Path, nargs="+", metavar="CASE.toml", help="case file(s)")
    run.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="output directory (default: results/<case file name without .toml>); with "
        "several cases, each runs into DIR/<case name> and the comparison figures go to "
        "DIR/figures (default DIR: results/comparison)",
    )
    run.add_argument("--jobs", type=int, default=0, metavar="N",
                     help="cases run at once (default: as many as cores, at most the cases)")
    run.add_argument("--no-figures", dest="figures", action="store_false",
                     help="do not draw the figures at the end")
    run.add_argument(
        "--resume",
        action="store_true",
        help="continue from DIR/checkpoint.h5 (the case may change e.g. dt or tolerances, "
        "not its bodies or grid)",
    )
    run.set_defaults(command=_run)

    check = commands.add_parser("check", help="validate and summarise a case, run nothing")
    check.add_argument("case", type=Path, metavar="CASE.toml", help="the case file")
    check.set_defaults(command=_check)

    for subparser in (run, check):
        subparser.add_argument(
            "--set",
            dest="overrides",
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="override a case key, e.g. --set simulation.dt=1e-4 (repeatable)",
        )

    plot = commands.add_parser(
        "plot", help="(re)draw the figures of a run, compare several compaction runs, or "
        "redraw a sweep's ensemble statistics")
    plot.add_argument("directories", type=Path, nargs="+", metavar="DIR",
                      help="run output directories")
    plot.add_argument("--out", type=Path, metavar="FIGDIR",
                      help="where the comparison figures go (default: DIR/figures for one "
                      "run, the first run's parent/figures for several)")
    plot.add_argument("--field", default="von_mises", metavar="NAME",
                      help="the field shading the grains in the snapshots and animations: "
                      "von_mises (default), pressure, J or any scalar point field of the "
                      "snapshots")
    plot.add_argument("--raw", action="store_true",
                      help="shade the raw point values instead of the field smoothed per "
                      "grain (least-squares fits on a grid of one cell, each grain's mean "
                      "kept)")
    plot.set_defaults(command=_plot)

    sweep = commands.add_parser(
        "sweep", help="run the members of a sweep file (parameters × seeds) on Dask")
    sweep.add_argument("sweep", type=Path, metavar="SWEEP.toml", help="the sweep file")
    sweep.add_argument("--out", type=Path, metavar="DIR",
                       help="output directory, one folder per member (default: "
                       "results/<sweep file name without .toml>)")
    sweep.add_argument("--workers", type=int, default=0, metavar="N",
                       help="worker processes of the local Dask cluster (default: as many as "
                       "cores, at most the members to run)")
    sweep.add_argument("--scheduler", metavar="ADDRESS",
                       help="an existing Dask scheduler (tcp://host:8786) instead of a local "
                       "cluster")
    sweep.add_argument("--threads", type=int, default=1, metavar="T",
                       help="Numba threads per member (default 1: one member per core)")
    sweep.set_defaults(command=_sweep)

    info = commands.add_parser("info", help="show versions, threads and devices")
    info.set_defaults(command=_info)
    return parser


def _run(args: argparse.Namespace) -> int:
    """``softgrains run``: load the case(s) (all validated first) and run them."""
    cases = [load_case(path, overrides=args.overrides) for path in args.cases]
    if len(cases) == 1:
        out = args.out if args.out is not None else Path("results") / args.cases[0].stem
        status = _run_one(cases[0], out, args.resume)
        if status == EXIT_OK and args.figures:
            _draw([out], None)
        return status
    root = args.out if args.out is not None else Path("results") / "comparison"
    stems = [path.stem for path in args.cases]
    if len(set(stems)) != len(stems):
        raise CaseError(f"several cases have the same file name ({stems}): each runs into "
                        "DIR/<file name>; rename them")
    outs = [root / stem for stem in stems]
    jobs = max(1, min(args.jobs or min(len(cases), os.cpu_count() or 1), len(cases)))
    with _worker_pool(jobs) as pool:
        animations = None
        if args.figures:  # each run's animation drawn as it ends, on the core it frees
            from softgrains.viz.compaction import AnimationQueue  # heavy: matplotlib

            animations = AnimationQueue(pool, root / "figures")
        try:
            statuses = _run_parallel(pool, jobs, args.cases, args.overrides, outs, args.resume,
                                     animations.start if animations is not None else None)
            done = [out for out, status in zip(outs, statuses, strict=True)
                    if status == EXIT_OK]
            if args.figures:
                # a failed run's rows up to its failure are valid: draw them too when they
                # can be
                written = [out for out in outs if (out / "series.csv").is_file()]
                try:
                    _draw(written, root / "figures", animations)
                except CaseError as error:
                    _error(f"figures with every run failed ({error}); drawing the finished "
                           "runs")
                    if done:
                        _draw(done, root / "figures", animations)
        finally:
            if animations is not None:
                animations.close()
    return max(statuses)


def _run_one(case, out: Path, resume: bool = False) -> int:
    from softgrains.simulation import Simulation  # heavy: numba kernels

    sim = Simulation(case, out=out)
    try:
        summary = sim.run(resume=resume)
    except SimulationError as error:
        _error(f"{error}\nsee {out / 'run.log'}")
        return EXIT_FAILED
    if summary["status"] == "interrupted":
        _error(f"{summary['message']}; continue with: softgrains run ... --out {out} --resume")
        return 128 + (sim.stop_signal or 2)
    if summary["status"] != "completed":  # completed with unconverged steps
        print(f"{summary['status']}: {summary['message']}")
    print(f"results in {out}")
    return EXIT_OK


@contextmanager
def _worker_pool(jobs: int) -> Iterator[ProcessPoolExecutor]:
    """``jobs`` worker processes (spawned: no threads or Numba state inherited); what is
    still queued when the block is left is cancelled."""
    import multiprocessing

    pool = ProcessPoolExecutor(max_workers=jobs,
                               mp_context=multiprocessing.get_context("spawn"))
    try:
        yield pool
    finally:
        pool.shutdown(cancel_futures=True)


def _run_parallel(pool: ProcessPoolExecutor, jobs: int, paths: list[Path],
                  overrides: list[str], outs: list[Path], resume: bool = False,
                  on_done: Callable[[Path], object] | None = None) -> list[int]:
    """Run the cases in ``pool``'s ``jobs`` processes, the cores shared among them (no progress
    bars: each run writes its run.log; one line per case here as it ends, and
    ``on_done(out)`` called for each that completed). Returns the exit statuses in the
    order of ``paths``."""
    threads = max(1, (os.cpu_count() or 1) // jobs)
    print(f"running {len(paths)} cases, {jobs} at once, {threads} "
          f"thread(s) each; logs in {', '.join(str(o / 'run.log') for o in outs)}")
    # SIGTERM sent to this process alone (kill, a batch system) is passed on to the
    # workers, which stop cleanly after their step; SIGINT from a terminal reaches them
    # all already (one process group)
    forwarding = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _forward_to_workers) if forwarding else None
    try:
        futures = {pool.submit(run_case, str(p), list(overrides), str(o), threads, resume): i
                   for i, (p, o) in enumerate(zip(paths, outs, strict=True))}
        statuses = [EXIT_FAILED] * len(paths)
        for future in as_completed(futures):
            i = futures[future]
            status, message = future.result()
            outcome = (("done" if not message else "done, with warnings")
                       if status == EXIT_OK else "interrupted" if status > 128
                       else "invalid case" if status == EXIT_INVALID else "FAILED")
            print(f"{paths[i]}: {outcome} -> {outs[i]}" + (f"\n  {message}" if message else ""),
                  flush=True)
            statuses[i] = status
            if status == EXIT_OK and on_done is not None:
                on_done(outs[i])
    finally:
        if forwarding:
            signal.signal(signal.SIGTERM, previous)
    return statuses


def _forward_to_workers(signum: int, frame) -> None:
    """Send ``signum`` on to this process's live children (the pool's workers)."""
    import multiprocessing

    for child in multiprocessing.active_children():
        os.kill(child.pid, signum)


def _sweep(args: argparse.Namespace) -> int:
    """``softgrains sweep``: validate the sweep and every member, run them on Dask, print
    the table of members; non-zero if any failed."""
    from softgrains.sweep import load_sweep, run_sweep, table

    sweep = load_sweep(args.sweep)
    out = args.out if args.out is not None else Path("results") / args.sweep.stem
    outcomes = run_sweep(sweep, out, workers=args.workers, scheduler=args.scheduler,
                         threads=args.threads)
    print(table(outcomes))
    failed = [o for o in outcomes if o.code != EXIT_OK]
    if failed:
        _error(f"{len(failed)} of {len(outcomes)} members did not complete (see their "
               f"run.log); re-run the same command to retry them")
    return max((o.code for o in outcomes), default=EXIT_OK)


def _draw(run_dirs: list[Path], out: Path | None, animations: AnimationQueue | None = None
          ) -> None:
    from softgrains.viz import draw_figures  # heavy: matplotlib

    written = draw_figures(run_dirs, out, animations=animations)
    folders = sorted({str(path.parent) for path in written})
    print(f"{len(written)} figures in {', '.join(folders)}")


def _check(args: argparse.Namespace) -> int:
    """``softgrains check``: validate the case and print its summary."""
    case = load_case(args.case, overrides=args.overrides)
    print(f"{args.case}: valid")
    print(summarize(case))
    return EXIT_OK


def _plot(args: argparse.Namespace) -> int:
    """``softgrains plot``: draw the figures of run directories and list them."""
    for directory in args.directories:
        if not directory.is_dir():
            raise CaseError(f"no such run directory: '{directory}'")
    from softgrains.viz import draw_figures  # heavy: matplotlib

    sweeps = [d for d in args.directories if (d / "sweep.json").is_file()]
    if sweeps:  # a sweep folder: its ensemble statistics and figures
        from softgrains.sweep.ensemble import ensemble_statistics

        for directory in sweeps:
            ensemble_statistics(directory)
            for path in sorted((directory / "ensemble").glob("*")):
                print(path)
        if len(sweeps) == len(args.directories):
            return EXIT_OK
        args.directories = [d for d in args.directories if d not in sweeps]
    out = args.out
    if out is None and len(args.directories) > 1:
        out = args.directories[0].parent / "figures"
    from softgrains.viz.compaction import FieldChoice

    for path in draw_figures(args.directories, out, FieldChoice(args.field, not args.raw)):
        print(path)
    return EXIT_OK


def _info(args: argparse.Namespace) -> int:
    """``softgrains info``: versions of softgrains and its dependencies, threads, devices."""
    import numba

    lines = [f"softgrains {_version('softgrains')}"]
    lines.append(f"python {platform.python_version()} ({sys.executable})")
    lines += [f"{name} {_version(name)}" for name in ("numpy", "scipy", "numba", "pydantic")]
    lines.append(f"numba threading layer: {_threading_layer()}, threads: {numba.get_num_threads()}"
                 f", OpenMP wait policy: {os.environ.get('OMP_WAIT_POLICY', 'default')} (kernels"
                 f" over fewer than {PARALLEL_MIN_POINTS} points on one thread)")
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    lines.append(f"CPUs: {os.cpu_count()} ({usable} usable by this process)")
    lines.append(f"GPU: {_gpu()}")
    print("\n".join(lines))
    return EXIT_OK


def _version(distribution: str) -> str:
    """The installed version of ``distribution``, or "not installed"."""
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return "not installed"


def _threading_layer() -> str:
    """Numba's threading layer, known only once a parallel function has run: run a tiny one."""
    import numba

    @numba.njit(parallel=True)
    def total(n: int) -> int:
        result = 0
        for i in numba.prange(n):
            result += i
        return result

    total(2)
    return numba.threading_layer()


def _gpu() -> str:
    """The CUDA device numba sees, or "none detected"."""
    from numba import cuda

    if not cuda.is_available():
        return "none detected"
    name = cuda.get_current_device().name
    return name.decode() if isinstance(name, bytes) else str(name)


def _error(message: str) -> None:
    """Print ``softgrains: error: message`` to stderr."""
    print(f"softgrains: error: {message}", file=sys.stderr)

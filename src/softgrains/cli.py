"""The ``softgrains`` command line: ``run``, ``check``, ``plot`` and ``info``.

Exit statuses: 0 success; 2 invalid case or arguments; 3 the simulation failed.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path

from softgrains.case import load_case, summarize
from softgrains.errors import CaseError, SimulationError

EXIT_OK = 0
EXIT_INVALID = 2
EXIT_FAILED = 3
EXIT_INTERRUPTED = 130


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

    run = commands.add_parser("run", help="run a case")
    run.add_argument("case", type=Path, metavar="CASE.toml", help="the case file")
    run.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="output directory (default: results/<case file name without .toml>)",
    )
    run.add_argument(
        "--resume",
        action="store_true",
        help="continue from DIR/checkpoint.h5 (not implemented yet)",
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

    plot = commands.add_parser("plot", help="(re)draw the figures of a run")
    plot.add_argument("directory", type=Path, metavar="DIR", help="the run's output directory")
    plot.set_defaults(command=_plot)

    info = commands.add_parser("info", help="show versions, threads and devices")
    info.set_defaults(command=_info)
    return parser


def _run(args: argparse.Namespace) -> int:
    """``softgrains run``: load the case and run it into the output directory."""
    if args.resume:
        _error("resume is not implemented yet")
        return EXIT_INVALID
    case = load_case(args.case, overrides=args.overrides)
    out = args.out if args.out is not None else Path("results") / args.case.stem
    from softgrains.simulation import Simulation  # heavy: numba kernels

    try:
        Simulation(case, out=out).run()
    except SimulationError as error:
        _error(f"{error}\nsee {out / 'run.log'}")
        return EXIT_FAILED
    print(f"results in {out}")
    return EXIT_OK


def _check(args: argparse.Namespace) -> int:
    """``softgrains check``: validate the case and print its summary."""
    case = load_case(args.case, overrides=args.overrides)
    print(f"{args.case}: valid")
    print(summarize(case))
    return EXIT_OK


def _plot(args: argparse.Namespace) -> int:
    """``softgrains plot``: draw the figures of a run directory and list them."""
    if not args.directory.is_dir():
        raise CaseError(f"no such run directory: '{args.directory}'")
    from softgrains.viz.series import plot_run  # heavy: matplotlib

    for path in plot_run(args.directory):
        print(path)
    return EXIT_OK


def _info(args: argparse.Namespace) -> int:
    """``softgrains info``: versions of softgrains and its dependencies, threads, devices."""
    import numba

    lines = [f"softgrains {_version('softgrains')}"]
    lines.append(f"python {platform.python_version()} ({sys.executable})")
    lines += [f"{name} {_version(name)}" for name in ("numpy", "scipy", "numba", "pydantic")]
    lines.append(f"numba threading layer: {_threading_layer()}, threads: {numba.get_num_threads()}")
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

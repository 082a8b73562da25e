"""One case run to an exit status in a worker process: the cases of `softgrains run A B`
(cli.py) and the members of a sweep (sweep/runner.py)."""

from __future__ import annotations

import os
from contextlib import ExitStack, redirect_stderr, redirect_stdout
from pathlib import Path

from softgrains.errors import EXIT_FAILED, EXIT_INVALID, EXIT_OK, CaseError, SimulationError


def run_case(path: str, overrides, out: str, threads: int, resume: bool = False,
             quiet: bool = False) -> tuple[int, str]:
    """Load ``path`` with ``overrides`` (no progress bar), run it into ``out`` with
    ``threads`` Numba threads (unless the case sets its own), and return (exit status,
    message): 0, 2 (invalid case), 3 (failed) or 128 + the signal that stopped it.
    ``quiet``: the run's log goes to its run.log only, not to this process's console."""
    import numba

    from softgrains.case import load_case
    from softgrains.simulation import Simulation

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    try:
        case = load_case(path, overrides)
        case.output.progress = False
        if case.simulation.threads == 0:
            case.simulation.threads = threads
        sim = Simulation(case, out=Path(out))
        with ExitStack() as stack:
            if quiet:
                sink = stack.enter_context(open(os.devnull, "w"))
                stack.enter_context(redirect_stdout(sink))
                stack.enter_context(redirect_stderr(sink))
            summary = sim.run(resume=resume)
    except SimulationError as error:
        return EXIT_FAILED, str(error)
    except CaseError as error:
        return EXIT_INVALID, str(error)
    if summary["status"] == "interrupted":
        return 128 + (sim.stop_signal or 2), str(summary["message"])
    return EXIT_OK, str(summary.get("message", ""))

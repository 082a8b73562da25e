"""Trace the coupling loop of a few steps of a run: every contact solve (contacts, the
tolerance it was asked for, solver iterations, residual reached, seconds) and the loop's
stall measure m after it (coupling.Progress: m ≤ 1 is converged), then per step its
seconds, coupling iterations and working-set growths (issue 14, session 33).

Replayed contact problems (contact_solve_replay.py) time a solver on fixed problems; a
change of solver also changes which solution within the tolerance each solve returns,
and with it the loop's iterates. Session 33: a solver stage that made the 1000-grain
front's 11 replayed problems 2.1× faster made the same steps 2× slower (coupling
iterations 11 / 8 / 9 / 17 → 14 / 19 / 28 / 14). Judge solver changes on whole steps;
this trace shows where a step's iterations go.

The run folder's checkpoint is resumed (its stop criterion lifted), ``--steps`` steps are
taken. Run:  python benchmarks/coupling_loop_trace.py RUN_DIR [--steps 2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from contact_problems_from_run import resumed_without_stop

import softgrains.contact.coupling as coupling


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="run folder with checkpoint.h5, case.toml")
    parser.add_argument("--steps", type=int, default=2)
    args = parser.parse_args()
    sim = resumed_without_stop(args.run)
    solve, stalled = coupling.solve, coupling.Progress.stalled

    def traced_solve(problem, P0, options):
        start = time.perf_counter()
        result = solve(problem, P0, options)
        print(f"  solve: {problem.n_contacts:6d} contacts, tolerance {options.tolerance:.2g}, "
              f"{result.iterations:4d} iterations, residual {result.residual:.2g}"
              f"{'' if result.converged else ' (not converged)'}, "
              f"{time.perf_counter() - start:.2f} s", flush=True)
        return result

    def traced_stalled(progress, measure, *rest, **keywords):
        print(f"  loop measure {measure:.3g}", flush=True)
        return stalled(progress, measure, *rest, **keywords)

    coupling.solve, coupling.Progress.stalled = traced_solve, traced_stalled
    try:
        for _ in range(args.steps):
            start = time.perf_counter()
            diag = sim.step()
            print(f"step {sim.state.step}: {time.perf_counter() - start:.1f} s, "
                  f"{diag.contact.iterations} coupling iterations, "
                  f"{diag.contact.working_set_growths} working-set growths, "
                  f"converged {diag.contact.converged}", flush=True)
    finally:
        coupling.solve, coupling.Progress.stalled = solve, stalled


if __name__ == "__main__":
    main()

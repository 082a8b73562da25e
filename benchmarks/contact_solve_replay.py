"""Replay saved contact problems (ContactProblem.save, .npz; e.g. tests/contact/data/ or
the problems a run saves for its unconverged steps) through the default solver and print,
per problem: contacts, seconds (best of --repeat), Newton iterations, residual, and how the
Newton matrices were solved (newton_matrix.NewtonMatrix: factorizations against row
updates of a kept factorization). Compare code versions by running it from each checkout
on the same files, one after the other, 1 thread (issue 11, session 27).

Problems saved with their warm start and solver options, every solve of a few steps of a
run: benchmarks/contact_problems_from_run.py (issue 14, session 31).

``--no-retry`` turns off the second try of a stalled solve on the contacts' deformation
scale (solvers.solve, session 49) to compare with it on the same problems; the last line
gives the totals: Newton iterations and the solves left above their tolerance (stalled).

Run:  python benchmarks/contact_solve_replay.py FILE.npz ... [--tolerance 1e-6] [--repeat 3]
                                                [--no-retry]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from softgrains.contact import solvers
from softgrains.contact.problem import ContactProblem
from softgrains.contact.solvers import ContactSolverOptions, solve


def replay(path: Path, tolerance: float | None, repeat: int) -> str:
    """One table row: the best time of ``repeat`` solves from the saved warm start (or 0),
    with the saved solver options (benchmarks/contact_problems_from_run.py) or the
    defaults; ``tolerance`` replaces the options' where given."""
    with np.load(path) as data:
        start = data["warm_start"] if "warm_start" in data else None
        saved = {f.name: data[f"option_{f.name}"].item() for f in fields(ContactSolverOptions)
                 if f"option_{f.name}" in data}
    options = ContactSolverOptions(**saved)
    if tolerance is not None:
        options = replace(options, tolerance=tolerance)
    best = np.inf
    for _ in range(repeat):
        problem = ContactProblem.load(path)  # a fresh problem: nothing cached
        began = time.perf_counter()
        result = solve(problem, start, options)
        best = min(best, time.perf_counter() - began)
    matrices = [v for k, v in problem._cache.items() if isinstance(k, tuple)]
    factorizations = sum(getattr(m, "factorizations", 0) for m in matrices)
    updates = sum(getattr(m, "updates", 0) for m in matrices)
    row = (f"| {path.name} | {problem.n_contacts} | {best:.3f} | {result.iterations} | "
           f"{result.residual:.1e} | {factorizations} | {updates} |")
    return row, result.iterations, result.residual > options.tolerance


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", type=Path, nargs="+")
    parser.add_argument("--tolerance", type=float, default=None,
                        help="instead of the saved options' (default 1e-6 without them)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-retry", action="store_true",
                        help="no second try of a stalled solve on the deformation scale")
    args = parser.parse_args()
    if args.no_retry:
        solvers._rigid_dominated = lambda problem: False
    print("| problem | contacts | s (best) | iterations | residual | factorizations | "
          "row updates |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    iterations = stalled = 0
    for path in args.files:
        row, its, failed = replay(path, args.tolerance, args.repeat)
        iterations, stalled = iterations + its, stalled + failed
        print(row, flush=True)
    print(f"{len(args.files)} problems: {iterations} Newton iterations, {stalled} stalled")


if __name__ == "__main__":
    main()

"""The interior point's cost against the size of a contact problem (issue 11, session 51):
per saved problem (ContactProblem.save, .npz; e.g. from benchmarks/contact_problems_from_run.py),
its contacts, W's nonzeros (interior_point.delassus_nonzeros, what solvers'
INTERIOR_POINT_NONZEROS limits), the interior point's iterations to the tolerance, its
residual, and the time an iteration (best of --repeat). Frictionless problems are solved as
they are; a frictional one (2D) as the Tresca problem of the friction bound μ P_n of its
saved warm start (or of a tenth of its impulse scale where it has none), the first
problem of the Tresca fixed point (3D frictional files are skipped: the interior point
solves Tresca problems in 2D only). The time an iteration includes the set-up (W in the
contacts' frames, assembled once a problem), as in a solve. Judge whether the interior
point pays on a larger problem (the 1000-grain front, #14 item 2) before raising the
limit.

Run:  python benchmarks/interior_point_cost.py FILE.npz ... [--tolerance 1e-7] [--repeat 2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from softgrains.contact.interior_point import delassus_nonzeros, interior_point
from softgrains.contact.problem import ContactProblem, impulse_scale


def bound_of(problem: ContactProblem, path: Path) -> np.ndarray | None:
    """None for a frictionless problem, else μ P_n of the warm start (or of a tenth of the
    impulse scale)."""
    if not np.any(problem.mu > 0.0):
        return None
    with np.load(path) as data:
        start = data["warm_start"] if "warm_start" in data else None
    if start is None or not np.any(start):
        return problem.mu * 0.1 * impulse_scale(problem)
    return problem.mu * np.maximum(np.einsum("ci,ci->c", start, problem.normal), 0.0)


def row(path: Path, tolerance: float, repeat: int) -> str:
    problem = ContactProblem.load(path)
    if np.any(problem.mu > 0.0) and problem.dim != 2:
        return f"| {path.name} | (3D, frictional: skipped) | {problem.n_contacts} | | | | |"
    best, result = np.inf, None
    for _ in range(repeat):
        problem = ContactProblem.load(path)  # nothing cached
        bound = bound_of(problem, path)
        began = time.perf_counter()
        result = interior_point(problem, tolerance, bound=bound)
        best = min(best, time.perf_counter() - began)
    law = "frictionless" if bound is None else "Tresca"
    per_iteration = best / max(result.iterations, 1)
    return (f"| {path.name} | {law} | {problem.n_contacts} | {delassus_nonzeros(problem)} | "
            f"{result.iterations} | {result.residual:.1e} | {1e3 * per_iteration:.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", type=Path, nargs="+")
    parser.add_argument("--tolerance", type=float, default=1e-7)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    print("| problem | law | contacts | W nonzeros | iterations | residual | ms / iteration "
          "(set-up included) |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for path in args.files:
        print(row(path, args.tolerance, args.repeat), flush=True)


if __name__ == "__main__":
    main()

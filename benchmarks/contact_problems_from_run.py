"""Save every contact problem of a few steps of a run, with its warm start and solver
options, for benchmarks/contact_solve_replay.py (issue 14, session 31: the dense states of
the 30- and 100-grain compactions, where the first solve of a step takes 44–62 Newton
iterations and the cost of one grows faster than the contacts).

The run folder's checkpoint is resumed (its stop criterion lifted) and ``--steps`` steps
are taken; each solve of the coupling loop is written to OUT/problem_<k>.npz
(ContactProblem.save with the arrays warm_start and option_<name>).
Run:  python benchmarks/contact_problems_from_run.py RUN_DIR OUT_DIR [--steps 3]
"""

from __future__ import annotations

import argparse
from dataclasses import fields
from pathlib import Path

import numpy as np

import softgrains.contact.coupling as coupling
from softgrains.case import load_case
from softgrains.simulation import Simulation


def resumed_without_stop(run: Path) -> Simulation:
    """The run folder's simulation resumed from its checkpoint, its protocol's stop
    criteria lifted (so that the steps taken from there are not cut short)."""
    case = load_case(run / "case.toml")
    if case.protocol is not None:
        case = case.model_copy(update={"protocol": case.protocol.model_copy(
            update={"stop_stress_ratio": None, "stop_packing_fraction": None})})
    sim = Simulation(case)
    sim.resume(run / "checkpoint.h5")
    return sim


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--steps", type=int, default=3)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    sim = resumed_without_stop(args.run)
    solve, saved = coupling.solve, []

    def saving(problem, P0, options):
        path = args.out / f"problem_{len(saved):04d}.npz"
        problem.save(path, warm_start=np.asarray(P0, float),
                     **{f"option_{f.name}": np.asarray(getattr(options, f.name))
                        for f in fields(options)})
        saved.append(path)
        return solve(problem, P0, options)

    coupling.solve = saving
    try:
        for _ in range(args.steps):
            sim.step()
    finally:
        coupling.solve = solve
    first = sim.state.step - args.steps
    print(f"{len(saved)} contact problems of {args.steps} steps from step {first} in {args.out}")


if __name__ == "__main__":
    main()

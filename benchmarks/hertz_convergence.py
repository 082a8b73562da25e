"""Validation table (VALIDATION.md B8): Hertz half-width against D/h and the seeding.

Runs examples/hertz.toml (a linear-elastic disk squeezed between two kinematic walls) at
D/h = 25, 50, 100 with the disk seeded on the lattice and on rings, and prints, over the steps
where 0.004 ≤ P/(E* R) ≤ 0.012 at either wall, the mean and largest |a/a_Hertz − 1|, with
a = 2√(Σ f_I x_I²/Σ f_I) from the contact forces, and the wall time.
Run:  python benchmarks/hertz_convergence.py [--dh 25 50 100]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from softgrains.case import load_case
from softgrains.observe.contacts import contact_patch, contact_records
from softgrains.simulation import Simulation

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "hertz.toml"
WINDOW = (0.004, 0.012)


def errors(d_over_h: int, seeding: str) -> tuple[np.ndarray, int, float]:
    case = load_case(EXAMPLE, {"grid.cell_size": 1.0 / d_over_h, "bodies.0.seeding": seeding})
    disk = case.bodies[0]
    mat = case.materials[disk.material]
    e_star = mat.young / (1.0 - mat.poisson**2)
    radius = disk.radius
    sim = Simulation(case)
    found = []
    t0 = time.perf_counter()
    for _ in range(sim.n_steps):
        sim.step()
        records = contact_records(sim.model, sim.last_diagnostics.contacts, sim.last_dt)
        for wall in (1, 2):
            load, _, a = contact_patch(records, wall)
            ratio = load / (e_star * radius)
            if WINDOW[0] <= ratio <= WINDOW[1]:
                found.append(a / (2.0 * np.sqrt(load * radius / (np.pi * e_star))) - 1.0)
    return np.array(found), sim.model.n_points, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dh", type=int, nargs="+", default=[25, 50, 100])
    args = parser.parse_args()
    print("| D/h | seeding | points | samples | mean abs error | max abs error | wall time [s] |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for d_over_h in args.dh:
        for seeding in ("lattice", "rings"):
            err, points, wall = errors(d_over_h, seeding)
            print(f"| {d_over_h} | {seeding} | {points} | {len(err)} | "
                  f"{np.abs(err).mean():.1%} | {np.abs(err).max():.1%} | {wall:.1f} |",
                  flush=True)


if __name__ == "__main__":
    main()

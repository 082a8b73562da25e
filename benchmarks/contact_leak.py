"""Grain–grain penetration in two small cases (issue 11, item 2), quick enough to compare
contact treatments in seconds before a compaction run:

1. two disks stacked under gravity in a channel (tests/contact/test_relations.py): the
   boundary gap between them along the vertical through their centres (points ± δ/2, and
   ± the deformed cell's half-extent ½δ‖Fᵀe_y‖₁), every 10 steps, in cells h;
2. a disk launched at 0.5 m/s along a frictionless deformable block: its position, speed
   and how far it has sunk into the block, every 20 steps (it must keep sliding), and the
   energy the contacts took out so far (≥ 0: a frictionless contact must not inject any).

Session 8 measured with it that the nodal constraint leaks (docs/dev-notes.md, #11):

    python benchmarks/contact_leak.py --shape bspline2 --dh 10 --seeding lattice \\
        --set contact.keep_closed=true [--set contact.normal=...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "contact"))

from test_relations import _disk_sliding_on_block, _two_disks_stacked  # noqa: E402

from softgrains import Simulation  # noqa: E402
from softgrains.case import load_case  # noqa: E402


def _with(sim, shape: str, overrides: list[str], end_time: float | None = None):
    data = sim.case.model_dump()
    case = load_case(data, [f"grid.shape_function={shape}", *overrides]
                     + ([f"simulation.end_time={end_time}"] if end_time else []))
    return Simulation(case)


def stacked(shape: str, dh: int, seeding: str, overrides: list[str]) -> None:
    h = 0.4 / dh
    delta = h / 2
    sim = _with(_two_disks_stacked(h, seeding), shape, overrides, end_time=1.5)
    lower, upper = (sim.model.bodies[i].points for i in (0, 1))
    row = []
    for k in range(sim.n_steps):
        sim.step()
        if (k + 1) % 10:
            continue
        x, F = sim.state.x, sim.state.F
        ends = []
        for points, side in ((lower, 1.0), (upper, -1.0)):
            column = np.abs(x[points, 0] - 0.5) <= 0.75 * delta
            y = x[points][column, 1]
            extent = 0.5 * delta * np.abs(F[points][column][:, 1, :]).sum(axis=1)
            ends.append(((y + side * 0.5 * delta), (y + side * extent)))
        plain = (ends[1][0].min() - ends[0][0].max()) / h
        deformed = (ends[1][1].min() - ends[0][1].max()) / h
        row.append(f"{sim.state.time:.1f} s {plain:+.3f} ({deformed:+.3f})")
    print(f"stacked disks, {shape}, D/h {dh}, {seeding}: boundary gap [h] (deformed "
          "cells):\n  " + "\n  ".join(row))


def sliding(shape: str, overrides: list[str]) -> None:
    sim = _with(_disk_sliding_on_block(False), shape, overrides)
    disk, block = (sim.model.bodies[i].points for i in (0, 1))
    h = sim.model.lattice.h
    delta = h / 2
    row = []
    dissipated = 0.0
    for k in range(sim.n_steps):
        diag = sim.step()
        dissipated += diag.contact.dissipation
        if (k + 1) % 20:
            continue
        x, v = sim.state.x, sim.state.v
        centre = x[disk, 0].mean()
        near = np.abs(x[disk, 0] - centre) <= 1.5 * delta
        under = np.abs(x[block, 0] - centre) <= 1.5 * delta
        sink = (x[block][under, 1].max() + delta / 2 - (x[disk][near, 1].min() - delta / 2)) / h
        row.append(f"x {centre:.3f} m v {v[disk, 0].mean():.3f} m/s sink {sink:+.3f} h, "
                   f"contact dissipation {dissipated:+.3g} J")
    print(f"disk sliding on a block, {shape}:\n  " + "\n  ".join(row))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", default="bspline2", choices=["linear", "bspline2"])
    parser.add_argument("--dh", type=int, default=10)
    parser.add_argument("--seeding", default="lattice", choices=["lattice", "rings"])
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="case overrides for both cases")
    args = parser.parse_args()
    stacked(args.shape, args.dh, args.seeding, args.overrides)
    sliding(args.shape, args.overrides)


if __name__ == "__main__":
    main()

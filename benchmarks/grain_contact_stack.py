"""Grain–grain contact under sustained load (issue 11): two equal neo-Hookean disks stacked
between two plates squeezed quasi-statically to 30% of the stack's height.

Disks R = 0.25 m (E = 10 MPa, ν = 0.4, ρ = 1000, plane strain), Coulomb μ everywhere
(frictionless, the stack buckles sideways), plates closing 0.1 h a step each at
Δt c/h = ``--dtch``, θ = 1, PIC. Prints every tenth of the run: the contact's own least gap
at the active grain–grain contacts and at the plates (cells; gap.py's estimate), where the
worst grain–grain one is (x from the axis, cells), the largest tilt |n_x| of the
grain–grain normals (the interface is flat: 0 ideally), coupling iterations, and the area
where the two disks' cells overlap (observe/coverage.py raster, cells²).

    python benchmarks/grain_contact_stack.py [--shape bspline2] [--dh 20] [--dtch 3000]
                                             [--friction 0.5] [--normal difference]
                                             [--sites surface]

Session 11 (2026-12-02, `--sites surface` / `nodes`, μ = 0.5, first steps): point-to-surface
grain contacts hold the disks within 0.005 h at Δt c/h 10–300 but fail at 3000 (impulses
at contacts 0.5 h open, the load lost, a disk leaves the grid: the run stops, printed);
nodal contacts carry the load at 3000 with the disks 0.45–0.83 h into each other.
"""

from __future__ import annotations

import argparse

import numpy as np
from squeeze_convergence import NU, RHO, E, wave_speed

from softgrains import Simulation, load_case
from softgrains.contact.detection import node_position
from softgrains.errors import SimulationError
from softgrains.observe.coverage import coverage

R = 0.25


def stack_case(shape: str, d_over_h: int, dt_c_over_h: float, friction: float,
               normal: str, sites: str = "surface") -> dict:
    h = 2 * R / d_over_h
    dt = dt_c_over_h * h / wave_speed()
    speed = 0.1 * h / dt
    size = 4 * R + 8 * h
    c = size / 2
    plate = {"shape": "rectangle", "material": "gel", "kind": "kinematic"}
    disk = {"shape": "disk", "radius": R, "material": "gel", "seeding": "rings"}
    return {
        "simulation": {"dt": dt, "steps": int(0.3 * 4 * R / (0.2 * h)), "flip": 0.0},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [size, size],
                 "shape_function": shape},
        "materials": {"gel": {"law": "neo-hookean", "young": E, "poisson": NU,
                              "density": RHO}},
        "bodies": [
            {**disk, "name": "low", "center": [c, c - R]},
            {**disk, "name": "high", "center": [c, c + R]},
            {**plate, "name": "bottom", "lower": [h, c - 2 * R - 3 * h],
             "upper": [size - h, c - 2 * R], "velocity": [0.0, speed]},
            {**plate, "name": "top", "lower": [h, c + 2 * R],
             "upper": [size - h, c + 2 * R + 3 * h], "velocity": [0.0, -speed]},
        ],
        "contact": {"friction": friction, "normal": normal, "grain_sites": sites},
        "output": {"progress": False},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", default="bspline2")
    parser.add_argument("--dh", type=int, default=20)
    parser.add_argument("--dtch", type=float, default=3000.0)
    parser.add_argument("--friction", type=float, default=0.5)
    parser.add_argument("--normal", default="difference")
    parser.add_argument("--sites", default="surface", choices=["surface", "nodes"],
                        help="contact.grain_sites")
    args = parser.parse_args()
    sim = Simulation(load_case(stack_case(args.shape, args.dh, args.dtch, args.friction,
                                          args.normal, args.sites)))
    m, h = sim.model, sim.model.lattice.h
    disks = np.r_[m.bodies[0].points.start:m.bodies[1].points.stop]
    lower = np.asarray(sim.case.grid.origin, float)
    upper = np.asarray(sim.case.grid.upper, float)
    axis = 0.5 * (lower[0] + upper[0])
    print("| step | grain–grain least gap [h] | worst at x [h] | plates least gap [h] | "
          "max normal tilt | its | overlap [h²] |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    every = max(1, sim.n_steps // 10)
    for k in range(sim.n_steps):
        try:
            diag = sim.step()
        except SimulationError as error:  # the stack lost its load: say so and stop
            print(f"stopped at step {k}: {error}")
            return
        if k % every and k != sim.n_steps - 1:
            continue
        c = diag.contacts
        active = np.any(c.impulse != 0.0, axis=1)
        between = active & (c.nodes.alpha == 0) & (c.nodes.beta == 1)
        plates = active & ~between
        s = sim.state
        _, overlap = coverage(s.x[disks], s.F[disks], m.reference_cells[disks], m.body_id[disks],
                              lower, upper)
        area = overlap * float(np.prod(upper - lower))
        if between.any():
            worst = np.argmin(c.gap[between])
            x = (node_position(m.lattice, c.nodes.node[between][worst:worst + 1])[0, 0]
                 if c.nodes.position is None else c.nodes.position[between][worst, 0])
            row = (f"{c.gap[between].min() / h:.3f} | {(x - axis) / h:.1f} | ",
                   f"{np.abs(c.nodes.normal[between, 0]).max():.3f}")
        else:
            row = ("– | – | ", "–")
        print(f"| {k} | {row[0]}"
              f"{c.gap[plates].min() / h if plates.any() else float('nan'):.3f} | {row[1]} | "
              f"{diag.contact.iterations} | {area / h**2:.2f} |")


if __name__ == "__main__":
    main()

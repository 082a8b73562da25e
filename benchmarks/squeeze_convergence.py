"""VALIDATION.md D10: a neo-Hookean disk squeezed between two frictionless kinematic plates to
30% of its diameter, against the finite-element reference of squeeze_reference.py.

Disk R = 0.5 m, E = 10 MPa, ν = 0.4, ρ = 1000 kg/m³ (plane strain, ring seeding, n_pc = 2),
plates 3 cells thick closing symmetrically by ``travel`` cells each per step, θ = 1, PIC,
default contact settings. The plate force per unit thickness F (the top plate's reaction) is
compared with the reference F/(E R) at the same total travel δ/D. Prints, per D/h and Δt c/h:
the steps (with those the step-size controller retried shorter, and the least Δt c/h it
took), the largest relative error of F over 5–30% of D, the errors at 10/20/30%, coupling
iterations per step (mean/max), contact solver iterations, the least boundary gap at the
active contacts (the contact law's own estimate, gap.py: a step's start-of-step gap is the
previous step's end-of-step gap; −: an overlap), the largest penetration of the disk's points
past a plate face at the end of each step (± their deformed round half cell, the cell the
contact holds; and the corners of their reference squares), all in cells, and the wall time.

    python benchmarks/squeeze_convergence.py [--dh 20 40 80] [--dtch 3000 40] [--travel 0.1]
                                             [--set contact.overlap_removal=1] [--log]
"""

from __future__ import annotations

import argparse
import csv
import time
import tomllib
from pathlib import Path

import numpy as np

from softgrains import Simulation, load_case

E, NU, RHO, R = 10e6, 0.4, 1000.0, 0.5
REFERENCE = Path(__file__).parent / "data" / "squeeze_reference_nu0.4.csv"


def wave_speed() -> float:
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    return float(np.sqrt((lam + 2 * mu) / RHO))


def squeeze_case(d_over_h: int, dt_c_over_h: float, travel: float, strain: float = 0.30,
                 overrides: dict | None = None) -> dict:
    """The case: plates each move ``travel`` cells a step until the total travel is
    ``strain`` D."""
    h = 2 * R / d_over_h
    dt = dt_c_over_h * h / wave_speed()
    speed = travel * h / dt
    steps = int(np.ceil(strain * 2 * R / (2 * travel * h) - 1e-9))
    size = 2.6 * R + 8 * h  # room for the disk widening under the plates (~1.2 D at 30%)
    c = size / 2
    plate = {"shape": "rectangle", "material": "gel", "kind": "kinematic"}
    case = {
        # end_time, not a step count: a step the controller retries shorter keeps the travel
        "simulation": {"dt": dt, "end_time": steps * dt, "flip": 0.0},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [size, size]},
        "materials": {"gel": {"law": "neo-hookean", "young": E, "poisson": NU,
                              "density": RHO}},
        "bodies": [
            {"name": "disk", "shape": "disk", "center": [c, c], "radius": R,
             "material": "gel", "seeding": "rings"},
            {**plate, "name": "bottom", "lower": [h, c - R - 3 * h], "upper": [size - h, c - R],
             "velocity": [0.0, speed]},
            {**plate, "name": "top", "lower": [h, c + R], "upper": [size - h, c + R + 3 * h],
             "velocity": [0.0, -speed]},
        ],
        "output": {"progress": False},
    }
    for key, value in (overrides or {}).items():
        section, name = key.split(".")
        case.setdefault(section, {})[name] = value
    return case


def penetration(sim: Simulation, h: float, corners: bool = False) -> float:
    """Largest distance, in cells, by which a disk point's deformed cell passes a plate's
    inner face (negative: a gap), at the state's positions: the round cell's edge along
    the plate's normal n = e_y, ½δ‖Fᵀn‖ — the cell the contact holds (surfaces.py) — or,
    with ``corners``, the corners of the point's reference square, ½δ Σ_j |F_yj| (farther
    where the cells shear under the plates: ~0.1 h at 30% squeeze at any Δt)."""
    m, s = sim.model, sim.state
    disk = m.bodies[0].points
    half = 0.5 * h / m.points_per_cell
    F = s.F[disk]
    extent = half * (np.abs(F[:, 1, 0]) + np.abs(F[:, 1, 1]) if corners
                     else np.hypot(F[:, 1, 0], F[:, 1, 1]))
    bottom = m.bodies[1].shape.upper[1] + s.body_offset[1][1]
    top = m.bodies[2].shape.lower[1] + s.body_offset[2][1]
    y = s.x[disk, 1]
    return float(max((y + extent).max() - top, bottom - (y - extent).min()) / h)


def run(d_over_h: int, dt_c_over_h: float, travel: float, overrides: dict | None = None,
        log: bool = False) -> dict:
    sim = Simulation(load_case(squeeze_case(d_over_h, dt_c_over_h, travel, overrides=overrides)))
    h = 2 * R / d_over_h
    t0 = time.perf_counter()
    strain, force, its, solver_its, pen, corner_pen, gap = [], [], [], [], [], [], []
    while not sim.at_end:
        diag = sim.step()
        offset = sim.state.body_offset
        strain.append((offset[1][1] - offset[2][1]) / (2 * R))
        force.append(diag.contact_forces(3, 2, sim.last_dt)[2, 1] / (E * R))
        its.append(diag.contact.iterations)
        solver_its.append(diag.contact.sweeps)
        pen.append(penetration(sim, h))
        corner_pen.append(penetration(sim, h, corners=True))
        active = np.any(diag.contacts.impulse != 0.0, axis=1)
        gap.append(float(diag.contacts.gap[active].min()) / h if active.any() else np.inf)
        if log:  # one line a step, for long runs (D/h 80)
            print(f"D/h {d_over_h} dt c/h {dt_c_over_h:g} step {len(its)}/{sim.n_steps}: "
                  f"squeeze {strain[-1]:.4f}, F/(E R) {force[-1]:.5g}, coupling its {its[-1]}, "
                  f"solver its {solver_its[-1]}, least gap {gap[-1]:.3f} h, "
                  f"{time.perf_counter() - t0:.0f} s", flush=True)
    wall = time.perf_counter() - t0
    with REFERENCE.open() as f:
        rows = list(csv.DictReader(f))
    ref_x = np.array([float(r["delta_over_D"]) for r in rows])
    ref_f = np.array([float(r["force_per_thickness_over_ER"]) for r in rows])
    strain, force = np.array(strain), np.array(force)
    error = force / np.interp(strain, ref_x, ref_f) - 1.0
    window = (strain >= 0.05 - 1e-9) & (strain <= 0.30 + 1e-9)
    at = {p: float(np.interp(p, strain, error)) for p in (0.1, 0.2, 0.3)}
    return {"D/h": d_over_h, "dt c/h": dt_c_over_h, "points": sim.model.n_points,
            "steps": len(its), "retried": sim.retried_steps,
            "least dt c/h": dt_c_over_h * sim.smallest_dt_factor,
            "max |error| 5-30%": float(np.abs(error[window]).max()),
            "error 10%": at[0.1], "error 20%": at[0.2], "error 30%": at[0.3],
            "its/step": f"{np.mean(its):.1f} / {max(its)}",
            "solver its/step": f"{np.mean(solver_its):.1f}",
            "least gap at active contacts [h]": min(gap), "penetration [h]": max(pen),
            "penetration, cell corners [h]": max(corner_pen),
            "wall [s]": wall}


def print_table(rows: list[dict], digits: int = 4) -> None:
    """The rows (same keys) as a Markdown table, floats to ``digits`` significant digits."""
    keys = list(rows[0])
    print("| " + " | ".join(keys) + " |")
    print("| " + " | ".join("---" for _ in keys) + " |")
    for r in rows:
        print("| " + " | ".join(f"{v:.{digits}g}" if isinstance(v, float) else str(v)
                                for v in r.values()) + " |")


def _value(text: str) -> object:
    """A --set value as TOML reads it (1 an integer, 1.0 a float, true a boolean), else the
    text (e.g. bspline2), as ``softgrains run --set`` reads it."""
    try:
        parsed = tomllib.loads(f"value = {text}")
    except (tomllib.TOMLDecodeError, RecursionError):
        return text
    return parsed["value"] if len(parsed) == 1 else text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dh", type=int, nargs="+", default=[20, 40])
    parser.add_argument("--dtch", type=float, nargs="+", default=[3000.0, 40.0])
    parser.add_argument("--travel", type=float, default=0.1,
                        help="plate travel per step, cells (each plate)")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE",
                        help="case overrides, e.g. contact.overlap_removal=1")
    parser.add_argument("--log", action="store_true", help="print a line per step")
    args = parser.parse_args()
    overrides = {k: _value(v) for k, v in (item.split("=", 1) for item in args.set)}
    results = [run(dh, dtch, args.travel, overrides, args.log)
               for dtch in args.dtch for dh in args.dh]
    print_table(results)


if __name__ == "__main__":
    main()

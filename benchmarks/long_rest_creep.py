"""Issue 11, item 2: resting and squeezed bodies must not creep into each other or into
walls over thousands of steps.

Three set-ups, default contact settings, θ = 1, each run for ``--steps`` steps:

- ``disk on slab``: a disk (R = 0.2 m, E = 0.1 MPa, ν = 0.3, ρ = 1000 kg/m³, c ≈ 10 m/s,
  ring seeding) released 0.005 m above a kinematic slab under gravity (10 m/s²), Δt = 10 ms
  (Δt c/h = 5 at D/h 20);
- ``two disks``: two such disks stacked in a channel of kinematic walls (as
  tests/contact/test_relations.py), frictionless and with μ = 0.5;
- ``squeezed, held``: the D10 disk (squeeze_convergence.py: R = 0.5 m, E = 10 MPa, ν = 0.4)
  squeezed quasi-statically (Δt c/h 3000, 0.1 h a step per plate) to 10% of D, then held
  with the plates at rest; frictionless and with μ = 0.5.

Per run it prints the least boundary gap at the loaded contacts over the rest and at
10 / 25 / 50 / 100% of it (series.csv's ``least_contact_gap``, the contact law's own
estimate, in cells h; < 0: an overlap); the bodies' separation at the same marks, from
its value at 10% (the disk's centre over the slab; the upper disk's centre over the
lower's; the extent of the disk's points between the plates, which grows as the disk sinks
into them where the others shrink); and the creep, the slope of a line fitted to the
separation over the second half of the rest (settled), in h per 1000 steps; with the steps
the step-size controller retried and the time a step.

    python benchmarks/long_rest_creep.py [--steps 3000] [--dh 20] [--only "two disks"]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from squeeze_convergence import squeeze_case

from softgrains import Simulation, load_case

GEL = {"young": 1e5, "poisson": 0.3, "density": 1000.0}
WALL = {"shape": "rectangle", "material": "gel", "kind": "kinematic"}


def disk_on_slab(dh: float, friction: float) -> dict:
    h = 0.4 / dh
    return {
        "simulation": {"dt": 0.01, "end_time": 1.0, "theta": 1.0},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [1.0, 1.0]},
        "materials": {"gel": GEL},
        "bodies": [{"name": "disk", "shape": "disk", "center": [0.5, 0.705], "radius": 0.2,
                    "material": "gel", "seeding": "rings"},
                   {**WALL, "name": "slab", "lower": [0.1, 0.3], "upper": [0.9, 0.5]}],
        "gravity": {"acceleration": [0.0, -10.0]},
        "contact": {"friction": friction},
        "output": {"progress": False},
    }


def two_disks(dh: float, friction: float) -> dict:
    h = 0.4 / dh
    disk = {"shape": "disk", "radius": 0.2, "material": "gel", "seeding": "rings"}
    return {
        "simulation": {"dt": 0.01, "end_time": 1.0, "theta": 1.0},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [1.0, 1.6]},
        "materials": {"gel": GEL},
        "bodies": [{**disk, "name": "lower", "center": [0.5, 0.705]},
                   {**disk, "name": "upper", "center": [0.5, 1.11]},
                   {**WALL, "name": "slab", "lower": [0.1, 0.3], "upper": [0.9, 0.5]},
                   {**WALL, "name": "left", "lower": [0.1, 0.5], "upper": [0.298, 1.5]},
                   {**WALL, "name": "right", "lower": [0.702, 0.5], "upper": [0.9, 1.5]}],
        "gravity": {"acceleration": [0.0, -10.0]},
        "contact": {"friction": friction},
        "output": {"progress": False},
    }


def squeezed(dh: float, friction: float) -> dict:
    return squeeze_case(dh, 3000.0, 0.1, strain=0.10, overrides={"contact.friction": friction})


def _centre(sim, body: int) -> np.ndarray:
    points = sim.model.bodies[body].points
    m = sim.model.mass[points]
    return (m[:, None] * sim.state.x[points]).sum(axis=0) / m.sum()


def _separation(name: str, sim) -> float:
    """The distance whose drift is creep (m)."""
    if name == "disk on slab":
        return float(_centre(sim, 0)[1] - 0.5)
    if name == "two disks":
        return float(_centre(sim, 1)[1] - _centre(sim, 0)[1])
    points = sim.model.bodies[0].points  # squeezed: the disk's height between the plates
    y = sim.state.x[points, 1]
    return float(y.max() - y.min())


def run(name: str, build, dh: float, friction: float, steps: int) -> dict:
    case = build(dh, friction)
    h = case["grid"]["cell_size"]
    dt = case["simulation"]["dt"]
    squeeze_time = case["simulation"]["end_time"] if name == "squeezed, held" else 0.0
    case["simulation"]["end_time"] = squeeze_time + steps * dt
    sim = Simulation(load_case(case))
    gaps, separations = [], []
    start = time.perf_counter()
    while sim.state.time < squeeze_time - 1e-9 * dt:  # the squeeze (shorter steps if retried)
        sim.step()
    sim.state.body_velocity[1:] = 0.0  # the plates stop and hold
    for _ in range(steps):
        sim.step()
        gaps.append(sim.series_row()["least_contact_gap"] / h)
        separations.append(_separation(name, sim))
    seconds = (time.perf_counter() - start) / sim.state.step
    gaps, separations = np.array(gaps), np.array(separations)
    marks = np.array([steps // 10, steps // 4, steps // 2, steps]) - 1
    rest = separations[marks[2]:]  # the second half of the rest: settled
    slope = np.polyfit(np.arange(rest.size), rest / h, 1)[0]
    return {"case": name, "mu": friction, "steps": sim.state.step,
            "retried": sim.retried_steps,
            "least gap": np.nanmin(gaps),
            "gap at 10/25/50/100%": "/".join(f"{g:+.4f}" for g in gaps[marks]),
            "separation at 10/25/50/100%": "/".join(
                f"{(x - separations[marks[0]]) / h:+.4f}" for x in separations[marks]),
            "creep per 1000": 1000.0 * slope, "s/step": seconds}


CASES = {"disk on slab": disk_on_slab, "two disks": two_disks, "squeezed, held": squeezed}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="steps at rest (≥ 20)")
    parser.add_argument("--dh", type=float, default=20.0, help="D/h of the disks")
    parser.add_argument("--only", action="append", choices=sorted(CASES), default=None)
    args = parser.parse_args()
    if args.steps < 20:
        parser.error("--steps: at least 20 (the marks are at 10 / 25 / 50 / 100% of the rest)")
    rows = []
    for name in args.only or CASES:
        for friction in (0.0, 0.5):
            if name == "disk on slab" and friction:
                continue
            rows.append(run(name, CASES[name], args.dh, friction, args.steps))
            r = rows[-1]
            print(f"{r['case']}, μ {r['mu']}: {r['steps']} steps, least gap "
                  f"{r['least gap']:+.4f} h, separation {r['separation at 10/25/50/100%']} h, "
                  f"creep {r['creep per 1000']:+.5f} h per 1000 steps", flush=True)
    keys = ["case", "mu", "steps", "retried", "least gap", "gap at 10/25/50/100%",
            "separation at 10/25/50/100%", "creep per 1000", "s/step"]
    print("\n| " + " | ".join(keys) + " |")
    print("|" + " --- |" * len(keys))
    for r in rows:
        print("| " + " | ".join(f"{r[k]:.4g}" if isinstance(r[k], float) else str(r[k])
                                for k in keys) + " |")
    print(f"(D/h {args.dh:g}; gaps and separations in cells h, the separations from their "
          "value at 10% of the rest; creep: the slope of a line fitted to the separation "
          "over the rest's second half)")


if __name__ == "__main__":
    main()

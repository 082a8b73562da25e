"""Benchmark: 30 neo-Hookean disks squeezed in a box by a wall at 5 m/s (issue 3, item 8;
issue 4, item 8).

The sample of examples/compaction_frictionless.toml (E = 10 MPa, ν = 0.4, d = 1 cm) is
pre-compacted under σ0 once, then compacted by the top wall at 5 m/s (no ramp) for a fixed
number of steps from that same state at each time step Δt and each local relation.
Prints time per step, coupling iterations and Gauss–Seidel sweeps per step, contacts,
material-point updates per second, and the time the wall would take to move by one mean
diameter (d/v/Δt steps at the measured cost).
Run:  python benchmarks/bench_compaction.py [--dh 10] [--steps 10]
"""

from __future__ import annotations

import argparse
import copy
import itertools
import platform
import resource
import time
from pathlib import Path

import numba

from softgrains.case import load_case
from softgrains.errors import SimulationError
from softgrains.simulation import Simulation

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "compaction_frictionless.toml"
D, SPEED = 0.01, 5.0


def example(d_over_h: float, density: float, dt: float | None = None,
            relation: str = "delassus") -> Simulation:
    overrides = {"grid.cell_size": D / d_over_h, "materials.gel.density": density,
                 "protocol.wall_speed_ramp": 0.0, "protocol.stop_stress_ratio": 1e9,
                 "contact.on_failure": "warn", "contact.local_relation": relation,
                 "output.progress": False}
    if dt is not None:
        overrides["simulation.dt"] = dt
    return Simulation(load_case(EXAMPLE, overrides))


def precompacted(d_over_h: float, density: float) -> Simulation:
    """The example's sample brought to equilibrium under σ0 (its pre-compaction)."""
    sim = example(d_over_h, density)
    while sim.protocol.phase == "precompaction":
        sim.step()
    return sim


def measure(start: Simulation, dt: float, relation: str, steps: int, d_over_h: float,
            density: float) -> dict:
    """``steps`` compaction steps from a copy of ``start``'s state at dt and relation."""
    sim = example(d_over_h, density, dt, relation)
    sim.state = copy.deepcopy(start.state)
    sim.protocol.phase = "compaction"
    sim.protocol.h0, sim.protocol.phi0 = start.protocol.h0, start.protocol.phi0
    sim.step()  # warm-up
    iterations = sweeps = contacts = unconverged = 0
    t0 = time.perf_counter()
    try:
        for _ in range(steps):
            dg = sim.step()
            iterations += dg.contact.iterations
            sweeps += dg.contact.sweeps
            contacts += dg.contact.active
            unconverged += not dg.contact.converged
    except SimulationError as err:
        return {"failed": str(err).split(";")[0]}
    per_step = (time.perf_counter() - t0) / steps
    return {"ms/step": 1e3 * per_step, "its/step": iterations / steps,
            "sweeps/step": sweeps / steps, "contacts": contacts / steps,
            "Mpts/s": sim.model.n_points / per_step / 1e6, "points": sim.model.n_points,
            "unconverged": unconverged, "time for d [s]": D / SPEED / dt * per_step}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dh", type=float, default=10.0, help="D/h (default 10)")
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--density", type=float, default=100.0)
    parser.add_argument("--dt", type=float, nargs="+", default=[1e-7, 1e-6, 1e-5])
    args = parser.parse_args()
    print(f"# {platform.machine()}, {numba.get_num_threads()} Numba threads, D/h = {args.dh}, "
          f"density {args.density} kg/m³, {args.steps} steps after one warm-up step")
    print("| Δt [µs] | relation | points | ms/step | coupling its/step | sweeps/step | "
          "active contacts | Mpts/s | wall time to move d [s] | unconverged steps |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    start = precompacted(args.dh, args.density)
    print(f"# pre-compacted: σ_yy = {start.protocol._sigma:.4g} Pa, "
          f"φ0 = {start.protocol.phi0:.4f}")
    for dt, relation in itertools.product(args.dt, ("delassus", "lumped")):
        r = measure(start, dt, relation, args.steps, args.dh, args.density)
        if "failed" in r:
            print(f"| {dt * 1e6:g} | {relation} | | failed: {r['failed']} | | | | | | |")
            continue
        print(f"| {dt * 1e6:g} | {relation} | {r['points']} | {r['ms/step']:.0f} | "
              f"{r['its/step']:.1f} | {r['sweeps/step']:.0f} | {r['contacts']:.0f} | "
              f"{r['Mpts/s']:.3f} | {r['time for d [s]']:.0f} | {r['unconverged']} |",
              flush=True)
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()

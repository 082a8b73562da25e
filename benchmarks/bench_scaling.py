"""Benchmark: cost per compaction step against the number of grains (issue 4, item 8).

The sample of examples/compaction_frictionless.toml (D/h = 10 by default) with 30, 100 and
300 grains in a box whose width grows as √N (5 d for 30 grains: the same aspect ratio). From
the seeded deposit the top wall comes down at 5 m/s (Δt = 40 µs, the example's compaction
step; no pre-compaction: its cost depends on how long the servo takes, not on the step),
``--warm`` steps bring it onto the pile, then ``--steps`` steps are timed.
Prints points, contact nodes, active contacts, ms per step, coupling iterations and Newton
iterations per step, material-point updates per second and peak memory.
Run:  python benchmarks/bench_scaling.py [--grains 30 100 300] [--dh 10]
"""

from __future__ import annotations

import argparse
import math
import platform
import resource
import time
from pathlib import Path

import numba

from softgrains.case import load_case
from softgrains.simulation import Simulation

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "compaction_frictionless.toml"
D = 0.01


def sample(count: int, d_over_h: float) -> Simulation:
    overrides = {"grid.cell_size": D / d_over_h, "sample.count": count,
                 "sample.box_width": 5 * D * math.sqrt(count / 30),
                 "protocol.wall_speed_ramp": 0.0, "protocol.stop_stress_ratio": 1e9,
                 "output.progress": False}
    sim = Simulation(load_case(EXAMPLE, overrides))
    protocol = sim.protocol
    protocol.phase = "compaction"  # straight from the deposit, at the compaction step
    protocol.h0, protocol.phi0 = 1.0, 1.0  # unused here (they scale the plotted ratios)
    return sim


def measure(count: int, d_over_h: float, warm: int, steps: int) -> dict:
    sim = sample(count, d_over_h)
    for _ in range(warm):
        sim.step()
    totals = {"contact nodes": 0, "active": 0, "coupling its": 0, "newton its": 0}
    t0 = time.perf_counter()
    for _ in range(steps):
        dg = sim.step()
        totals["contact nodes"] += dg.contact.n_contacts
        totals["active"] += dg.contact.active
        totals["coupling its"] += dg.contact.iterations
        totals["newton its"] += dg.newton_iterations
    per_step = (time.perf_counter() - t0) / steps
    return {"points": sim.model.n_points, "ms/step": 1e3 * per_step,
            "Mpts/s": sim.model.n_points / per_step / 1e6,
            **{k: v / steps for k, v in totals.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grains", type=int, nargs="+", default=[30, 100, 300])
    parser.add_argument("--dh", type=float, default=10.0)
    parser.add_argument("--warm", type=int, default=20)
    parser.add_argument("--steps", type=int, default=5)
    args = parser.parse_args()
    dt = load_case(EXAMPLE).simulation.dt
    print(f"# {platform.machine()}, {numba.get_num_threads()} Numba threads, D/h = {args.dh}, "
          f"Δt = {dt * 1e6:g} µs, {args.warm} steps onto the pile, then {args.steps} timed")
    print("| grains | points | contact nodes | active contacts | ms/step | coupling its/step "
          "| Newton its/step | Mpts/s | ms/step per 1000 points |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for count in args.grains:
        r = measure(count, args.dh, args.warm, args.steps)
        print(f"| {count} | {r['points']} | {r['contact nodes']:.0f} | {r['active']:.0f} | "
              f"{r['ms/step']:.0f} | {r['coupling its']:.1f} | {r['newton its']:.1f} | "
              f"{r['Mpts/s']:.3f} | {r['ms/step'] / r['points'] * 1e3:.2f} |", flush=True)
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()

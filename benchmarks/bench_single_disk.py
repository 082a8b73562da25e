"""Benchmark: one neo-Hookean disk stepped by the implicit solver (issue 2, item 9).

Disk of diameter D = 1 mm at D/h = 20, 40, 80 (n_pc = 2: about 1.2k, 5k, 20k points),
E = 10 MPa, ν = 0.4, ρ = 1000 kg/m³, set in motion by a uniform velocity gradient (shear and
breathing, ~0.5 m/s at the rim), stepped at Δt = 0.1 µs and 10 µs with each linear solver.
Prints time per step, Newton iterations per step, material-point updates per second, peak
memory (max RSS of the process) and threads. Run:  python benchmarks/bench_single_disk.py
"""

from __future__ import annotations

import argparse
import itertools
import platform
import resource
import time

import numba

from softgrains.case import load_case
from softgrains.errors import SimulationError
from softgrains.simulation import Simulation

D = 1.0e-3


def disk_case(d_over_h: int, dt: float, solver: str, steps: int, mass: str = "lumped") -> dict:
    h = D / d_over_h
    return {
        "simulation": {"dt": dt, "steps": steps, "linear_solver": solver, "mass_matrix": mass},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [2 * D, 2 * D]},
        "materials": {"gel": {"law": "neo-hookean", "young": 1.0e7, "poisson": 0.4,
                              "density": 1000.0}},
        "bodies": [{"shape": "disk", "center": [D, D], "radius": D / 2, "material": "gel",
                    "velocity_gradient": [[-500.0, 300.0], [0.0, 500.0]]}],
        "output": {"progress": False},
    }


def measure(d_over_h: int, dt: float, solver: str, mass: str, steps: int,
            warmup: int = 3) -> dict:
    sim = Simulation(load_case(disk_case(d_over_h, dt, solver, steps + warmup, mass)))
    for _ in range(warmup):
        sim.step()
    iters = 0
    methods = set()
    t0 = time.perf_counter()
    for _ in range(steps):
        diag = sim.step()
        iters += diag.newton_iterations
        methods.add(diag.linear_method)
    wall = time.perf_counter() - t0
    n = sim.model.n_points
    return {"D/h": d_over_h, "dt": dt, "solver": solver, "mass": mass,
            "used": ",".join(sorted(methods)),
            "points": n, "ms/step": 1e3 * wall / steps, "newton/step": iters / steps,
            "Mpts/s": n * steps / wall / 1e6}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[20, 40, 80])
    ap.add_argument("--dts", type=float, nargs="+", default=[1e-7, 1e-5])
    ap.add_argument("--solvers", nargs="+", default=["auto", "cg", "direct"])
    ap.add_argument("--masses", nargs="+", default=["consistent", "lumped"])
    ap.add_argument("--steps", type=int, default=20)
    args = ap.parse_args()
    print(f"# {platform.processor() or platform.machine()}, {numba.get_num_threads()} threads, "
          f"numba {numba.__version__}, {time.strftime('%Y-%m-%d')}")
    head = (f"{'D/h':>4} {'dt [s]':>8} {'mass':>10} {'solver':>7} {'used':>10} {'points':>7} "
            f"{'ms/step':>9} {'newton':>7} {'Mpts/s':>7}")
    print(head)
    print("-" * len(head))
    for n, dt, mass, solver in itertools.product(args.sizes, args.dts, args.masses,
                                                 args.solvers):
        try:
            r = measure(n, dt, solver, mass, args.steps)
        except SimulationError as err:
            print(f"{n:>4} {dt:>8.1e} {mass:>10} {solver:>7}  failed: {err}", flush=True)
            continue
        print(f"{r['D/h']:>4} {r['dt']:>8.1e} {mass:>10} {r['solver']:>7} {r['used']:>10} "
              f"{r['points']:>7} {r['ms/step']:>9.2f} {r['newton/step']:>7.2f} "
              f"{r['Mpts/s']:>7.3f}", flush=True)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory (max RSS): {rss:.0f} MiB")


if __name__ == "__main__":
    main()

"""Benchmark: time per step with 1 and 2 threads on an idle machine and beside one competing
process per core (issue 14, item 5; softgrains/threads.py).

Two thread set-ups are compared, each in a fresh process:
- ``now``: softgrains' defaults (OMP_WAIT_POLICY=PASSIVE set at import, kernels over fewer
  than PARALLEL_MIN_POINTS points on one thread, the coupling loop's bodies shared among
  the threads);
- ``before``: libgomp's default wait policy (spin, then sleep), every kernel on all
  threads and the bodies one after the other, as before session 30.
Cases: the bar example (one body of 100 points), one neo-Hookean disk at D/h 40 (5k points,
where threads pay) and the frictional compaction's first steps (30 grains of ~300 points).
Run:  python benchmarks/threads_busy.py [--steps-scale 1.0]
Never beside another benchmark: the competing processes are part of the measurement.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = {  # name: (what, steps timed)
    "bar (100 points)": ("examples/bar_vibration.toml", 100),
    "disk D/h 40 (5k points)": ("disk", 10),
    "compaction, 30 grains": ("examples/compaction_frictional.toml", 8),
}


def child(case: str, steps: int, setup: str) -> None:
    """Time ``steps`` steps after two untimed ones; print JSON."""
    import softgrains.threads

    if setup == "before":
        import softgrains.contact.coupling

        del os.environ["OMP_WAIT_POLICY"]  # before libgomp is loaded by a first kernel
        softgrains.threads.PARALLEL_MIN_POINTS = 0
        softgrains.contact.coupling.over_bodies = lambda function, items: [
            function(x) for x in items]
    import numba

    from softgrains.case import load_case
    from softgrains.simulation import Simulation

    if case == "disk":
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from bench_single_disk import disk_case

        loaded = load_case(disk_case(40, 1e-7, "direct", steps + 2))
    else:
        loaded = load_case(ROOT / case, {"output.progress": False})
    sim = Simulation(loaded)
    for _ in range(2):
        sim.step()
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    seconds = (time.perf_counter() - t0) / steps
    print(json.dumps({"s_per_step": seconds, "threads": numba.get_num_threads(),
                      "layer": numba.threading_layer()}))


def measure(case: str, steps: int, setup: str, threads: int) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
    env.pop("OMP_WAIT_POLICY", None)
    out = subprocess.run([sys.executable, __file__, "--child", case, str(steps), setup],
                         env=env, capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def competing_processes(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps-scale", type=float, default=1.0)
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], int(args.child[1]), args.child[2])
        return
    cores = os.cpu_count() or 1
    print(f"{cores} cores; 'busy': one competing process per core\n")
    print(f"{'case':26s} {'machine':7s} {'set-up':7s} {'1 thread':>11s} {'2 threads':>11s} "
          f"{'1 / 2':>6s}")
    for name, (case, steps) in CASES.items():
        steps = max(2, round(steps * args.steps_scale))
        for busy in (False, True):
            burners = competing_processes(cores) if busy else []
            try:
                for setup in ("before", "now"):
                    t = [measure(case, steps, setup, n)["s_per_step"] for n in (1, 2)]
                    print(f"{name:26s} {'busy' if busy else 'idle':7s} {setup:7s} "
                          f"{1e3 * t[0]:8.1f} ms {1e3 * t[1]:8.1f} ms {t[0] / t[1]:6.2f}",
                          flush=True)
            finally:
                for p in burners:
                    p.kill()


if __name__ == "__main__":
    main()

"""Issue #13: what drawing a snapshot costs for 30 and 1000 grains.

A synthetic frame: N ring-seeded disks of D/h = 10 (two points per cell, ~310 points a
disk, the reference compaction's resolution) on a square lattice, each slightly squashed
(F = diag(1.1, 1/1.1)), between a bottom and a top wall of lattice points, with a random
stress per point and one pair force per touching neighbour. Timed, one thread, each
stage once after a warm-up on a small frame (Numba compilation and imports excluded):

    smooth:  observe/stress.project_per_grain of the stress tensors (what a snapshot adds),
    mesh:    viz/grains.grain_mesh (outlines and triangulations of every grain),
    draw:    draw_grains + draw_walls and savefig at 150 dpi (PNG),
    chains:  the force-chain panel (pair forces, segments, outlines) and savefig.

    python benchmarks/figure_timing.py [--grains 30 1000]
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from softgrains.geometry import Disk, seed_disk_rings
from softgrains.observe.chains import body_centres, pair_forces
from softgrains.observe.stress import project_per_grain, von_mises
from softgrains.viz.chains import ChainPanel, chains_figure
from softgrains.viz.grains import GrainPoints, draw_grains, draw_walls, grain_mesh

RADIUS, H = 0.005, 0.001  # D/h = 10


def frame(count: int, seed: int = 0):
    """(points, volumes, stresses, pair forces) of ``count`` disks on a square lattice."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count)))
    F = np.diag([1.1, 1.0 / 1.1])
    disk, vol = seed_disk_rings(Disk(np.zeros(2), RADIUS), H / 2)
    xs, vols, bodies, centres = [], [], [], []
    for k in range(count):
        centre = 2.2 * RADIUS * np.array([k % side + 0.5, k // side + 0.5])
        xs.append(centre + disk @ F.T)
        vols.append(vol)
        bodies.append(np.full(len(disk), k))
        centres.append(centre)
    width = 2.2 * RADIUS * side
    wall_x = np.arange(H / 4, width, H / 2)
    for index, y in enumerate((-H / 4, 2.2 * RADIUS * side + H / 4)):
        xs.append(np.column_stack([wall_x, np.full_like(wall_x, y)]))
        vols.append(np.full(len(wall_x), (H / 2) ** 2))
        bodies.append(np.full(len(wall_x), count + index))
    x, volume, body = np.concatenate(xs), np.concatenate(vols), np.concatenate(bodies)
    grains = body < count
    Fs = np.where(grains[:, None, None], F, np.eye(2))
    points = GrainPoints(x, Fs, np.sqrt(volume / np.linalg.det(Fs)), body,
                         frozenset({count, count + 1}))
    stress = rng.normal(size=(len(x), 3, 3)) * 1e5
    # one contact node per horizontal and vertical lattice neighbour
    alpha, beta, where = [], [], []
    for k in range(count):
        for other in (k + 1, k + side):
            if other < count and (other != k + 1 or (k + 1) % side):
                alpha.append(k)
                beta.append(other)
                where.append(0.5 * (centres[k] + centres[other]))
    fn = rng.exponential(1e3, len(alpha))
    pairs = pair_forces(np.array(alpha), np.array(beta), fn, np.ones(len(alpha), int),
                        np.array(where).reshape(-1, 2))
    return points, volume, stress, pairs


def timed(function, *args):
    start = time.perf_counter()
    result = function(*args)
    return result, time.perf_counter() - start


def measure(count: int) -> dict:
    points, volume, stress, pairs = frame(count)
    smoothed, t_smooth = timed(project_per_grain, points.positions, volume, stress,
                               points.body, H / 2)
    field = von_mises(smoothed)
    mesh, t_mesh = timed(grain_mesh, points)

    def draw():
        figure = Figure(figsize=(6, 6), layout="constrained")
        ax = figure.add_subplot()
        draw_grains(ax, mesh, field, Normalize(0.0, float(np.percentile(field, 99))))
        draw_walls(ax, points)
        ax.set_aspect("equal")
        ax.autoscale_view()
        figure.savefig("/dev/null", format="png", dpi=150)

    _, t_draw = timed(draw)
    centres = body_centres(points.positions, volume, points.body)
    low, high = points.positions.min(axis=0), points.positions.max(axis=0)
    panel = ChainPanel(points, mesh.outlines, pairs, centres, "")

    def chains():
        chains_figure([panel], (low, high)).savefig("/dev/null", format="png", dpi=150)

    _, t_chains = timed(chains)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1e3  # kB on Linux
    return {"grains": count, "points": len(points.positions), "smooth [s]": t_smooth,
            "mesh [s]": t_mesh, "mesh per grain [ms]": 1e3 * t_mesh / count,
            "draw+save [s]": t_draw, "chains [s]": t_chains, "process peak RSS [MB]": peak / 1e6}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grains", type=int, nargs="+", default=[30, 1000])
    args = parser.parse_args()
    measure(4)  # warm-up: imports, Numba's compiled raster
    rows = [measure(count) for count in args.grains]
    print(" | ".join(rows[0]))
    for row in rows:
        print(" | ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in row.values()))


if __name__ == "__main__":
    main()

"""Issue #13, item 2: how noisy is the point stress, and does the smoothed field fix it?

A neo-Hookean disk (VALIDATION D10: R = 0.5 m, E = 10 MPa, ν = 0.4, rings seeding) is
squeezed quasi-statically between frictionless plates (squeeze_convergence.py's case, Δt c/h
3000) to ``--strain`` of D. At the end, the von Mises stress of each material point is
compared with the finite-element solution of squeeze_reference.py (scikit-fem, P2,
benchmark-only) at the point's reference position (quarter model folded by symmetry,
interpolated linearly between its quadrature points):

    raw:       σ_vm at the points,
    smoothed:  σ_vm of the stress projected per grain (observe/stress.project_per_grain on the
               grid spacing h: what the figures and the snapshots' von_mises_smoothed show).

Printed per D/h and shape function, relative to the mean FE von Mises stress ⟨σ_FE⟩: the
point-to-point scatter RMS(raw − smoothed), the errors RMS(raw − FE) and RMS(smoothed − FE)
over all points and over the points more than one cell inside the disk's boundary, and the
relative change of the disk's mean stress tensor by the smoothing (round-off by
construction of the projection's shift).

    python benchmarks/stress_scatter.py [--dh 20 40] [--shape linear bspline2] [--strain 0.2]
                                        [--cells 1 0.5]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

sys.path.insert(0, str(Path(__file__).parent))
from squeeze_convergence import NU, E, R, squeeze_case  # noqa: E402
from squeeze_reference import squeeze  # noqa: E402

from softgrains import Simulation, load_case  # noqa: E402
from softgrains.observe.stress import project_per_grain, von_mises  # noqa: E402


def fe_von_mises(strain: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature points (q, 2), relative to the centre, of the quarter disk of radius R,
    and the FE von Mises stress there at total plate travel ``strain`` D."""
    result = squeeze(NU, young=E, radius=R, n_refine=4, steps=steps, delta_max_over_d=strain)
    X, vm = result.cauchy_von_mises(NU, E)
    return X.T, vm


def mpm_state(d_over_h: int, shape: str, strain: float) -> dict:
    """Reference positions (relative to the disk's centre), volumes, stresses of the disk's
    points after the squeeze, and the grid spacing."""
    case = squeeze_case(d_over_h, 3000.0, 0.1, strain=strain,
                        overrides={"grid.shape_function": shape})
    sim = Simulation(load_case(case))
    disk = sim.model.bodies[0].points
    centre = np.array(case["bodies"][0]["center"])
    X = sim.state.x[disk].copy() - centre
    s = sim.state

    def travel() -> float:
        return (s.body_offset[1][1] - s.body_offset[2][1]) / (2 * R)

    while travel() < strain - 1e-9:  # by travel: the step-size controller may halve Δt
        sim.step()
        s = sim.state
    return {"X": X, "vol": s.vol[disk], "sigma": s.sigma[disk], "h": sim.model.lattice.h,
            "travel": travel()}


def measure(state: dict, fe: tuple[np.ndarray, np.ndarray], cells: float = 1.0) -> dict:
    """The scatter and errors, the smoothing grid ``cells`` × h."""
    X, vol, sigma, h = state["X"], state["vol"], state["sigma"], state["h"]
    grain = np.zeros(len(X), np.int64)
    smoothed = project_per_grain(X + 10.0 * R, vol, sigma, grain, cells * h)  # any origin
    raw_vm, smooth_vm = von_mises(sigma), von_mises(smoothed)
    folded = np.abs(X)
    points, values = fe
    linear = LinearNDInterpolator(points, values)
    fe_vm = linear(folded)
    missing = np.isnan(fe_vm)  # outside the quadrature points' hull: the nearest one
    fe_vm[missing] = NearestNDInterpolator(points, values)(folded[missing])
    scale = float(np.average(fe_vm, weights=vol))
    inner = np.linalg.norm(X, axis=1) < R - h

    def rms(a, b, mask):
        return float(np.sqrt(np.average((a[mask] - b[mask]) ** 2, weights=vol[mask]))) / scale

    everywhere = np.ones(len(X), bool)
    mean_raw = np.einsum("p,pij->ij", vol, sigma)
    mean_smooth = np.einsum("p,pij->ij", vol, smoothed)
    return {"scatter raw-smooth": rms(raw_vm, smooth_vm, everywhere),
            "raw-FE": rms(raw_vm, fe_vm, everywhere),
            "smooth-FE": rms(smooth_vm, fe_vm, everywhere),
            "raw-FE inner": rms(raw_vm, fe_vm, inner),
            "smooth-FE inner": rms(smooth_vm, fe_vm, inner),
            "mean change": float(np.abs(mean_smooth - mean_raw).max()
                                 / np.abs(mean_raw).max()),
            "<s_FE>/E": scale / E,
            "<s_raw>/<s_FE>": float(np.average(raw_vm, weights=vol)) / scale}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dh", type=int, nargs="+", default=[20, 40])
    parser.add_argument("--shape", nargs="+", default=["linear", "bspline2"])
    parser.add_argument("--strain", type=float, default=0.2)
    parser.add_argument("--cells", type=float, nargs="+", default=[1.0],
                        help="smoothing grid spacings to compare, in cells h")
    args = parser.parse_args()
    header = None
    for shape in args.shape:
        for dh in args.dh:
            t0 = time.perf_counter()
            state = mpm_state(dh, shape, args.strain)
            wall = time.perf_counter() - t0
            # the reference at the travel the run reached (its last step may pass the target)
            fe = fe_von_mises(state["travel"], steps=max(2, round(state["travel"] / 0.005)))
            for cells in args.cells:
                row = {"shape": shape, "D/h": dh, "travel/D": state["travel"],
                       "grid/h": cells, **measure(state, fe, cells), "wall [s]": wall}
                if header is None:
                    header = list(row)
                    print(" | ".join(header))
                print(" | ".join(f"{v:.4g}" if isinstance(v, float) else str(v)
                                 for v in row.values()), flush=True)


if __name__ == "__main__":
    main()

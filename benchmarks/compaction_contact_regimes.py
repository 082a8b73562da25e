"""Issue 11 item 7 (b): the coupled contact solve of the 30-grain compaction across regimes.

Each example case (both frictions) is pre-compacted as its protocol does (to σ0, in
equilibrium) at each D/h; from that state every regime runs ``--steps`` steps at
Δt c/h = 0.1, 1, 10, 100, 10⁴ with the top wall moving down at v = min(10⁻³ c, 0.1 h/Δt)
from the first step (slow against the waves, at most 0.1 h a step; c the P-wave speed of
the grains' material). Prints per (case, D/h, regime): coupling iterations a step (mean /
max), contact-solver iterations a step (Newton iterations plus any Gauss–Seidel sweeps),
seconds a step (mean / max), steps retried by the step-size controller (``--halvings``,
default 6) and its smallest Δt factor (it also shortens steps in which the grains'
velocities would carry a point more than a cell: max_step_motion), steps committed
unconverged, the least end-of-step gap at the active contacts (cells h), and where the
walls' work W went over the regime (series.csv's bookkeeping): the share stored in the
grains (ΔE/W, E = kinetic + strain + gravity energy), taken by friction and the contacts
(D_c/W) and by the integrator (D_int/W, θ = 1's numerical damping, with the transfers).

    python benchmarks/compaction_contact_regimes.py [--dh 10 20] [--steps 5] \
        [--cases examples/compaction_frictional.toml examples/compaction_frictionless.toml]
        [--threads 1]

D/h 20 takes cell_size = D/20 and keeps the example's points per cell (45k points). The
pre-compactions take minutes (frictional D/h 10 / 20: 72 s / 292 s on one core of the 2-core
machine); ``--save DIR`` writes each pre-compacted state there as a checkpoint and
``--load DIR`` starts from it. A regime whose step fails (after the step-size controller's
retries) is reported with the error and the benchmark goes on with the next regime.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np
from contact_regimes import StepTally
from squeeze_convergence import print_table

from softgrains import Simulation, checkpointing, load_case
from softgrains.errors import SimulationError
from softgrains.materials.dispatch import lame_parameters

REGIMES = (0.1, 1.0, 10.0, 100.0, 1e4)
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
ENERGY_COLUMNS = ("kinetic_energy", "strain_energy", "gravity_energy")
INTEGRATOR = ("integrator_dissipation", "transfer_dissipation")


def wave_speed(case) -> float:
    """P-wave speed sqrt((λ + 2μ)/ρ) of the sample's material."""
    material = case.materials[case.sample.material]
    lam, mu = lame_parameters(material.young, material.poisson)
    return float(np.sqrt((lam + 2.0 * mu) / material.density))


def precompacted(path: Path, d_over_h: int, threads: int, load: Path | None,
                 save: Path | None) -> Simulation:
    """The example at D/h, run until its pre-compaction ends (or loaded from ``load``)."""
    probe = load_case(path)
    overrides = [f"grid.cell_size={probe.sample.mean_diameter / d_over_h!r}",
                 f"simulation.threads={threads}"]
    sim = Simulation(load_case(path, overrides))
    name = f"{path.stem}_dh{d_over_h}.h5"
    if load is not None:
        sim.resume(load / name)
        return sim
    while sim.protocol.phase != "compaction":
        sim.step()
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)
        sim.write_checkpoint(save / name)
    return sim


def _energy(sim: Simulation) -> np.ndarray:
    """(E, W, D_c, D_int): the grains' energy, the walls' work, what the contacts and the
    integrator (with the transfers) took out, so far."""
    row = sim.series_row()
    return np.array([sum(row[k] for k in ENERGY_COLUMNS), row["wall_work"],
                     row["contact_dissipation"], sum(row[k] for k in INTEGRATOR)])


def set_regime(sim: Simulation, dt_c_over_h: float) -> float:
    """Δt = (Δt c/h) h/c and the top wall at v = min(10⁻³ c, 0.1 h/Δt) from the next step
    on (no ramp); returns v."""
    h = sim.model.lattice.h
    c = wave_speed(sim.case)
    dt = dt_c_over_h * h / c
    speed = min(1e-3 * c, 0.1 * h / dt)
    sim.dt = sim.protocol.dt = dt
    sim.protocol.settings = sim.protocol.settings.model_copy(
        update={"wall_speed": speed, "wall_speed_ramp": 0.0})
    return speed


def regime(sim: Simulation, dt_c_over_h: float, steps: int, halvings: int) -> dict:
    """``steps`` steps at Δt c/h from the state of ``sim`` (changed in place), the
    step-size controller allowed ``halvings`` halvings of Δt."""
    h = sim.model.lattice.h
    speed = set_regime(sim, dt_c_over_h)
    sim.case = sim.case.model_copy(update={"simulation": sim.case.simulation.model_copy(
        update={"retry_halvings": halvings})})
    sim.smallest_dt_factor = sim.dt_factor = 1.0
    tally, seconds = StepTally(h), []
    retried, failure = sim.retried_steps, ""
    before = _energy(sim)
    for _ in range(steps):
        start = time.perf_counter()
        try:
            diag = sim.step()
        except SimulationError as error:
            failure = str(error).splitlines()[0]
            break
        seconds.append(time.perf_counter() - start)
        tally.add(diag)
    stored, work, contacts, integrator = _energy(sim) - before
    share = (lambda x: x / work) if work > 0.0 else (lambda x: float("nan"))
    columns = tally.columns()
    row = {"dt c/h": dt_c_over_h, "wall m/s": speed, "its/step": columns["its/step"],
           "solver its/step": columns["solver its/step"],
           "s/step": f"{np.mean(seconds):.3g} / {max(seconds):.3g}" if seconds else "-",
           "retried": sim.retried_steps - retried, "least dt": sim.smallest_dt_factor,
           "unconverged": columns["unconverged"],
           "least gap [h]": columns["least gap [h]"],
           "ΔE/W": share(stored), "D_c/W": share(contacts), "D_int/W": share(integrator)}
    if failure:
        row["s/step"] = f"stopped after {len(seconds)}: {failure}"
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=Path, nargs="+", default=[
        EXAMPLES / "compaction_frictional.toml", EXAMPLES / "compaction_frictionless.toml"])
    parser.add_argument("--dh", type=int, nargs="+", default=[10, 20])
    parser.add_argument("--regimes", type=float, nargs="+", default=list(REGIMES))
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--halvings", type=int, default=6,
                        help="the step-size controller's retry_halvings (the examples' 2 "
                             "cannot bring Δt c/h = 10⁴ down to what the pre-compacted "
                             "state's rattlers need)")
    parser.add_argument("--save", type=Path, help="write the pre-compacted states here")
    parser.add_argument("--load", type=Path, help="start from the states saved there")
    args = parser.parse_args()
    rows = []
    for d_over_h in args.dh:
        for path in args.cases:
            start = time.perf_counter()
            sim = precompacted(path, d_over_h, args.threads, args.load, args.save)
            print(f"{path.stem} D/h {d_over_h}: pre-compacted (φ0 = {sim.protocol.phi0:.4f}) "
                  f"in {time.perf_counter() - start:.0f} s, {sim.model.n_points} points",
                  flush=True)
            saved = checkpointing.snapshot(sim)
            for dt_c_over_h in args.regimes:
                checkpointing.restore(sim, *saved)
                row = {"case": path.stem.removeprefix("compaction_"), "D/h": d_over_h,
                       **regime(sim, dt_c_over_h, args.steps, args.halvings)}
                rows.append(row)
                print(" | ".join(f"{v:.3g}" if isinstance(v, float) else str(v)
                                 for v in row.values()), flush=True)
    print()
    print_table(rows, digits=3)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"(top wall at min(1e-3 c, 0.1 h/Δt) from the pre-compacted state, {args.steps} "
          f"steps a regime, retry_halvings = {args.halvings}, {args.threads} thread(s); "
          f"least dt: the smallest Δt factor of the step-size controller; peak memory "
          f"{peak:.0f} MB)")


if __name__ == "__main__":
    main()

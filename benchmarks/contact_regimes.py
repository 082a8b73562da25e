"""Issue 11 item 7: the coupled contact solve across regimes, Δt c/h = 0.1 … 10⁴.

The squeezed disk of squeeze_convergence.py (neo-Hookean, R = 0.5 m, E = 10 MPa, ν = 0.4,
frictionless or μ = 0.5 plates) is first squeezed quasi-statically to 10% of D (Δt c/h =
3000, 0.1 h a step each plate); from that state each regime runs ``--steps`` steps at
Δt c/h = 0.1, 1, 10, 100, 10⁴ with the plates closing at v = min(10⁻³ c, 0.1 h/Δt) (slow
against the waves, at most 0.1 h a step). Prints per regime: coupling iterations per step
(mean / max), contact solver iterations per step (Newton iterations plus any Gauss–Seidel
sweeps), wall time per step, the steps whose coupled solve did not converge, and the
least gap at the active contacts in cells.

    python benchmarks/contact_regimes.py [--dh 20] [--friction 0 0.5]
                                         [--shape linear bspline2] [--steps 10]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field

import numpy as np
from squeeze_convergence import R, print_table, squeeze_case, wave_speed

from softgrains import Simulation, checkpointing, load_case

REGIMES = (0.1, 1.0, 10.0, 100.0, 1e4)
PRESQUEEZE = 0.10  # of D, before the regimes start


@dataclass
class StepTally:
    """What the regime tables report of each step: coupling iterations, contact-solver
    iterations, unconverged steps, the least gap at the active contacts (in cells h)."""

    h: float
    iterations: list[int] = field(default_factory=list)
    solver_iterations: list[int] = field(default_factory=list)
    unconverged: int = 0
    gaps: list[float] = field(default_factory=list)

    def add(self, diag) -> None:
        self.iterations.append(diag.contact.iterations)
        self.solver_iterations.append(diag.contact.sweeps)
        self.unconverged += not diag.contact.converged
        active = np.any(diag.contacts.impulse != 0.0, axis=1)
        if active.any():
            self.gaps.append(float(diag.contacts.gap[active].min()) / self.h)

    def columns(self) -> dict:
        its = self.iterations
        return {"its/step": f"{np.mean(its):.1f} / {max(its)}" if its else "-",
                "solver its/step": float(np.mean(self.solver_iterations)) if its
                else float("nan"),
                "unconverged": self.unconverged,
                "least gap [h]": min(self.gaps) if self.gaps else float("nan")}


def presqueezed(d_over_h: int, friction: float, shape: str) -> Simulation:
    """The disk squeezed quasi-statically to PRESQUEEZE of D (its Simulation)."""
    case = squeeze_case(d_over_h, 3000.0, 0.1, strain=PRESQUEEZE, overrides={
        "grid.shape_function": shape, "contact.friction": friction})
    sim = Simulation(load_case(case))
    for _ in range(sim.n_steps):
        sim.step()
    return sim


def regime(sim: Simulation, dt_c_over_h: float, steps: int) -> dict:
    """``steps`` steps at Δt c/h from the state of ``sim`` (changed in place)."""
    h = sim.model.lattice.h
    dt = dt_c_over_h * h / wave_speed()
    speed = min(1e-3 * wave_speed(), 0.1 * h / dt)
    sim.dt = dt
    sim.state.body_velocity[1][:] = (0.0, speed)
    sim.state.body_velocity[2][:] = (0.0, -speed)
    tally = StepTally(h)
    t0 = time.perf_counter()
    for _ in range(steps):
        tally.add(sim.step())
    wall = (time.perf_counter() - t0) / steps
    columns = tally.columns()
    return {"dt c/h": dt_c_over_h, "its/step": columns["its/step"],
            "solver its/step": columns["solver its/step"], "s/step": wall,
            "unconverged": columns["unconverged"], "least gap [h]": columns["least gap [h]"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dh", type=int, nargs="+", default=[20])
    parser.add_argument("--friction", type=float, nargs="+", default=[0.0, 0.5])
    parser.add_argument("--shape", nargs="+", default=["linear", "bspline2"])
    parser.add_argument("--steps", type=int, default=10)
    args = parser.parse_args()
    rows = []
    for d_over_h in args.dh:
        for shape in args.shape:
            for mu in args.friction:
                start = presqueezed(d_over_h, mu, shape)
                saved = checkpointing.snapshot(start)
                for dtch in REGIMES:
                    checkpointing.restore(start, *saved)
                    row = regime(start, dtch, args.steps)
                    rows.append({"D/h": d_over_h, "shape": shape, "μ": mu, **row})
    print_table(rows, digits=3)
    print(f"(plates closing at min(1e-3 c, 0.1 h/Δt) from {PRESQUEEZE:.0%} of D; "
          f"R = {R} m, c = {wave_speed():.1f} m/s)")


if __name__ == "__main__":
    main()

"""Why a loaded grain spins up (issue 11, next step 000): per step, each grain's angular
momentum change against the contacts' angular impulse and against the θ-step's
angular-momentum error for a pre-stressed spinning body,

    ΔL_bulk = ΔL − Σ_c (x_c − c) × P_c  ≈  θ Δt² ω Σ_c P_c (x_c − c)·(−n_c)   (predicted),

n_c the contact normal out of the grain; the error has the sign of ω under compression,
so a grain that nothing holds from turning spins up (docs/dev-notes.md, session 45).

Runs the six-disk compaction of ``tests/protocol/test_compaction.py`` (D/h 5, ρ 100,
seed 3) with the given ``contact.grain_passes`` and friction, and prints the steps where
some grain's rim moves more than ``--spin`` cells a step (and every 10th step). A point
ω measured from the points after the step's PIC update; L about the grain's mass centre.

The contacts' angular impulse is taken at the sites; since session 46 the surface sides'
levers (contact/levers.py) add the moment that cancels the error, so ΔL_bulk then shows
the error the levers cancel. ``--no-levers`` runs without them (as before session 46).

Run:  python benchmarks/spin_trace.py [--passes one] [--friction 0] [--steps 140]
      [--no-levers]
Measured (session 45, passes "one", μ 0, no levers): grain 2 went 1 → 729 rad/s in steps
80–95 with ΔL_bulk 10–12% below the prediction (7.5e-6 against 8.2e-6 N·s at step 90,
1.26e-4 against 1.40e-4 at step 95) while the contacts' angular impulse opposed the spin.
With the levers (session 46) no grain passes 520 rad/s (a rim at 0.13 h a step, for a
few steps) and the corrections do no work.
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

from softgrains import Simulation, load_case
from softgrains.contact import coupling
from softgrains.contact.levers import moment


def six_disks(passes: str, friction: float) -> dict:
    """The six-disk frictionless compaction of tests/protocol/test_compaction.py."""
    return {
        # the consistent form's error (the momentum form, the default since session 50,
        # has none, and its grains take no levers)
        "simulation": {"dt": 1e-4, "end_time": 0.2, "theta": 1.0, "seed": 3,
                       "stress_form": "consistent"},
        "grid": {"cell_size": 2e-3},
        "materials": {"gel": {"young": 1e7, "poisson": 0.4, "density": 100.0}},
        "sample": {"count": 6, "mean_diameter": 0.01, "polydispersity": 0.2,
                   "box_width": 0.02, "material": "gel", "seeding": "rings"},
        "protocol": {"kind": "uniaxial-compaction", "sigma0": 5e3, "wall_speed": 0.5,
                     "precompaction_dt": 5e-4, "precompaction_speed": 0.5,
                     "stop_stress_ratio": 30.0},
        "contact": {"friction": friction, "grain_passes": passes},
        "output": {"interval": 1, "snapshot_interval": 0, "progress": False},
    }


def _spin(sim, body) -> tuple[float, np.ndarray, float, float]:
    """(L, mass centre, polar moment, largest radius) of a grain's points."""
    m, x, v = sim.model.mass[body.points], sim.state.x[body.points], sim.state.v[body.points]
    c = (m[:, None] * x).sum(0) / m.sum()
    r, w = x - c, v - (m[:, None] * v).sum(0) / m.sum()
    return (float((m * moment(r, w)).sum()), c, float((m * (r * r).sum(1)).sum()),
            float(np.sqrt((r * r).sum(1)).max()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--passes", default="one", choices=["auto", "one", "two"])
    parser.add_argument("--friction", type=float, default=0.0)
    parser.add_argument("--steps", type=int, default=140)
    parser.add_argument("--spin", type=float, default=0.05,
                        help="print steps where a rim moves more than this many cells")
    parser.add_argument("--no-levers", action="store_true",
                        help="the surface sides' impulses without their levers")
    args = parser.parse_args()
    coupling.SURFACE_LEVERS = not args.no_levers
    case = load_case(six_disks(args.passes, args.friction))
    theta = case.simulation.theta
    print("| step | Δt | grain | ω [rad/s] | rim [h/step] | ΔL | contacts' ∫τ | ΔL_bulk "
          "| predicted | gap work / wall work |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as out:
        sim = Simulation(case, out=out)
        grains = [b for b in sim.model.bodies if b.deformable]
        h = sim.model.lattice.h
        for step in range(1, args.steps + 1):
            if sim.finished:
                break
            before = {b.index: _spin(sim, b) for b in grains}
            sim.step()
            dt, contacts = sim.last_dt, sim.state.contacts
            nodes = contacts.nodes if contacts is not None else None
            for b in grains:
                L0, c0, _, _ = before[b.index]
                L1, c1, inertia, radius = _spin(sim, b)
                omega, rim = L1 / inertia, abs(L1 / inertia) * radius * dt / h
                if rim < args.spin and step % 10:
                    continue
                torque = predicted = 0.0
                if nodes is not None and nodes.position is not None and len(nodes):
                    mine = (nodes.alpha == b.index) | (nodes.beta == b.index)
                    sign = np.where(nodes.alpha == b.index, 1.0, -1.0)[mine]
                    lever = nodes.position[mine] - 0.5 * (c0 + c1)
                    impulse = sign[:, None] * contacts.impulse[mine]  # on the grain
                    torque = float(moment(lever, impulse).sum())
                    # Σ P R: the impulses pressing on the grain along its lever, per Δt
                    predicted = theta * dt * omega * float(-(lever * impulse).sum())
                work = sim.gap_correction_work / max(sim.wall_work, 1e-300)
                print(f"| {step} | {dt:.1e} | {b.index} | {omega:+.1f} | {rim:.3f} | "
                      f"{L1 - L0:+.3e} | {torque:+.3e} | {L1 - L0 - torque:+.3e} | "
                      f"{predicted:+.3e} | {work:.3f} |")


if __name__ == "__main__":
    main()

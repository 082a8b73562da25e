"""The negative modes of the bodies' exact Newton matrices in the quasi-static squeeze
(issue 11, item 0a; session 35).

Runs the D10 squeeze (squeeze_convergence.py's case: one neo-Hookean disk between
frictionless plates) and, at the first Newton direction of each step, takes the disk's
exact Newton matrix A = c_m M + θΔt K_T (A v = λ M v, M the lumped mass) and prints:
its lowest eigenvalues λ (the rigid modes' mass term c_m for scale), how much of the
lowest mode is the rigid rotation of the current configuration,
v_I = ẑ × (X_I + u_I − x̄) (1: all of it), and that rotation's Rayleigh quotient
vᵀAv / vᵀMv; then per step the coupling iterations and Δt, and their totals.

Session 35 (this 2-core machine, D/h 20, Δt c/h 3000): one negative eigenvalue at every
step, −270 at step 1 to −1900 at step 5 against c_m ≈ 0.98, its mode the rotation to 3
digits: the compressed disk's rotation releases energy along a straight path (the contact
loads' virial), and a definite tangent diverges from the step's saddle along it (see
docs/dev-notes.md, Next steps for #11, 0a).

    python benchmarks/negative_modes.py [--dh 20] [--dtch 3000] [--steps 8]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from squeeze_convergence import squeeze_case

import softgrains.integrator.implicit as implicit
from softgrains import Simulation, load_case
from softgrains.integrator.linear_solvers import dense


def rotation(step: implicit.BodyStep) -> np.ndarray:
    """The rigid rotation of the body's current configuration over its unknowns (2D)."""
    X = step.stepper.lattice.node_positions(step.box)[step.active] + step.u
    centre = np.average(X, axis=0, weights=step.m[:, 0])
    v = np.c_[-(X[:, 1] - centre[1]), X[:, 0] - centre[0]].ravel()
    v[step.fixed.ravel()] = 0.0
    return v


def modes(step: implicit.BodyStep, count: int = 3) -> tuple[np.ndarray, float, float]:
    """(lowest ``count`` eigenvalues of A v = λ M v, the rotation's share of the lowest
    mode, the rotation's Rayleigh quotient)."""
    A = dense(step.newton_matrix())
    root = np.sqrt(step.m.ravel())
    B = A / root[:, None] / root[None, :]
    lam, U = np.linalg.eigh(0.5 * (B + B.T))
    v = rotation(step)
    scaled = v * root
    share = abs(float(scaled @ U[:, 0])) / float(np.linalg.norm(scaled))
    quotient = float(v @ (A @ v)) / float(v @ (step.m.ravel() * v))
    return lam[:count], share, quotient


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dh", type=int, default=20)
    parser.add_argument("--dtch", type=float, default=3000.0)
    parser.add_argument("--steps", type=int, default=8, help="steps analysed (then run on)")
    args = parser.parse_args()
    # the consistent form's modes (the momentum form, the default since session 50, gives
    # the loaded disk's rotation no negative curvature)
    sim = Simulation(load_case(squeeze_case(args.dh, args.dtch, 0.1, overrides={
        "simulation.stress_form": "consistent"})))
    if sim.model.dim != 2:
        raise SystemExit("the rotation mode is written for 2D")
    seen: set[int] = set()
    direction = implicit.BodyStep.newton_direction

    def probed(step, *rest, **keywords):
        number = step.step + 1  # (the step being taken)
        if number not in seen and number <= args.steps and not step.projected:
            seen.add(number)
            lam, share, quotient = modes(step)
            print(f"step {number:3d} {step.stepper.name}: lowest λ "
                  f"{', '.join(f'{x:.4g}' for x in lam)} (c_m {step.c_m:.4g}); rotation's "
                  f"share of the lowest mode {share:.3f}, its quotient {quotient:.4g}",
                  flush=True)
        return direction(step, *rest, **keywords)

    implicit.BodyStep.newton_direction = probed
    iterations, start = [], time.perf_counter()
    try:
        while not sim.at_end:
            diag = sim.step()
            iterations.append(diag.contact.iterations)
            print(f"step {sim.state.step:3d}: Δt {sim.last_dt:.3g} s, "
                  f"{diag.contact.iterations} coupling iterations", flush=True)
    finally:
        implicit.BodyStep.newton_direction = direction
    print(f"{len(iterations)} steps, {sum(iterations)} coupling iterations (max "
          f"{max(iterations)}), {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()

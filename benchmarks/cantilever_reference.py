"""Finite-element reference for VALIDATION case A4: a neo-Hookean cantilever under gravity.

An independent, benchmark-only reference (scikit-fem, not softgrains) for the static
deflection of the free bottom corner of a 4 m × 1 m beam clamped at x = 0 (u = 0 there),
E = 1 MPa, ν = 0.3, ρ = 1050 kg/m³, g = 10 m/s² downwards, plane strain, the compressible
neo-Hookean law of squeeze_reference.py (the same W as softgrains' materials/neo_hookean.py):

    W(F) = μ/2 (tr C − 3) − μ ln J + λ/2 (ln J)²,   static equilibrium  ∫ P : ∇v dX = ∫ ρ g · v dX.

Discretisation: biquadratic (Q2, 9-node) quadrilaterals on an n_x × n_y grid of the beam,
gravity applied in equal load steps, each solved by Newton's method with the consistent
tangent (to ‖du‖ < 1e-11 m). The corner's displacement is read at the node (4, 0).

Checks: the mesh sequence 16×4, 32×8, 64×16, 128×32 (the corner changes by less than
0.1% between the last two); with g scaled to 1% the tip deflection approaches the
Timoshenko beam's (plane strain: E' = E/(1 − ν²)).

Results (session 52, 2026-12-07): printed by the script; the table is in docs/dev-notes.md.
VALIDATION.md quotes u_y ≈ −2.51 m, u_x ≈ −1.47 m.

Run:  python benchmarks/cantilever_reference.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla
from skfem import Basis, ElementQuad2, ElementVector, LinearForm, MeshQuad

sys.path.insert(0, str(Path(__file__).parent))
from squeeze_reference import _internal_force, _stiffness, lame, neo_hookean  # noqa: E402

LENGTH, HEIGHT = 4.0, 1.0
YOUNG, NU, DENSITY, GRAVITY = 1.0e6, 0.3, 1050.0, 10.0


@LinearForm
def _weight(v, w):
    return -w["load"] * v[1]


def cantilever(n_x: int, n_y: int, *, gravity: float = GRAVITY, steps: int = 10
               ) -> tuple[np.ndarray, int]:
    """Static corner displacement (u_x, u_y) at (L, 0) and the Newton iterations taken."""
    lam, mu = lame(YOUNG, NU)
    mesh = MeshQuad.init_tensor(np.linspace(0.0, LENGTH, n_x + 1),
                                np.linspace(0.0, HEIGHT, n_y + 1))
    basis = Basis(mesh, ElementVector(ElementQuad2()), intorder=5)
    clamped = basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).flatten()
    free = np.setdiff1d(np.arange(basis.N), clamped)
    u = np.zeros(basis.N)
    iterations = 0
    for step in range(1, steps + 1):
        f_ext = _weight.assemble(basis, load=DENSITY * gravity * step / steps)
        for _ in range(40):
            g = basis.interpolate(u).grad
            stress, tangent = neo_hookean(g, lam, mu)
            residual = _internal_force.assemble(basis, stress=stress) - f_ext
            k = _stiffness.assemble(basis, tangent=tangent)
            du = np.zeros(basis.N)
            du[free] = spla.spsolve(k[free][:, free].tocsc(), -residual[free])
            alpha = 1.0
            while True:  # backtrack if an element would invert
                f = np.eye(2)[:, :, None, None] + basis.interpolate(u + alpha * du).grad
                if np.all(f[0, 0] * f[1, 1] - f[0, 1] * f[1, 0] > 0.0):
                    break
                alpha *= 0.5
            u += alpha * du
            iterations += 1
            if alpha == 1.0 and np.max(np.abs(du)) < 1e-11:
                break
        else:
            raise RuntimeError(f"Newton did not converge at load step {step}")
    corner = int(np.argmin(np.hypot(mesh.p[0] - LENGTH, mesh.p[1])))
    return u[basis.nodal_dofs[:, corner]], iterations


def timoshenko_tip(gravity: float) -> float:
    """Small-load tip deflection of a plane-strain cantilever under its weight q = ρ g H:
    q L⁴/(8 E' I) + q L²/(2 κ G A), E' = E/(1 − ν²), I = H³/12, κ = 5/6, G = E/(2(1 + ν))."""
    q = DENSITY * gravity * HEIGHT
    e_plane = YOUNG / (1.0 - NU**2)
    shear = YOUNG / (2.0 * (1.0 + NU))
    return -(q * LENGTH**4 / (8.0 * e_plane * HEIGHT**3 / 12.0)
             + q * LENGTH**2 / (2.0 * 5.0 / 6.0 * shear * HEIGHT))


def main() -> None:
    print("A4 cantilever, static corner displacement at (4, 0) [m], Q2 elements")
    print(f"{'mesh':>8} {'dofs':>7} {'u_x':>10} {'u_y':>10} {'Newton':>7} {'time s':>7}")
    for n_y in (4, 8, 16, 32):
        t0 = time.perf_counter()
        corner, its = cantilever(4 * n_y, n_y)
        dofs = 2 * (8 * n_y + 1) * (2 * n_y + 1)
        print(f"{4 * n_y:>3}×{n_y:<4} {dofs:>7} {corner[0]:>10.5f} {corner[1]:>10.5f} "
              f"{its:>7} {time.perf_counter() - t0:>7.1f}", flush=True)
    small = GRAVITY * 0.01
    corner, _ = cantilever(64, 16, gravity=small, steps=1)
    print(f"small load (g = {small} m/s², 64×16): u_y {corner[1]:.6f} m, Timoshenko "
          f"{timoshenko_tip(small):.6f} m")


if __name__ == "__main__":
    main()

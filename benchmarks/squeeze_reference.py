"""Finite-element reference for VALIDATION case D10: a disk squeezed between two plates.

An independent, benchmark-only reference (scikit-fem, not softgrains) for the plate force of
an elastic disk of radius R (diameter D = 2R) squeezed to large strain between two rigid,
frictionless, flat plates y = +(R - δ/2) and y = -(R - δ/2), where δ is the total plate
travel (the sum of both plates' displacements), from δ = 0 to δ = 0.30 D.  Static equilibrium
at each δ (quasi-static, no inertia), plane strain.

Material: compressible neo-Hookean, plane strain (F_zz = 1, b_zz = 1), with strain energy
per unit reference volume

    W(F) = μ/2 (tr C − 3) − μ ln J + λ/2 (ln J)²,   C = FᵀF,  tr C = C11 + C22 + 1,  J = det F,

first Piola stress and Kirchhoff stress

    P = ∂W/∂F = μ F + (λ ln J − μ) F⁻ᵀ,   τ = P Fᵀ = μ (b − I) + λ ln J I,   σ = τ / J,

and the consistent tangent (used in Newton's method)

    ∂P/∂F : dF = μ dF − (λ ln J − μ) F⁻ᵀ dFᵀ F⁻ᵀ + λ (F⁻ᵀ : dF) F⁻ᵀ,

with the Lamé constants λ = E ν / ((1 + ν)(1 − 2ν)), μ = E / (2 (1 + ν)).  For the small-strain
check, the same script also runs linear elasticity, σ = λ tr(ε) I + 2 μ ε, ε = sym ∇u.

Discretisation: by symmetry only the quarter disk x ≥ 0, y ≥ 0 is modelled, with u_x = 0 on
x = 0 and u_y = 0 on y = 0 (the bottom plate's contact is the mirror image of the top one).
Isoparametric P2 triangles (MeshTri2 + ElementTriP2, nodes on the arc lie on the circle), on a
mesh refined uniformly and then twice more along the arc where the contact will be.  The top
plate is a unilateral constraint on every boundary node (vertices and edge midpoints) of the
arc, Y + u_y ≤ R − δ/2, enforced by an active set: a node whose position would pass the plate
is fixed to u_y = R − δ/2 − Y (u_x stays free: no friction) and is released when its reaction
becomes tensile.  At each load step Newton's method with the consistent tangent solves
∫ P(F) : ∇v dX = 0 for the free degrees of freedom; the nodal reactions on the constrained
y-degrees of freedom are the residual there.

Output: the plate force per unit thickness for the WHOLE disk, F = 2 × (quarter model's
reaction on the top plate) (the quarter carries half of the top plate's contact), as a function
of δ.  Scaling X → X/R and stress → stress/E makes the problem dimensionless: F/(E R) as a
function of δ/D depends on ν only (not on E or R).  `python benchmarks/squeeze_reference.py
--check-scaling` verifies this numerically with a second (E, R) pair.

Checks (`--checks`): (1) the small-strain limit, linear elasticity against neo-Hookean at
δ/D = 0.002 on a mesh refined at the first contact point (they must agree within ~1%), and
both against the plane-strain Hertz-type formula for a cylinder between two flat plates
(Johnson, Contact Mechanics, 1985, ch. 5), δ = (2 F (1 − ν²)/(π E)) (2 ln(4R/a) − 1) with the Hertz
half-width a = (4 F R (1 − ν²)/(π E))^½; (2) mesh convergence of F at δ/D = 0.1, 0.2, 0.3;
(3) that the contact half-width grows monotonically and no node passes the plate.

Results, ν = 0.4 (production mesh n_refine = 4, 10 632 dofs, 60 steps, ~80 s on one core):
F/(E R) = 0.03755, 0.09231, 0.16232, 0.24965, 0.35809, 0.49325 at δ/D = 0.05, 0.10, …, 0.30;
meshes of 948 / 3 148 / 10 632 dofs change F at δ/D = 0.1, 0.2, 0.3 by at most 0.09% and then
0.02%; at δ/D = 0.002 neo-Hookean and linear differ by 0.06%, and the Johnson formula gives
δ within 0.04% of the FE value (a/R = 0.030 against Hertz 0.0302).  `--checks` adds ~1.5 min.

Run:  python benchmarks/squeeze_reference.py [--nu 0.4] [--checks] [--check-scaling]
Writes benchmarks/data/squeeze_reference_nu<ν>.csv (delta_over_D, force_per_thickness_over_ER).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla
from skfem import Basis, BilinearForm, ElementTriP2, ElementVector, LinearForm, MeshTri, MeshTri2
from skfem.helpers import grad

DATA = Path(__file__).resolve().parent / "data"
DELTA_MAX_OVER_D = 0.30
EYE = np.eye(2)[:, :, None, None]


def lame(young: float, nu: float) -> tuple[float, float]:
    """Lamé constants (λ, μ) from Young's modulus and Poisson's ratio."""
    return young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), young / (2.0 * (1.0 + nu))


# --------------------------------------------------------------------------------------------
# Mesh
# --------------------------------------------------------------------------------------------


def _on_arc(points: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Points off both axes (on the unit-radius mesh these are the arc's boundary points)."""
    return (points[0] > tol) & (points[1] > tol)


def _project_arc(mesh: MeshTri) -> MeshTri:
    """Move the mesh's boundary vertices that are not on an axis onto the unit circle."""
    p = mesh.p.copy()
    nodes = mesh.boundary_nodes()
    nodes = nodes[_on_arc(p[:, nodes])]
    p[:, nodes] /= np.linalg.norm(p[:, nodes], axis=0)
    return replace(mesh, doflocs=p)


def quarter_disk_mesh(radius: float, n_refine: int, focus: tuple[tuple, ...] = ()) -> MeshTri2:
    """Isoparametric P2 mesh of the quarter disk x ≥ 0, y ≥ 0 of the given radius.

    Two triangles (0, 0)–(1, 0)–(c, c) and (0, 0)–(c, c)–(0, 1), c = cos 45°, refined uniformly
    `n_refine` times with the new arc vertices moved to the circle after each refinement; then
    for each (depth, x_max) in `focus` the elements with centroid at r > 1 − depth and
    x < x_max are refined once more (conforming red-green-blue refinement).  The arc's edge
    midpoints are placed on the circle, so the boundary is exactly quadratic.
    """
    c = np.sqrt(0.5)
    mesh = MeshTri(np.array([[0.0, 1.0, c, 0.0], [0.0, 0.0, c, 1.0]]),
                   np.array([[0, 0], [1, 2], [2, 3]]))
    for _ in range(n_refine):
        mesh = _project_arc(mesh.refined())
    for depth, x_max in focus:
        mid = mesh.p[:, mesh.t].mean(axis=1)
        marked = np.flatnonzero((np.linalg.norm(mid, axis=0) > 1.0 - depth) & (mid[0] < x_max))
        mesh = _project_arc(mesh.refined(marked))
    quad = MeshTri2.from_mesh(mesh)
    doflocs = quad.doflocs.copy()
    arc = quad.dofs.get_facet_dofs(quad.boundary_facets()).flatten()
    arc = arc[_on_arc(doflocs[:, arc])]
    doflocs[:, arc] /= np.linalg.norm(doflocs[:, arc], axis=0)
    return replace(quad, doflocs=radius * doflocs)


# Meshes: the production mesh and the convergence sequence refine uniformly and then twice
# along the arc over the contact zone (a ≤ 0.7 R at δ = 0.3 D); the small-strain mesh
# refines seven times more near the first contact (x < 0.05 R, ever thinner layers at the arc).
def mesh_levels(level: int) -> tuple[int, tuple[tuple, ...]]:
    """(n_refine, focus) of the convergence sequence; level 2 is the production mesh."""
    return level + 2, ((0.3, 0.9), (0.12, 0.9))


SMALL_STRAIN_FOCUS = tuple((0.3 * 0.5**k, max(0.3 * 0.5**k, 0.05)) for k in range(7))


# --------------------------------------------------------------------------------------------
# Material laws: stress and consistent tangent at the quadrature points
# --------------------------------------------------------------------------------------------


def _inv_t(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """F⁻ᵀ and det F of a (2, 2, ...) array of 2×2 matrices."""
    det = f[0, 0] * f[1, 1] - f[0, 1] * f[1, 0]
    inv_t = np.array([[f[1, 1], -f[1, 0]], [-f[0, 1], f[0, 0]]]) / det
    return inv_t, det


def neo_hookean(g: np.ndarray, lam: float, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """First Piola stress P and tangent A_ijkl = ∂P_ij/∂F_kl for the displacement gradient g."""
    f = EYE + g
    h, det = _inv_t(f)
    if np.any(det <= 0.0):
        raise FloatingPointError("inverted element (J <= 0)")
    c1 = lam * np.log(det) - mu
    stress = mu * f + c1 * h
    # ∂P_ij/∂F_kl = μ δ_ik δ_jl − c1 H_il H_kj + λ H_ij H_kl, H = F⁻ᵀ
    eye = np.eye(2)
    tangent = (mu * np.einsum("ik,jl->ijkl", eye, eye)[..., None, None]
               - c1 * np.einsum("il...,kj...->ijkl...", h, h)
               + lam * np.einsum("ij...,kl...->ijkl...", h, h))
    return stress, tangent


def linear_elastic(g: np.ndarray, lam: float, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """Small-strain stress σ = λ tr ε I + 2 μ ε and its (constant) tangent."""
    eps = 0.5 * (g + np.swapaxes(g, 0, 1))
    stress = lam * (eps[0, 0] + eps[1, 1]) * EYE + 2.0 * mu * eps
    eye = np.eye(2)
    tangent = (lam * np.einsum("ij,kl->ijkl", eye, eye)
               + mu * (np.einsum("ik,jl->ijkl", eye, eye) + np.einsum("il,jk->ijkl", eye, eye)))
    tangent = np.broadcast_to(tangent[..., None, None], (2, 2, 2, 2) + g.shape[2:])
    return stress, tangent


LAWS = {"neo-hookean": neo_hookean, "linear": linear_elastic}


@LinearForm
def _internal_force(v, w):
    return np.einsum("ij...,ij...->...", np.asarray(w["stress"]), grad(v))


@BilinearForm
def _stiffness(u, v, w):
    return np.einsum("ijkl...,kl...,ij...->...", np.asarray(w["tangent"]), grad(u), grad(v))


# --------------------------------------------------------------------------------------------
# Quasi-static squeeze with an active-set contact
# --------------------------------------------------------------------------------------------


@dataclass
class SqueezeResult:
    delta_over_d: np.ndarray      # total plate travel δ / D
    force_over_er: np.ndarray     # whole-disk plate force per unit thickness F / (E R)
    half_width_over_r: np.ndarray  # contact half-width a / R (deformed, from the active nodes)
    penetration_over_r: np.ndarray  # largest (Y + u_y − plate) / R over the arc's nodes
    balance: np.ndarray           # |reaction on y = 0 − reaction on the plate| / F
    newton_iterations: int
    n_dofs: int
    wall_time: float
    basis: Basis | None = None    # the final state: the P2 basis and displacement (quarter)
    displacement: np.ndarray | None = None

    def cauchy_von_mises(self, nu: float, young: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(reference positions (2, q), von Mises of the Cauchy stress (q,)) at the
        quadrature points of the final state, neo-Hookean plane strain:
        σ = [μ (b − I) + λ ln J I] / J in the plane, σ_zz = λ ln J / J."""
        lam, mu = lame(young, nu)
        g = self.basis.interpolate(self.displacement).grad  # (2, 2, elements, points)
        F = EYE + g
        J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        b = np.einsum("ik...,jk...->ij...", F, F)
        sigma = (mu * (b - EYE) + lam * np.log(J) * EYE) / J
        szz = lam * np.log(J) / J
        sxx, syy, sxy = sigma[0, 0], sigma[1, 1], sigma[0, 1]
        vm = np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2)
                     + 3.0 * sxy**2)
        X = self.basis.global_coordinates().value  # (2, elements, points)
        return X.reshape(2, -1), vm.ravel()


def squeeze(nu: float, *, young: float = 1.0, radius: float = 1.0, n_refine: int = 4,
            focus: tuple[tuple, ...] | None = None, steps: int = 60,
            delta_max_over_d: float = DELTA_MAX_OVER_D, law: str = "neo-hookean",
            verbose: bool = False) -> SqueezeResult:
    """Squeeze the quarter disk from δ = 0 to `delta_max_over_d` D in `steps` equal steps."""
    t0 = time.perf_counter()
    lam, mu = lame(young, nu)
    material = LAWS[law]
    if focus is None:
        focus = mesh_levels(n_refine - 2)[1]
    mesh = quarter_disk_mesh(radius, n_refine, focus)
    basis = Basis(mesh, ElementVector(ElementTriP2()), intorder=4)
    n = basis.N

    # Points carrying two dofs (vertices and edge midpoints) and their reference positions.
    x_dofs = np.concatenate((basis.nodal_dofs[0], basis.facet_dofs[0]))
    y_dofs = np.concatenate((basis.nodal_dofs[1], basis.facet_dofs[1]))
    pos = basis.doflocs[:, x_dofs]
    tol = 1e-9 * radius
    arc = np.abs(np.linalg.norm(pos, axis=0) - radius) < tol  # contact candidates
    sym = np.concatenate((x_dofs[np.abs(pos[0]) < tol], y_dofs[np.abs(pos[1]) < tol]))
    bottom = y_dofs[np.abs(pos[1]) < tol]
    cand_y, cand_x, cand_pos = y_dofs[arc], x_dofs[arc], pos[:, arc]

    u = np.zeros(n)
    u_old = np.zeros(n)
    active = np.zeros(arc.sum(), dtype=bool)
    deltas = np.linspace(0.0, delta_max_over_d * 2.0 * radius, steps + 1)
    out = {k: [0.0] for k in ("force", "half", "pen", "bal")}
    total_its = 0

    def min_det(u_now: np.ndarray) -> float:
        if law == "linear":
            return 1.0
        return _inv_t(EYE + basis.interpolate(u_now).grad)[1].min()

    def assemble(u_now: np.ndarray, matrix: bool):
        g = basis.interpolate(u_now).grad
        stress, tangent = material(g, lam, mu)
        f_int = _internal_force.assemble(basis, stress=stress)
        k = _stiffness.assemble(basis, tangent=tangent) if matrix else None
        return f_int, k

    for step in range(1, steps + 1):
        plate = radius - 0.5 * deltas[step]
        # Predictor: linear extrapolation of the last two converged states.
        u_prev = u.copy()
        if step > 1 and min_det(2.0 * u - u_old) > 0.0:
            u = 2.0 * u - u_old
        u_old = u_prev
        active |= cand_pos[1] + u[cand_y] > plate
        for _ in range(30):  # active-set passes
            fixed = np.concatenate((sym, cand_y[active]))
            free = np.setdiff1d(np.arange(n), fixed)
            target = np.zeros(n)
            target[cand_y[active]] = plate - cand_pos[1, active]
            for _ in range(40):
                # Newton step; the prescribed values are reached through the linearised
                # problem, so that a newly fixed node drags its neighbours along.
                f_int, k = assemble(u, True)
                du = np.zeros(n)
                du[fixed] = target[fixed] - u[fixed]
                rhs = -f_int[free] - k[free][:, fixed] @ du[fixed]
                du[free] = spla.spsolve(k[free][:, free].tocsc(), rhs)
                alpha = 1.0
                while min_det(u + alpha * du) <= 0.0:  # backtrack if an element would invert
                    alpha *= 0.5
                    if alpha < 1e-3:
                        raise RuntimeError(f"element inversion at step {step}")
                u += alpha * du
                total_its += 1
                if alpha == 1.0 and np.max(np.abs(du)) < 1e-11 * radius:
                    break
            else:
                raise RuntimeError(f"Newton did not converge at step {step}")
            f_int, _ = assemble(u, False)
            reaction = f_int[cand_y]  # force of the plate on the body (negative: compressive)
            scale = max(abs(reaction[active].sum()), 1e-12 * young * radius)
            tensile = active & (reaction > 1e-10 * scale)
            passing = ~active & (cand_pos[1] + u[cand_y] > plate + tol)
            if not tensile.any() and not passing.any():
                break
            active = (active & ~tensile) | passing
        else:
            raise RuntimeError(f"active set did not settle at step {step}")
        force_quarter = -reaction[active].sum()
        bottom_reaction = f_int[bottom].sum()
        out["force"].append(2.0 * force_quarter)
        out["half"].append((cand_pos[0, active] + u[cand_x[active]]).max(initial=0.0))
        out["pen"].append((cand_pos[1] + u[cand_y] - plate).max())
        out["bal"].append(abs(bottom_reaction - force_quarter) / max(force_quarter, 1e-300))
        if verbose and step % 10 == 0:
            print(f"  step {step:4d}  δ/D = {deltas[step] / (2 * radius):.4f}  "
                  f"F/(ER) = {out['force'][-1] / (young * radius):.6f}  "
                  f"active = {active.sum()}", flush=True)

    return SqueezeResult(
        delta_over_d=deltas / (2.0 * radius),
        force_over_er=np.array(out["force"]) / (young * radius),
        half_width_over_r=np.array(out["half"]) / radius,
        penetration_over_r=np.array(out["pen"]) / radius,
        balance=np.array(out["bal"]),
        newton_iterations=total_its,
        n_dofs=n,
        wall_time=time.perf_counter() - t0,
        basis=basis,
        displacement=u,
    )


def reference_curve(nu: float, n_refine: int = 4, steps: int = 60,
                    delta_max_over_d: float = DELTA_MAX_OVER_D) -> tuple[np.ndarray, np.ndarray]:
    """(δ/D, F/(E R)) of the neo-Hookean disk of Poisson's ratio `nu`, δ/D from 0 to 0.30.

    F is the whole disk's plate force per unit thickness; the curve depends on ν only.
    `n_refine` is the number of uniform refinements (4 is the production mesh; each further
    one quarters the element size squared), `steps` the number of equal load steps.
    """
    res = squeeze(nu, n_refine=n_refine, steps=steps, delta_max_over_d=delta_max_over_d)
    return res.delta_over_d, res.force_over_er


# --------------------------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------------------------


def johnson_delta_over_d(force_over_er: float, nu: float) -> float:
    """δ/D of a plane-strain cylinder between two flat plates (Johnson, ch. 5), small loads."""
    e_star_ratio = 1.0 - nu**2  # F (1 − ν²)/(E R) = F / (E* R)
    p = force_over_er * e_star_ratio
    a_over_r = np.sqrt(4.0 * p / np.pi)
    return 0.5 * (2.0 * p / np.pi) * (2.0 * np.log(4.0 / a_over_r) - 1.0)


def check_small_strain(nu: float) -> None:
    print(f"\nSmall-strain limit, δ/D = 0.002, ν = {nu} (mesh refined at the first contact):")
    rows = {}
    for law in ("linear", "neo-hookean"):
        res = squeeze(nu, n_refine=3, focus=SMALL_STRAIN_FOCUS, steps=10,
                      delta_max_over_d=0.002, law=law)
        rows[law] = res
        f = res.force_over_er[-1]
        print(f"  {law:12s} F/(ER) = {f:.6e}  a/R = {res.half_width_over_r[-1]:.4f}  "
              f"dofs = {res.n_dofs}  [{res.wall_time:.1f} s]")
    f_lin, f_nh = rows["linear"].force_over_er[-1], rows["neo-hookean"].force_over_er[-1]
    print(f"  neo-Hookean / linear − 1 = {f_nh / f_lin - 1:+.3%}")
    for law, res in rows.items():
        f = res.force_over_er[-1]
        d_j = johnson_delta_over_d(f, nu)
        a_h = np.sqrt(4.0 * f * (1 - nu**2) / np.pi)
        print(f"  {law:12s} Johnson δ/D at this F = {d_j:.6f} (FE 0.002, {d_j / 0.002 - 1:+.2%}); "
              f"Hertz a/R = {a_h:.4f}")


def check_convergence(nu: float, levels: tuple[int, ...] = (0, 1, 2), steps: int = 30) -> None:
    # The equilibrium at a given δ does not depend on the load path (elastic, frictionless),
    # so fewer steps than in production suffice here.
    print(f"\nMesh convergence, ν = {nu}, {steps} steps (F/(ER) at δ/D = 0.1, 0.2, 0.3):")
    targets = (0.1, 0.2, 0.3)
    previous = None
    for level in levels:
        n_refine, focus = mesh_levels(level)
        res = squeeze(nu, n_refine=n_refine, focus=focus, steps=steps)
        idx = [int(round(t / DELTA_MAX_OVER_D * steps)) for t in targets]
        vals = res.force_over_er[idx]
        line = "  ".join(f"{v:.6f}" for v in vals)
        diff = ""
        if previous is not None:
            change = vals / previous - 1.0
            diff = "  change: " + "  ".join(f"{c:+.3%}" for c in change)
        print(f"  n_refine = {n_refine} dofs = {res.n_dofs:6d}  {line}{diff}  "
              f"[{res.wall_time:.1f} s, {res.newton_iterations} Newton its]", flush=True)
        previous = vals


def check_scaling(nu: float) -> None:
    print(f"\nScaling: F/(ER) for (E, R) = (1, 1) and (2.5e6, 0.004), ν = {nu}, coarse mesh:")
    a = squeeze(nu, n_refine=2, focus=mesh_levels(0)[1], steps=30)
    b = squeeze(nu, young=2.5e6, radius=0.004, n_refine=2, focus=mesh_levels(0)[1], steps=30)
    rel = np.max(np.abs(b.force_over_er[1:] / a.force_over_er[1:] - 1))
    print(f"  largest relative difference over the curve: {rel:.2e}")


def report(res: SqueezeResult) -> None:
    grows = bool(np.all(np.diff(res.half_width_over_r) >= -1e-12))
    print(f"  contact half-width non-decreasing: {grows}; a/R at δ/D = 0.3: "
          f"{res.half_width_over_r[-1]:.4f}")
    print(f"  largest penetration of a node past the plate: {res.penetration_over_r.max():.2e} R")
    print(f"  largest |bottom reaction − plate reaction| / F: {res.balance[1:].max():.2e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nu", type=float, default=0.4)
    parser.add_argument("--n-refine", type=int, default=4)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--rows-every", type=int, default=2, help="write every k-th step")
    parser.add_argument("--checks", action="store_true", help="small-strain and mesh checks")
    parser.add_argument("--check-scaling", action="store_true")
    args = parser.parse_args()

    res = squeeze(args.nu, n_refine=args.n_refine, steps=args.steps, verbose=True)
    print(f"\nν = {args.nu}: {res.n_dofs} dofs, {args.steps} steps, {res.newton_iterations} "
          f"Newton iterations, {res.wall_time:.1f} s")
    print("| δ/D | F/(E R) | a/R |")
    print("| --- | --- | --- |")
    rows = np.arange(0, args.steps + 1, args.rows_every)
    for i in rows:
        print(f"| {res.delta_over_d[i]:.4f} | {res.force_over_er[i]:.6f} | "
              f"{res.half_width_over_r[i]:.4f} |")
    report(res)
    DATA.mkdir(exist_ok=True)
    path = DATA / f"squeeze_reference_nu{args.nu:g}.csv"
    np.savetxt(path, np.column_stack((res.delta_over_d[rows], res.force_over_er[rows])),
               delimiter=",", fmt="%.8g", header="delta_over_D,force_per_thickness_over_ER",
               comments="")
    print(f"wrote {path}")
    if args.check_scaling:
        check_scaling(args.nu)
    if args.checks:
        check_small_strain(args.nu)
        check_convergence(args.nu)


if __name__ == "__main__":
    main()

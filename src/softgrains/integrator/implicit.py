"""One implicit step of one deformable body with Newton (ALGORITHM.md §3, §7).

Moreau–Jean θ-scheme (default), velocity form, impulse units:
    v^{n+1}(u) = (u/Δt − (1−θ) v^n)/θ
    R(u) = M (v^{n+1} − v^n) − Δt [(1−θ) F^n + θ F^{n+1}(u)] − P,   dR/du = M/(θΔt) + θΔt K_T
Newmark (β, γ; trapezoidal rule for β = 1/4, γ = 1/2), force units:
    a^{n+1}(u) = (u − Δt v^n)/(βΔt²) − (1/(2β) − 1) a^n,  v^{n+1} = v^n + Δt[(1−γ)a^n + γ a^{n+1}]
    R(u) = M a^{n+1} − F^{n+1}(u) − P/(γΔt),              dR/du = M/(βΔt²) + K_T
F = f^int + f^ext (f^ext = M g). Newton stops when ‖R‖ ≤ max(tol ‖R_0‖, floor), with the floor
the residual of a displacement error of 1e-10 h at every node: floor = 1e-10 h c_m ‖M‖
(c_m = 1/(θΔt) or 1/(βΔt²)). Dirichlet dofs carry their prescribed velocity (u = Δt v̄). A Newton update that would invert
a point (J ≤ 0) is halved, up to MAX_STEP_HALVINGS times.
Contact impulses P are zero until the contact issue adds them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.sparse as sp

from softgrains.errors import SimulationError
from softgrains.grid.lattice import Lattice, NodeBox
from softgrains.grid.shape_functions import compute_stencils, stencil_width
from softgrains.grid.transfers import grid_to_particles, local_node_indices, particles_to_grid
from softgrains.integrator.assembly import (
    add_diagonal_and_constrain,
    block_pattern,
    gather_forces,
    gather_tangent,
    node_point_map,
    pair_codes,
    point_stresses,
)
from softgrains.integrator.linear_solvers import LinearSolver

ACTIVE_MASS_FRACTION = 1e-12
RESIDUAL_FLOOR_DISPLACEMENT = 1e-10  # in units of h
CHUNKS_PER_THREAD = 8  # point chunks per thread in the parallel kernels
MAX_STEP_HALVINGS = 8  # backtracking of a Newton update that inverts a point


@dataclass(frozen=True)
class IntegratorSettings:
    """Time integrator and Newton options (case keys under [simulation])."""

    kind: str = "theta"  # "theta" | "newmark"
    theta: float = 0.5
    beta: float = 0.25
    gamma: float = 0.5
    flip: float = 1.0
    tolerance: float = 1e-8
    max_iterations: int = 25
    linear_solver: str = "auto"


@dataclass(frozen=True)
class DirichletBox:
    """Nodes inside [lower, upper] get the prescribed velocity on the masked components."""

    lower: np.ndarray
    upper: np.ndarray
    components: np.ndarray  # bool (d,)
    velocity: np.ndarray  # (d,)


@dataclass
class BodyPoints:
    """Views of one body's point arrays (modified in place by the step)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    F: np.ndarray
    sigma: np.ndarray
    vol: np.ndarray
    mass: np.ndarray
    vol0: np.ndarray
    law: np.ndarray
    lam: np.ndarray
    mu: np.ndarray


@dataclass
class BodyStepResult:
    """Diagnostics of one body's step."""

    iterations: int
    residuals: list[float] = field(default_factory=list)
    linear_method: str = ""
    linear_iterations: int = 0


class BodyStepper:
    """Newton solver of one deformable body; keeps its linear-solver choice between steps."""

    def __init__(self, name: str, lattice: Lattice, shape_kind: int,
                 settings: IntegratorSettings, constraints: list[DirichletBox]) -> None:
        self.name = name
        self.lattice = lattice
        self.shape_kind = shape_kind
        self.s = stencil_width(shape_kind)
        self.settings = settings
        self.constraints = constraints
        self.solver = LinearSolver(settings.linear_solver)
        self.codes = pair_codes(self.s, lattice.dim)

    # -- step set-up -------------------------------------------------------------------
    def _stencils(self, pts: BodyPoints, step: int):
        n, d = pts.x.shape
        ns = self.s**d
        base = np.empty((n, d), dtype=np.int64)
        N = np.empty((n, ns))
        dN = np.empty((n, ns, d))
        lat = self.lattice
        compute_stencils(pts.x, lat.node_origin, lat.h, self.shape_kind, base, N, dN)
        out = (base < 0) | (base + self.s > lat.n_nodes)
        if out.any():
            p = int(np.argwhere(out.any(axis=1))[0, 0])
            raise SimulationError(
                f"step {step}: point {p} of body '{self.name}' at {pts.x[p].tolist()} left the "
                f"grid [{lat.domain_lower.tolist()}, {lat.domain_upper.tolist()}]; enlarge "
                "[grid] size/origin or check the loading.",
                step=step, body=self.name, point=p)
        box = NodeBox.of_stencils(base, self.s)
        nodes = np.empty((n, ns), dtype=np.int64)
        local_node_indices(base, box.lower, box.strides(), self.s, nodes)
        return box, nodes, N, dN

    def _dirichlet(self, box: NodeBox, active: np.ndarray):
        d = self.lattice.dim
        fixed = np.zeros((active.size, d), dtype=bool)
        vbar = np.zeros((active.size, d))
        if not self.constraints:
            return fixed, vbar
        xn = self.lattice.node_positions(box)[active]
        tol = 1e-9 * self.lattice.h
        for c in self.constraints:
            inside = np.all((xn >= c.lower - tol) & (xn <= c.upper + tol), axis=1)
            for j in range(d):
                if c.components[j]:
                    fixed[inside, j] = True
                    vbar[inside, j] = c.velocity[j]
        return fixed, vbar

    # -- the step ----------------------------------------------------------------------
    def step(self, pts: BodyPoints, gravity: np.ndarray, dt: float, step: int) -> BodyStepResult:
        st = self.settings
        d = self.lattice.dim
        box, nodes, N, dN = self._stencils(pts, step)
        n_box = box.size
        m_I = np.empty(n_box)
        mv_I = np.empty((n_box, d))
        ma_I = np.empty((n_box, d))
        particles_to_grid(nodes, N, pts.mass, pts.v, pts.a, n_box, m_I, mv_I, ma_I)
        active = np.flatnonzero(m_I > ACTIVE_MASS_FRACTION * pts.mass.max())
        active_row = -np.ones(n_box, dtype=np.int64)
        active_row[active] = np.arange(active.size)
        m = m_I[active][:, None] * np.ones(d)
        v_n = mv_I[active] / m
        newmark = st.kind == "newmark"
        a_n = ma_I[active] / m if newmark else np.zeros_like(v_n)
        fixed, vbar = self._dirichlet(box, active)
        v_n[fixed] = vbar[fixed]
        a_n[fixed] = 0.0
        f_ext = m * gravity

        indptr, indices, slot, diag_slot = block_pattern(active_row, box.shape, self.s)
        ptr, entries = node_point_map(nodes, active_row, active.size)
        n_pts = nodes.shape[0]
        n_chunks = CHUNKS_PER_THREAD * numba.get_num_threads()
        Pv = np.empty((n_pts, d, d))
        Av = np.empty((n_pts, d, d, d, d))
        data = np.empty((indices.size, d, d))
        f_int = np.empty((active.size, d))
        u_box = np.zeros((n_box, d))
        F_n = pts.F.copy()
        vol_n = pts.vol.copy()

        def internal_force(u, want_tangent):
            """f^int(u) on the active nodes (and K in `data` if want_tangent); min J."""
            u_box[active] = u
            jmin = point_stresses(nodes, dN, u_box, F_n, vol_n, pts.law, pts.lam, pts.mu,
                                  Pv, Av, want_tangent, n_chunks)
            if jmin > 0.0:
                gather_forces(ptr, entries, dN, Pv, f_int)
                if want_tangent:
                    gather_tangent(ptr, entries, dN, Av, slot, self.codes, data)
            return f_int.copy(), jmin

        f_int_n, _ = internal_force(np.zeros_like(v_n), False)
        if newmark:
            c_m = 1.0 / (st.beta * dt * dt)
            u = dt * v_n + 0.5 * dt * dt * a_n
        else:
            c_m = 1.0 / (st.theta * dt)
            u = dt * v_n
            force_n = f_int_n + f_ext
        u[fixed] = dt * vbar[fixed]

        def residual(u, f_int):
            if newmark:
                a1 = c_m * (u - dt * v_n) - (0.5 / st.beta - 1.0) * a_n
                r = m * a1 - f_int - f_ext
            else:
                v1 = (u / dt - (1.0 - st.theta) * v_n) / st.theta
                r = m * (v1 - v_n) - dt * ((1.0 - st.theta) * force_n + st.theta * (f_int + f_ext))
            r[fixed] = 0.0
            return r

        floor = RESIDUAL_FLOOR_DISPLACEMENT * self.lattice.h * c_m * np.linalg.norm(m)
        fixed_flat = fixed.ravel()
        diag = (m * c_m).ravel()
        k_scale = 1.0 if newmark else st.theta * dt
        result = BodyStepResult(iterations=0)
        r0 = None
        du = None
        halvings = 0
        while True:
            f_int, jmin = internal_force(u, False)
            if jmin <= 0.0 and du is not None and halvings < MAX_STEP_HALVINGS:
                # the Newton update inverts a point: backtrack along it
                du *= 0.5
                u = u - du
                halvings += 1
                continue
            halvings = 0
            r = residual(u, f_int)
            rnorm = float(np.linalg.norm(r))
            if not np.isfinite(rnorm) or jmin <= 0.0:
                raise SimulationError(
                    f"step {step}: Newton of body '{self.name}' produced "
                    f"{'a non-finite residual' if jmin > 0 else 'an inverted point (J ≤ 0)'} "
                    f"at iteration {result.iterations}; try a smaller dt or a finer grid.",
                    step=step, body=self.name, residuals=result.residuals + [rnorm])
            result.residuals.append(rnorm)
            if r0 is None:
                r0 = rnorm
            if rnorm <= max(st.tolerance * r0, floor):
                break
            if result.iterations >= st.max_iterations:
                raise SimulationError(
                    f"step {step}: Newton of body '{self.name}' did not converge in "
                    f"{st.max_iterations} iterations (residual {rnorm:.3e}, first {r0:.3e}); "
                    "try a smaller dt, more newton_max_iterations or a looser "
                    "newton_tolerance.",
                    step=step, body=self.name, residuals=result.residuals)
            internal_force(u, True)
            if k_scale != 1.0:
                data *= k_scale
            add_diagonal_and_constrain(data, indptr, indices, diag_slot, diag, fixed_flat)
            A = sp.bsr_matrix((data, indices, indptr), shape=(diag.size, diag.size))
            try:
                du = self.solver.solve(A, -r.ravel(), diag_slot).reshape(u.shape)
            except (np.linalg.LinAlgError, RuntimeError) as err:
                raise SimulationError(
                    f"step {step}: linear solve of body '{self.name}' failed at Newton "
                    f"iteration {result.iterations}: {err}", step=step, body=self.name,
                    residuals=result.residuals) from err
            u = u + du
            result.iterations += 1
            result.linear_method = self.solver.last_method
            result.linear_iterations += self.solver.last_iterations

        if newmark:
            a1 = c_m * (u - dt * v_n) - (0.5 / st.beta - 1.0) * a_n
            v1 = v_n + dt * ((1.0 - st.gamma) * a_n + st.gamma * a1)
        else:
            a1 = np.zeros_like(u)
            v1 = (u / dt - (1.0 - st.theta) * v_n) / st.theta
        v_old = np.zeros((n_box, d))
        v_new = np.zeros((n_box, d))
        a_new = np.zeros((n_box, d))
        u_box[:] = 0.0
        u_box[active] = u
        v_old[active] = v_n
        v_new[active] = v1
        a_new[active] = a1
        jmin = grid_to_particles(nodes, N, dN, u_box, v_old, v_new, a_new, st.flip, newmark,
                                 pts.law, pts.lam, pts.mu, pts.vol0, pts.x, pts.v, pts.a,
                                 pts.F, pts.sigma, pts.vol, n_chunks)
        if jmin <= 0.0:
            raise SimulationError(
                f"step {step}: body '{self.name}' has an inverted point (J = {jmin:.3e}); "
                "try a smaller dt or a finer grid.", step=step, body=self.name)
        return result

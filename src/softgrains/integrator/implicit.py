"""One implicit step of one deformable body with Newton (ALGORITHM.md §3, §7).

Moreau–Jean θ-scheme (default), velocity form, impulse units:
    v^{n+1}(u) = (u/Δt − (1−θ) v^n)/θ
    R(u) = M (v^{n+1} − v^n) − Δt [(1−θ) F^n + θ F^{n+1}(u)] − P,   dR/du = M/(θΔt) + θΔt K_T
Newmark (β, γ; trapezoidal rule for β = 1/4, γ = 1/2), force units:
    a^{n+1}(u) = (u − Δt v^n)/(βΔt²) − (1/(2β) − 1) a^n,  v^{n+1} = v^n + Δt[(1−γ)a^n + γ a^{n+1}]
    R(u) = M a^{n+1} − F^{n+1}(u) − P/(γΔt),              dR/du = M/(βΔt²) + K_T
F = f^int + f^ext (f^ext = M g). Newton stops when ‖R‖ ≤ max(tol ‖R_0‖, floor), with the floor
the residual of a displacement error of 1e-10 h at every node: floor = 1e-10 h c_m ‖M‖
(c_m = 1/(θΔt) or 1/(βΔt²)). Dirichlet dofs carry their prescribed velocity (u = Δt v̄).
Both residuals are gradients of an incremental potential, R = ∇Π with
Π(u) = ½ c_m uᵀMu − b·u + s W(u) (s = θΔt or 1, W = Σ V⁰ W(F(u))), so Newton updates go
through a backtracking (Armijo) line search on Π that also rejects updates inverting a point
(J ≤ 0). M is the lumped or the consistent mass matrix (docs/theory.md).
Contact impulses P are zero until the contact issue adds them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.sparse as sp

from softgrains.errors import SimulationError
from softgrains.grid.lattice import Lattice, NodeBox
from softgrains.grid.shape_functions import stencil_width
from softgrains.grid.stencils import body_stencils
from softgrains.grid.transfers import (
    UPDATE_FLIP_NEWMARK,
    UPDATE_FLIP_THETA,
    UPDATE_PARTICLE_NEWMARK,
    UPDATE_PARTICLE_THETA,
    grid_to_particles,
    particles_to_grid,
    restrict_to_active,
)
from softgrains.integrator.assembly import (
    add_block_mass,
    add_diagonal,
    block_pattern,
    block_scalar_matvec,
    constrain,
    gather_consistent_mass,
    gather_forces,
    gather_tangent,
    node_point_map,
    pair_codes,
    point_stresses,
)
from softgrains.integrator.linear_solvers import LinearSolver

ACTIVE_MASS_FRACTION = 1e-4  # lighter nodes (fraction of the heaviest point) are removed
RESIDUAL_FLOOR_DISPLACEMENT = 1e-10  # in units of h
CHUNKS_PER_THREAD = 8  # point chunks per thread in the parallel kernels
MAX_LINE_SEARCH = 8  # halvings of a Newton update in the backtracking line search


@dataclass(frozen=True)
class IntegratorSettings:
    """Time integrator and Newton options (case keys under [simulation])."""

    kind: str = "theta"  # "theta" | "newmark"
    theta: float = 0.5
    beta: float = 0.25
    gamma: float = 0.5
    flip: float = 1.0
    mass_matrix: str = "lumped"  # "lumped" | "consistent"
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

    @staticmethod
    def _line_search(u, du, r, pi, internal_force, residual, potential):
        """Backtracking along the Newton direction: u + α du, α = 1, ½, ¼, ...

        The step equations are the stationarity of the incremental potential Π (R = ∇Π), so
        the first α with no inverted point and either the Armijo decrease
        Π(u + α du) ≤ Π(u) + 10⁻⁴ α R·du or a residual decrease ‖R‖ ≤ (1 − 10⁻⁴ α)‖R(u)‖ is
        taken (the second test decides near convergence, where differences of Π drown in
        round-off). If du is no descent direction (R·du ≥ 0) or no α within
        MAX_LINE_SEARCH halvings qualifies, the admissible trial of lowest Π is taken (if every
        trial inverts a point, the last one, which the caller reports).
        """
        slope = float(np.sum(r * du))
        rnorm = float(np.linalg.norm(r))
        alpha = 1.0
        best = None
        for _ in range(MAX_LINE_SEARCH + 1):
            u_try = u + alpha * du
            f_try, j_try, w_try = internal_force(u_try, False)
            if j_try > 0.0:
                pi_try = potential(u_try, w_try)
                r_try = residual(u_try, f_try)
                n_try = float(np.linalg.norm(r_try))
                trial = (u_try, f_try, r_try, n_try, j_try, pi_try)
                armijo = slope < 0.0 and pi_try <= pi + 1e-4 * alpha * slope
                if np.isfinite(n_try) and (armijo or n_try <= (1.0 - 1e-4 * alpha) * rnorm):
                    return trial
                if np.isfinite(n_try) and (best is None or pi_try < best[5]):
                    best = trial
            alpha *= 0.5
        if best is not None:
            return best
        return u_try, f_try, residual(u_try, f_try), float("nan"), j_try, float("nan")

    # -- the step ----------------------------------------------------------------------
    def step(self, pts: BodyPoints, gravity: np.ndarray, dt: float, step: int) -> BodyStepResult:
        st = self.settings
        d = self.lattice.dim
        newmark = st.kind == "newmark"
        consistent = st.mass_matrix == "consistent"
        stencils = body_stencils(self.lattice, self.shape_kind, pts.x, self.name, step)
        box, nodes, N, dN = stencils.box, stencils.nodes, stencils.N, stencils.dN
        n_box = box.size
        m_I = np.empty(n_box)
        mv_I = np.empty((n_box, d))
        ma_I = np.empty((n_box, d))
        particles_to_grid(nodes, N, pts.mass, pts.v, pts.a, n_box, m_I, mv_I, ma_I)
        active = np.flatnonzero(m_I > ACTIVE_MASS_FRACTION * pts.mass.max())
        n_act = active.size
        active_row = -np.ones(n_box, dtype=np.int64)
        active_row[active] = np.arange(n_act)
        if restrict_to_active(nodes, N, dN, active_row):
            particles_to_grid(nodes, N, pts.mass, pts.v, pts.a, n_box, m_I, mv_I, ma_I)
        m = m_I[active][:, None] * np.ones(d)  # lumped mass per dof
        p_n = mv_I[active]  # nodal momentum Σ N m v (= M v^n for either mass matrix)
        q_n = ma_I[active]  # Σ N m a (Newmark)
        v_free = p_n / m  # unconstrained lumped velocity: the FLIP increment starts from it
        v_n = v_free.copy()  # lumped estimates (predictor; FLIP increments)
        a_n = q_n / m if newmark else np.zeros_like(v_n)
        fixed, vbar = self._dirichlet(box, active)
        v_n[fixed] = vbar[fixed]
        a_n[fixed] = 0.0
        if not consistent:
            p_n = m * v_n
            q_n = m * a_n
        f_ext = m * gravity

        indptr, indices, slot, diag_slot = block_pattern(active_row, box.shape, self.s)
        ptr, entries = node_point_map(nodes, active_row, n_act)
        n_chunks = CHUNKS_PER_THREAD * numba.get_num_threads()
        Pv = np.empty((nodes.shape[0], d, d))
        Av = np.empty((nodes.shape[0], d, d, d, d))
        data = np.empty((indices.size, d, d))
        f_int = np.empty((n_act, d))
        u_box = np.zeros((n_box, d))
        F_n = pts.F.copy()
        vol_n = pts.vol.copy()
        if consistent:
            m_blocks = np.empty(indices.size)
            gather_consistent_mass(ptr, entries, N, pts.mass, slot, self.codes, m_blocks)
            Mu = np.empty((n_act, d))

        def mass_times(u):
            if not consistent:
                return m * u
            block_scalar_matvec(indptr, indices, m_blocks, u, Mu)
            return Mu

        def internal_force(u, want_tangent):
            """f^int(u) on the active nodes (and K in `data` if want_tangent); min J, W(u)."""
            u_box[active] = u
            jmin, w_int = point_stresses(nodes, dN, u_box, F_n, vol_n, pts.law, pts.lam, pts.mu,
                                  Pv, Av, want_tangent, n_chunks)
            if jmin > 0.0:
                gather_forces(ptr, entries, dN, Pv, f_int)
                if want_tangent:
                    gather_tangent(ptr, entries, dN, Av, slot, self.codes, data)
            return f_int.copy(), jmin, w_int

        # R(u) = c_m M u − b − s f^int(u) = ∇Π(u),  Π(u) = ½ c_m uᵀMu − b·u + s W(u)
        f_int_n, _, _ = internal_force(np.zeros_like(v_n), False)
        if newmark:  # M a^{n+1} − F^{n+1}
            c_m = 1.0 / (st.beta * dt * dt)
            s_f = 1.0
            b = c_m * (dt * p_n + (0.5 - st.beta) * dt * dt * q_n) + f_ext
            u = dt * v_n + 0.5 * dt * dt * a_n
        else:  # M (v^{n+1} − v^n) − Δt[(1−θ)F^n + θF^{n+1}]
            c_m = 1.0 / (st.theta * dt)
            s_f = st.theta * dt
            b = (c_m * (1.0 - st.theta) * dt + 1.0) * p_n + dt * (
                (1.0 - st.theta) * (f_int_n + f_ext) + st.theta * f_ext)
            u = dt * v_n
        u[fixed] = dt * vbar[fixed]

        def residual(u, f_int):
            r = c_m * mass_times(u) - b - s_f * f_int
            r[fixed] = 0.0
            return r

        def potential(u, w_int):
            return float(0.5 * c_m * np.sum(u * mass_times(u)) - np.sum(b * u) + s_f * w_int)

        floor = RESIDUAL_FLOOR_DISPLACEMENT * self.lattice.h * c_m * np.linalg.norm(m)
        fixed_flat = fixed.ravel()
        lumped_diag = (m * c_m).ravel()
        result = BodyStepResult(iterations=0)
        f_int, jmin, w_int = internal_force(u, False)
        if jmin <= 0.0:  # the predictor inverts a point: start from rest instead
            u = np.zeros_like(u)
            u[fixed] = dt * vbar[fixed]
            f_int, jmin, w_int = internal_force(u, False)
        r = residual(u, f_int)
        rnorm = float(np.linalg.norm(r))
        pi = potential(u, w_int)
        r0 = rnorm
        while True:
            if not np.isfinite(rnorm) or jmin <= 0.0:
                raise SimulationError(
                    f"step {step}: Newton of body '{self.name}' produced "
                    f"{'a non-finite residual' if jmin > 0 else 'an inverted point (J ≤ 0)'} "
                    f"at iteration {result.iterations}; try a smaller dt or a finer grid.",
                    step=step, body=self.name, residuals=result.residuals + [rnorm])
            result.residuals.append(rnorm)
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
            if s_f != 1.0:
                data *= s_f
            if consistent:
                add_block_mass(data, m_blocks, c_m)
            else:
                add_diagonal(data, diag_slot, lumped_diag)
            constrain(data, indptr, indices, fixed_flat)
            A = sp.bsr_matrix((data, indices, indptr), shape=(lumped_diag.size,) * 2)
            try:
                du = self.solver.solve(A, -r.ravel(), diag_slot).reshape(u.shape)
            except (np.linalg.LinAlgError, RuntimeError) as err:
                raise SimulationError(
                    f"step {step}: linear solve of body '{self.name}' failed at Newton "
                    f"iteration {result.iterations}: {err}", step=step, body=self.name,
                    residuals=result.residuals) from err
            result.iterations += 1
            result.linear_method = self.solver.last_method
            result.linear_iterations += self.solver.last_iterations
            u, f_int, r, rnorm, jmin, pi = self._line_search(
                u, du, r, pi, internal_force, residual, potential)

        u_box[:] = 0.0
        u_box[active] = u
        v_old = np.zeros((n_box, d))
        v_new = np.zeros((n_box, d))
        a_new = np.zeros((n_box, d))
        if consistent:
            update = UPDATE_PARTICLE_NEWMARK if newmark else UPDATE_PARTICLE_THETA
        else:
            update = UPDATE_FLIP_NEWMARK if newmark else UPDATE_FLIP_THETA
            if newmark:
                a1 = c_m * (u - dt * v_n) - (0.5 / st.beta - 1.0) * a_n
                v1 = v_n + dt * ((1.0 - st.gamma) * a_n + st.gamma * a1)
                a_new[active] = a1
            else:
                v1 = (u / dt - (1.0 - st.theta) * v_n) / st.theta
            v_old[active] = v_free  # so that fixed nodes pass their prescribed velocity on
            v_new[active] = v1
        params = np.array([dt, st.flip, st.theta, st.beta, st.gamma])
        jmin = grid_to_particles(nodes, N, dN, u_box, v_old, v_new, a_new, update, params,
                                 pts.law, pts.lam, pts.mu, pts.vol0, pts.x, pts.v, pts.a,
                                 pts.F, pts.sigma, pts.vol, n_chunks)
        if jmin <= 0.0:
            raise SimulationError(
                f"step {step}: body '{self.name}' has an inverted point (J = {jmin:.3e}); "
                "try a smaller dt or a finer grid.", step=step, body=self.name)
        return result

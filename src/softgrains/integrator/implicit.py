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
Contact impulses P come from the coupling loop (contact/coupling.py).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from softgrains.errors import SimulationError
from softgrains.grid.clamps import clamp_faces
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
from softgrains.integrator import lapack
from softgrains.integrator.assembly import (
    add_block_mass,
    add_diagonal,
    block_pattern,
    block_scalar_matvec,
    constrain,
    dimension,
    gather_consistent_mass,
    gather_forces,
    gather_tangent,
    node_point_map,
    pair_codes,
    point_stresses,
    start_strain_energy,
)
from softgrains.integrator.banded import BandedDecoupled, band_pays, lower_bandwidth
from softgrains.integrator.banded import decoupled as banded_decoupled
from softgrains.integrator.dense_direction import (
    DONE,
    INDEFINITE,
    NewtonPattern,
    PointTangents,
    Rotations,
    StepTerms,
    banded_momentum_direction,
    momentum_direction,
)
from softgrains.integrator.linear_solvers import (
    DENSE_LIMIT,
    MIRROR_LIMIT,
    DenseCholesky,
    LinearSolver,
    dense,
    factorize,
    mirrored_negative_modes,
    site_columns,
    sparse_times,
)
from softgrains.integrator.momentum_line_search import ResidualTerms, residual_line_search
from softgrains.integrator.rotations import (
    DecoupledSparse,
    RigidRotations,
    corrected_solve,
    decoupled_dense,
    rotation_stiffness,
    symmetric_factorization,
)
from softgrains.materials.dispatch import LINEAR_LAW
from softgrains.threads import PARALLEL_MIN_POINTS, threads_for

ACTIVE_MASS_FRACTION = 1e-4  # lighter nodes (fraction of the heaviest point) are removed
RESIDUAL_FLOOR_DISPLACEMENT = 1e-10  # in units of h
CHUNKS_PER_THREAD = 8  # point chunks per thread in the parallel kernels
MAX_LINE_SEARCH = 8  # halvings of a Newton update in the backtracking line search
RIGID_MODES = {2: 3, 3: 6}  # a body's rigid modes by dimension (translations, rotations)


@dataclass(frozen=True)
class IntegratorSettings:
    """Time integrator and Newton options (case keys under [simulation])."""

    kind: str = "theta"  # "theta" | "newmark"
    theta: float = 1.0
    beta: float = 0.25
    gamma: float = 0.5
    flip: float = 1.0
    mass_matrix: str = "lumped"  # "lumped" | "consistent"
    tolerance: float = 1e-8
    max_iterations: int = 25
    linear_solver: str = "auto"
    tangent: str = "auto"  # "auto" (exact, projected when it fails) | "exact" | "projected"
    stress_form: str = "auto"  # "consistent" (V⁰ P Fⁿᵀ) | "momentum" (θ = 1: V⁰ Fⁿ S Fⁿᵀ) | "auto"

    @property
    def momentum_form(self) -> bool:
        """Whether free bodies of objective laws take the momentum form: stress_form
        "momentum" or "auto" with the θ-scheme at θ = 1 (the only step whose angular
        momentum balance it serves)."""
        return (self.stress_form in ("momentum", "auto") and self.kind == "theta"
                and self.theta == 1.0)


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
    # energy the step took out (J; see BodyStep.finish): the grid update's own
    # dissipation and the loss in the point ↔ grid transfers
    integrator_dissipation: float = 0.0
    transfer_dissipation: float = 0.0
    prescribed_work: float = 0.0  # work of the reactions at prescribed (Dirichlet) nodes


@dataclass(frozen=True)
class ImpulseResponse:
    """A body's impulse-to-iterate map X = w A⁻¹ G (G: its contact sites' components on the
    unknowns, zero at fixed dofs; w the impulse weight), applied as X q = w A⁻¹ (G q) with
    the factorization of the A its compliance was formed from, or by X where the LU formed
    it anyway (``formed``)."""

    weight: float
    factorization: object
    sites: np.ndarray
    free: np.ndarray
    formed: np.ndarray | None = None

    @property
    def positive_definite(self) -> bool:
        """Whether A is known to be positive definite (factorised by Cholesky; SuperLU's
        factorization does not tell)."""
        return isinstance(self.factorization, (DenseCholesky, BandedDecoupled))

    def move(self, q: np.ndarray) -> np.ndarray:
        """X q (q: one impulse per site component)."""
        if self.formed is not None:
            return self.formed @ q
        x = self.weight * self.factorization.solve(self.sites @ q)
        x[~self.free] = 0.0
        return x

    def matrix(self) -> np.ndarray:
        """X itself."""
        if self.formed is not None:
            return self.formed
        X = self.weight * self.factorization.solve(self.sites)
        X[~self.free] = 0.0
        return X


def line_search(u, du, r, pi, internal_force, residual, potential, enough=0.0):
    """Backtracking along the Newton direction: u + α du, α = 1, ½, ¼, ...

    The step equations are the stationarity of the incremental potential Π (R = ∇Π), so
    the first α with no inverted point and either the Armijo decrease
    Π(u + α du) ≤ Π(u) + 10⁻⁴ α R·du or a residual decrease ‖R‖ ≤ (1 − 10⁻⁴ α)‖R(u)‖ is
    taken (the second test decides near convergence, where differences of Π drown in
    round-off), or a trial whose ‖R‖ is within ``enough`` (the body's stopping threshold:
    it is converged there; a converged body moved only by impulse changes of ~1e-15 h
    otherwise had every trial refused, took 1/256 of its step and held the contact loop
    for ~10 iterations a step, session 35). If du is no descent direction (R·du ≥ 0) or
    no α within MAX_LINE_SEARCH halvings qualifies, the admissible trial of lowest Π is
    taken (if every trial inverts a point, the last one, which the caller reports).
    """
    slope = float(np.sum(r * du))
    rnorm = float(np.linalg.norm(r))
    alpha = 1.0
    best, best_key = None, np.inf
    for _ in range(MAX_LINE_SEARCH + 1):
        u_try = u + alpha * du
        f_try, j_try, w_try = internal_force(u_try, False)
        if j_try > 0.0:
            pi_try = potential(u_try, w_try)
            r_try = residual(u_try, f_try)
            n_try = float(np.linalg.norm(r_try))
            trial = (u_try, f_try, r_try, n_try, j_try, pi_try)
            armijo = np.isfinite(pi) and slope < 0.0 and pi_try <= pi + 1e-4 * alpha * slope
            if np.isfinite(n_try) and (armijo or n_try <= max((1.0 - 1e-4 * alpha) * rnorm,
                                                              enough)):
                return trial
            key = pi_try if np.isfinite(pi) else n_try  # (no Π: the momentum form)
            if np.isfinite(n_try) and (best is None or key < best_key):
                best, best_key = trial, key
        alpha *= 0.5
    if best is not None:
        return best
    return u_try, f_try, residual(u_try, f_try), float("nan"), j_try, float("nan")


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
        self.clamps = clamp_faces(lattice, constraints)  # faces whose ghost nodes reflect
        self.solver = LinearSolver(settings.linear_solver)
        self.codes = pair_codes(self.s, lattice.dim)

    # -- step set-up -------------------------------------------------------------------
    def _dirichlet(self, box: NodeBox, active: np.ndarray):
        d = self.lattice.dim
        fixed = np.zeros((active.size, d), dtype=bool)
        vbar = np.zeros((active.size, d))
        if not self.constraints:
            return fixed, vbar
        xn = self.lattice.node_positions(box, active)
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
        """One implicit step of the body (points updated in place)."""
        body_step = BodyStep(self, pts, gravity, dt, step)
        body_step.solve()
        return body_step.finish()


class BodyStep:
    """One body's implicit step in progress (ALGORITHM.md §3, §7).

    Set-up (P2G, active nodes, Dirichlet values, R = c_m M u − b − s f^int) happens at
    construction; :meth:`converged` records the residual and checks the stopping test;
    :meth:`newton_update` makes one Newton iteration with line search; :meth:`finish` moves
    the points (G2P). The contact loop (contact/coupling.py) takes :meth:`newton_direction`,
    solves the contacts, adds the impulse changes with :meth:`add_impulses` and moves the
    iterate with :meth:`take_step` along the direction plus :meth:`impulse_move`.
    """

    def __init__(self, stepper: BodyStepper, pts: BodyPoints, gravity: np.ndarray, dt: float,
                 step: int, threads: int | None = None) -> None:
        """``threads``: the run's Numba threads, which set the kernels' point chunks (None:
        the calling thread's; a BodyStep made on a worker of threads.over_bodies, which has
        one, keeps the chunks, and so the sums, of one made on the run's thread)."""
        st = self.settings = stepper.settings
        self.stepper, self.pts, self.dt, self.step = stepper, pts, dt, step
        self._projected = False  # tangent = "auto": switched to projected in this step
        self._mirrored = False  # tangent = "auto": negative modes mirrored in this step
        d = self.d = stepper.lattice.dim
        self.newmark = st.kind == "newmark"
        self.consistent = st.mass_matrix == "consistent"
        stencils = body_stencils(stepper.lattice, stepper.shape_kind, pts.x, stepper.name, step,
                                 stepper.clamps)
        self.box, self.nodes, self.N, self.dN = (stencils.box, stencils.nodes, stencils.N,
                                                 stencils.dN)
        nodes, N, dN = self.nodes, self.N, self.dN
        n_box = self.box.size
        m_I = np.empty(n_box)
        mv_I = np.empty((n_box, d))
        ma_I = np.empty((n_box, d))
        particles_to_grid(nodes, N, pts.mass, pts.v, pts.a, n_box, m_I, mv_I, ma_I)
        active = self.active = np.flatnonzero(m_I > ACTIVE_MASS_FRACTION * pts.mass.max())
        n_act = active.size
        active_row = self.active_row = -np.ones(n_box, dtype=np.int64)
        active_row[active] = np.arange(n_act)
        if restrict_to_active(nodes, N, dN, active_row):
            particles_to_grid(nodes, N, pts.mass, pts.v, pts.a, n_box, m_I, mv_I, ma_I)
        m = self.m = m_I[active][:, None] * np.ones(d)  # lumped mass per dof
        p_n = mv_I[active]  # nodal momentum Σ N m v (= M v^n for either mass matrix)
        q_n = ma_I[active]  # Σ N m a (Newmark)
        self.v_free = p_n / m  # unconstrained lumped velocity: FLIP increments start from it
        v_n = self.v_n = self.v_free.copy()  # lumped estimate (predictor, FLIP)
        a_n = self.a_n = q_n / m if self.newmark else np.zeros_like(v_n)
        fixed, vbar = self.fixed, self.vbar = stepper._dirichlet(self.box, active)
        # whether the internal forces take the momentum form (assembly.momentum_form: no
        # moment about the start nodes, as the θ = 1 step's angular momentum balance
        # needs): stress_form = "momentum", θ = 1, a free body (no prescribed node: a held
        # body's supports take its moment) of objective laws (the linear law's stress is
        # no push-forward)
        self.momentum_form = bool(
            st.momentum_form and not fixed.any() and np.all(pts.law != LINEAR_LAW))
        v_n[fixed] = vbar[fixed]
        a_n[fixed] = 0.0
        if not self.consistent:
            p_n = m * v_n
            q_n = m * a_n
        f_ext = self.f_ext = m * gravity

        self.indptr, self.indices, self.slot, self.diag_slot = block_pattern(
            active_row, self.box.shape, stepper.s)
        self.ptr, self.entries = node_point_map(nodes, active_row, n_act)
        self._bandwidth: int | None = None  # the Newton matrix's lower bandwidth (banded.py)
        self._band_refused = False  # Ā found indefinite this step (banded.py)
        self.n_chunks = CHUNKS_PER_THREAD * (threads or numba.get_num_threads())
        self.Pv = np.empty((nodes.shape[0], d, d))
        self.Av = np.empty((nodes.shape[0], d, d, d, d))
        self.data = np.empty((self.indices.size, d, d))
        self.f_int = np.empty((n_act, d))
        self.u_box = np.zeros((n_box, d))
        self.F_n = pts.F.copy()
        self.vol_n = pts.vol.copy()
        if self.consistent:
            self.m_blocks = np.empty(self.indices.size)
            with threads_for(nodes.shape[0]):
                gather_consistent_mass(self.ptr, self.entries, N, pts.mass, self.slot,
                                       stepper.codes, self.m_blocks)
            self._Mu = np.empty((n_act, d))

        # R(u) = c_m M u − b − s f^int(u) = ∇Π(u),  Π(u) = ½ c_m uᵀMu − b·u + s W(u)
        if (self.newmark or st.theta == 1.0) and self._serial_kernels():
            # f^int(0) is not in the step's equations: the start's strain energy alone, as
            # the serial kernels sum it (the parallel ones sum their chunks in another order)
            f_int_n = None
            self.w_int_n = start_strain_energy(self.F_n, self.vol_n, pts.law, pts.lam,
                                               pts.mu, self.n_chunks)
        else:
            f_int_n, _, self.w_int_n = self.internal_force(np.zeros_like(v_n), False)
        # kinetic energy on the points and on the grid at the start (energy bookkeeping);
        # with the consistent mass the step's grid velocity is M_C⁻¹ p_n, not the lumped v_n
        self.kinetic_points_n = 0.5 * float(np.sum(pts.mass[:, None] * pts.v * pts.v))
        self.v_grid_n = self._consistent_velocity(p_n) if self.consistent else v_n
        self.kinetic_grid_n = 0.5 * float(np.sum(self.v_grid_n * self.mass_times(self.v_grid_n)))
        if self.newmark:  # M a^{n+1} − F^{n+1}
            self.c_m = 1.0 / (st.beta * dt * dt)
            self.s_f = 1.0
            self.b = self.c_m * (dt * p_n + (0.5 - st.beta) * dt * dt * q_n) + f_ext
            u = dt * v_n + 0.5 * dt * dt * a_n
        else:  # M (v^{n+1} − v^n) − Δt[(1−θ)F^n + θF^{n+1}]
            self.c_m = 1.0 / (st.theta * dt)
            self.s_f = st.theta * dt
            self.b = (self.c_m * (1.0 - st.theta) * dt + 1.0) * p_n + dt * (
                st.theta * f_ext if f_int_n is None
                else (1.0 - st.theta) * (f_int_n + f_ext) + st.theta * f_ext)
            u = dt * v_n
        u[fixed] = dt * vbar[fixed]
        self.floor = (RESIDUAL_FLOOR_DISPLACEMENT * stepper.lattice.h * self.c_m
                      * np.linalg.norm(m))
        self.result = BodyStepResult(iterations=0)
        f_int, jmin, w_int = self.internal_force(u, False)
        if jmin <= 0.0:  # the predictor inverts a point: start from rest instead
            u = np.zeros_like(u)
            u[fixed] = dt * vbar[fixed]
            f_int, jmin, w_int = self.internal_force(u, False)
        self.u, self.jmin = u, jmin
        # (u, f^int(u), W(u)) of the iterate's last evaluation, for grid_dissipation
        self._forces_at = (u, f_int, w_int) if jmin > 0.0 else None
        self.r = self.residual(u, f_int)
        self.rnorm = self.r0 = float(np.linalg.norm(self.r))
        # the stopping threshold of the last convergence test (residual_ratio)
        self._threshold = self._stopping_threshold()
        self.pi = self.potential(u, w_int)
        self._A = self._lu = self._v_affine = None  # Newton matrix, its factorization, v(u) map
        self._bsr = None  # the Newton matrix object over self.data (newton_matrix)
        self._A_at = None  # the iterate u (the array) _A was built at
        self._mirrored_at = None  # (u, A⁺) made by mirror_negative_modes at that u
        self._exact = None  # momentum form: the exact (non-symmetric) Newton matrix
        self._stiff_rotation = False  # momentum form: stiffen_rotation was called
        self._relaxed = False  # ... and relax_rotation undid it: not again in this step
        self._rotations = None  # momentum form: the body's RigidRotations (set up once)
        self._rotation_block = None  # ... and their block B in the latest Newton matrix
        self.contact_impulse = np.zeros_like(u)  # Σ P received at each row this step

    # -- the Newton matrix's tangent ---------------------------------------------------
    @property
    def projected(self) -> bool:
        """Whether the Newton matrix uses per-point PSD-projected tangents: always with
        ``tangent = "projected"``, with ``auto`` once :meth:`use_projected_tangent` was
        called in this step (the exact tangent converges quadratically, but under
        compression it can make the Newton matrix indefinite)."""
        return self.settings.tangent == "projected" or self._projected

    def can_project(self) -> bool:
        """Whether :meth:`use_projected_tangent` would switch (``auto``, still exact; with
        the momentum form: its rotation not stiffened yet, nor relaxed in this step)."""
        if self.settings.tangent != "auto" or self._projected:
            return False
        return not (self.momentum_form and (self._stiff_rotation or self._relaxed))

    def use_projected_tangent(self) -> bool:
        """With ``tangent = "auto"``, switch to the projected tangent for the rest of the
        step (the iterate is kept; only the Newton matrix changes); with the momentum form
        :meth:`stiffen_rotation` instead. True if it switched."""
        if self.momentum_form:  # its tangent has no rotational negative mode to project
            return self.stiffen_rotation()
        if not self.can_project():
            return False
        self._projected, self._mirrored = True, False
        self._A = self._lu = None
        return True

    def stiffen_rotation(self) -> bool:
        """With the momentum form and ``tangent = "auto"``: from now on in this step the
        Newton matrix's rigid rotations take the stiffness of rotations.rotation_stiffness
        (the residual, and so the solution, unchanged): the auto tangent's remedy when
        the loop takes many iterations (coupling: since session 50 not after failed
        solves), where the rotations' inertia alone leaves their compliance
        ill-conditioned. The only one: the projected
        tangent made things worse (session 48: 40 iterations without convergence on the
        frictional squeeze). The frictionless D/h 10 squeeze takes 5.2 / 12 coupling
        iterations with it, 7.7 / 47 without. Once stiffened the direction is the
        stiffened matrix's own (:meth:`_momentum_direction`); the loop undoes it
        (:meth:`relax_rotation`) where it does not help (coupling.STIFFENING_TRIAL). True
        if it switched."""
        if not self.momentum_form or not self.can_project():
            return False
        self._stiff_rotation = True
        self._A = self._lu = None
        return True

    def relax_rotation(self) -> bool:
        """Undo :meth:`stiffen_rotation` for the rest of the step: the Newton matrix's
        rotations take their inertia alone again, and :meth:`stiffen_rotation` (the other
        fallbacks' too) refuses from now on (the coupling loop, where the stiffening did not
        help: coupling.STIFFENING_TRIAL). True if they were stiffened."""
        if not self._stiff_rotation:
            return False
        self._stiff_rotation, self._relaxed = False, True
        self._A = self._lu = None
        return True

    def mirror_negative_modes(self) -> bool:
        """With ``tangent = "auto"`` and the exact tangent: from now on in this step, the
        Newton matrix's negative modes are mirrored, A⁺ = A + Σ_{λ<0} 2|λ| M v vᵀ M over
        the eigenpairs A v = λ M v (M the lumped mass): positive definite, and equal to A
        on every other mode, so the bulk keeps Newton's convergence where the projected
        tangent (every compressed point's tangent changed) converges slowly. Only the
        Newton matrix changes, not the residual: the step's solution is the same. False
        where it does not apply: projected or exact tangent, a body above MIRROR_LIMIT
        unknowns (no dense eigensolve), or A without a negative mode."""
        if self.momentum_form:  # no negative rotation mode to mirror: stiffen it instead
            return self.stiffen_rotation()
        if not self.can_project() or self._mirrored or self.u.size > MIRROR_LIMIT:
            return False
        current = self._A is None or self._A_at is self.u
        A = self._A if self._A is not None else self.newton_matrix()
        mirrored = mirrored_negative_modes(A, self.m.ravel())
        if mirrored is None:
            return False
        self._mirrored = True
        self._A = self._lu = None
        # A⁺ of this iterate serves the next direction (the test of an earlier iterate's A
        # does not)
        self._mirrored_at = (self.u, mirrored) if current else None
        return True

    def _matrix(self):
        """The Newton matrix at the iterate: A (sparse), or A⁺ (dense) once mirrored; with
        the momentum form :meth:`_momentum_matrix`'s (never mirrored)."""
        self._A_at = self.u
        if self.momentum_form:
            return self._momentum_matrix()
        if self._mirrored:
            kept, self._mirrored_at = self._mirrored_at, None
            if kept is not None and kept[0] is self.u:
                return kept[1]
            A = self.newton_matrix()
            mirrored = mirrored_negative_modes(A, self.m.ravel())
            return dense(A) if mirrored is None else mirrored
        return self.newton_matrix()

    def _momentum_matrix(self):
        """With the momentum form: the exact (non-symmetric) Newton matrix is kept for the
        direction's defect correction (:attr:`_exact`; unused once the rotation is
        stiffened) and its symmetric form with the
        rigid rotations decoupled (rotations.py) is returned: dense up to DENSE_LIMIT
        unknowns, above as its factorization (:class:`DecoupledSparse`); where the band
        pays (banded.band_pays, also above DENSE_LIMIT for a body as wide as it is tall on
        a 2D grid) and Ā is positive definite, as the factorization of its band and
        rank-2k update (banded.py: against DecoupledSparse, a disk of 2946 unknowns
        (D/h 40) factorised in 5.6 against 36.5 ms and its compliance at 150 sites formed
        in 14 against 67 ms; 10 898 unknowns (D/h 80) 49 against 456 and 125 against
        457 ms)."""
        A = self._exact = self.newton_matrix()
        rotations = self._rigid_rotations()
        block = self._rotation_block = (
            rotation_stiffness(rotations, self.Pv, self.c_m, self.s_f)
            if self._stiff_rotation else self.c_m * rotations.inertia)
        if self._band_applies():
            factorization = banded_decoupled(A, rotations, block, self._lower_bandwidth())
            if factorization is not None:
                return factorization
            self._band_refused = True
        if A.shape[0] > DENSE_LIMIT:
            return DecoupledSparse(A, rotations, block)
        return decoupled_dense(A, rotations, block)

    def _lower_bandwidth(self) -> int:
        """The Newton matrix's lower bandwidth kd (banded.py; once a step)."""
        if self._bandwidth is None:
            self._bandwidth = lower_bandwidth(self.indptr, self.indices, self.d)
        return self._bandwidth

    def _band_applies(self) -> bool:
        """Whether A_s is tried as Ā's band and a rank-2k update (banded.py): where the band
        pays (banded.band_pays: narrow against the unknowns, and above DENSE_LIMIT against
        the body's size too), and Ā was not found indefinite earlier in the step (at
        quasi-static steps it mostly is: the rotation's inertia is tiny against its
        coupling to the strain, ½Kρ)."""
        return not self._band_refused and band_pays(self.u.size, self._lower_bandwidth(),
                                                    self.d, DENSE_LIMIT)

    def _rigid_rotations(self) -> RigidRotations:
        """The body's rigid rotations about its nodal mass centre (set up once a step)."""
        if self._rotations is None:
            positions = self.stepper.lattice.node_positions(self.box, self.active)
            self._rotations = RigidRotations.of(positions, self.m[:, 0],
                                                lambda v: self.mass_times(v).copy())
        return self._rotations

    # -- the step equations ------------------------------------------------------------
    def mass_times(self, u: np.ndarray) -> np.ndarray:
        if not self.consistent:
            return self.m * u
        with threads_for(self.nodes.shape[0]):
            block_scalar_matvec(self.indptr, self.indices, self.m_blocks, u, self._Mu)
        return self._Mu

    def internal_force(self, u: np.ndarray, want_tangent: bool):
        """f^int(u) on the active nodes (and K in ``data`` if want_tangent); min J, W(u)."""
        self.u_box[self.active] = u
        pts = self.pts
        with threads_for(self.nodes.shape[0]):
            jmin, w_int = point_stresses(self.nodes, self.dN, self.u_box, self.F_n,
                                         self.vol_n, pts.law, pts.lam, pts.mu, self.Pv,
                                         self.Av, want_tangent, self.n_chunks, self.projected,
                                         self.momentum_form, dimension(self.d))
            if jmin > 0.0:
                gather_forces(self.ptr, self.entries, self.dN, self.Pv, self.f_int)
                if want_tangent:
                    gather_tangent(self.ptr, self.entries, self.dN, self.Av, self.slot,
                                   self.stepper.codes, self.data)
        return self.f_int.copy(), jmin, w_int

    def residual(self, u: np.ndarray, f_int: np.ndarray) -> np.ndarray:
        r = self.c_m * self.mass_times(u) - self.b - self.s_f * f_int
        r[self.fixed] = 0.0
        return r

    def potential(self, u: np.ndarray, w_int: float) -> float:
        if self.momentum_form:  # not the gradient of a potential: no Π to decrease
            return float("nan")
        return float(0.5 * self.c_m * np.sum(u * self.mass_times(u)) - np.sum(self.b * u)
                     + self.s_f * w_int)

    # -- contact impulses (issue #3) ----------------------------------------------------
    def node_velocity(self, rows: np.ndarray) -> np.ndarray:
        """End-of-step velocity v^{n+1}(u) at active rows, from the current iterate u."""
        kappa, v0 = self.velocity_affine()
        return kappa * self.u[rows] + v0[rows]

    def velocity_affine(self) -> tuple[float, np.ndarray]:
        """v^{n+1} = κ u + v⁰ on the active rows: κ = 1/(θΔt) (θ) or γ/(βΔt) (Newmark)."""
        if self._v_affine is None:
            st, dt = self.settings, self.dt
            if self.newmark:
                kappa = st.gamma * dt * self.c_m
                v0 = (self.v_n + dt * (1.0 - st.gamma) * self.a_n
                      - kappa * dt * self.v_n - st.gamma * dt * (0.5 / st.beta - 1.0) * self.a_n)
            else:
                kappa = 1.0 / (st.theta * dt)
                v0 = -(1.0 - st.theta) / st.theta * self.v_n
            self._v_affine = (kappa, v0)
        return self._v_affine

    def contact_response(self, rows: np.ndarray, delassus: bool,
                         sites: sp.spmatrix | None = None
                         ) -> tuple[ImpulseResponse | None, np.ndarray]:
        """The impulse-to-iterate map X = w A⁻¹ E (or None for the lumped relation) and the
        local compliance W = κ w [A⁻¹]_cc (ALGORITHM.md §6) at the active ``rows``; with
        ``sites`` H (sites d × k d, Delassus), at the sites v_s = H v_rows instead:
        X = w A⁻¹ E Hᵀ and W = κ H X_rows, one column per site component (a grain's
        point sites are fewer than the node rows their stencils reach: 166 against 222
        components in the dense compaction). With G = E Hᵀ and A = L Lᵀ (Cholesky, A
        positive definite) W = κ w (L⁻¹G)ᵀ(L⁻¹G), and X is applied by solves, not formed.

        W is (k d × k d), symmetric, rows and columns ordered (row, component); lumped:
        diag(1/m). Fixed (Dirichlet) dofs take no impulse: their columns and rows are zero.
        """
        d, k = self.d, rows.size
        kappa, _ = self.velocity_affine()
        w = self.impulse_weight
        dofs = (rows[:, None] * d + np.arange(d)).ravel()
        free = ~self.fixed.ravel()
        if not delassus:
            W = np.diag(1.0 / self.m[rows].ravel() * free[dofs])
            return None, W
        # (Fortran order: the solves' right-hand sides are copied from it as they are)
        if sites is None:
            E = np.zeros((self.u.size, k * d), order="F")
            E[dofs, np.arange(k * d)] = free[dofs]
        else:
            E = np.empty((self.u.size, sites.shape[0]), order="F")
            H = sites.tocsr()
            site_columns(dofs, H.indptr, H.indices, H.data, free, E)
        factorization = self.factorization()
        if isinstance(factorization, (DenseCholesky, BandedDecoupled)):
            W = factorization.compliance(E, kappa * w)
            return ImpulseResponse(w, factorization, E, free), W
        X = factorization.solve(E) * w
        X[~free] = 0.0
        W = kappa * X[dofs] if sites is None else kappa * (sites @ X[dofs])
        # A's free block is symmetric (the Hessian of the step's potential, its mirrored or
        # projected forms too), so W is; made so exactly (the LU solves leave ~1e-12) for
        # the contact solvers' products by block rows (delassus.product)
        return ImpulseResponse(w, factorization, E, free, X), 0.5 * (W + W.T)

    def rigid_modes(self, rows: np.ndarray, sites: sp.spmatrix | None = None) -> np.ndarray:
        """G (k, d, d + r): the body's rigid modes of inertia alone at its contact sites
        (``sites`` H as in :meth:`contact_response`; None: the rows themselves), scaled so
        that G_c G_c'ᵀ is their share of the compliance block W_cc' (Delassus). A mode g with
        A g = λ M g is a term g gᵀ/(λ gᵀMg) of A⁻¹, so its share is
        κ w (H_c g)(H_c' g)ᵀ/(λ gᵀMg). The translations are such modes of every free body
        (K g = 0, λ = c_m; κ w/(c_m m) = 1/m: an impulse's velocity of the whole mass); with
        the momentum form so are the r rigid rotations (rotations.py; λ gᵀMg their block B
        in the Newton matrix last built, so call it after :meth:`contact_response`; before
        any, their columns are zero). Columns of zeros where a mode does not apply; all zero
        for a body with a prescribed dof (no rigid mode). At quasi-static steps these modes
        carry nearly all of W_cc (a free disk squeezed at Δt c/h 3000: all but 2e-5)."""
        d = self.d
        k = rows.size if sites is None else sites.shape[0] // d
        G = np.zeros((k, d, RIGID_MODES[d]))
        if self.fixed.any():
            return G
        kappa, _ = self.velocity_affine()
        scale = kappa * self.impulse_weight
        translations = np.tile(np.eye(d), (rows.size, 1))  # (rows d, d): g_a at the rows
        at_sites = translations if sites is None else sparse_times(sites, translations)
        G[:, :, :d] = at_sites.reshape(k, d, d) * np.sqrt(scale / (self.c_m * self.m[:, 0].sum()))
        if self.momentum_form and self._rotation_block is not None:
            dofs = (rows[:, None] * d + np.arange(d)).ravel()
            R = self._rotations.fields[dofs]
            at_sites = (R if sites is None else sparse_times(sites, R)).reshape(
                k, d, RIGID_MODES[d] - d)
            root = np.linalg.cholesky(np.linalg.inv(self._rotation_block))
            G[:, :, d:] = np.sqrt(scale) * at_sites @ root
        return G

    def factorization(self):
        """The factorization of the current Newton matrix A (Cholesky where A is positive
        definite, else LU; reused from a direct Newton solve)."""
        if self._lu is None:
            if self._A is None:
                self._A = self._matrix()
            self._lu = (symmetric_factorization(self._A) if self.momentum_form
                        else factorize(self._A))
        return self._lu

    # -- Newton ------------------------------------------------------------------------
    @property
    def impulse_weight(self) -> float:
        """How an impulse enters the residual: P (θ-scheme) or P/(γΔt) (Newmark)."""
        return 1.0 / (self.settings.gamma * self.dt) if self.newmark else 1.0

    def converged(self, limit: bool = True, floor: float = 0.0) -> bool:
        """Record the current residual; True when it passes the stopping test.

        Raises SimulationError on a non-finite residual, an inverted point or (when
        ``limit``) more than newton_max_iterations iterations; the contact loop bounds the
        iterations itself (limit=False) and may allow a coarser residual ``floor``.
        """
        res, st, name, step = self.result, self.settings, self.stepper.name, self.step
        if self.jmin <= 0.0:
            p, J = self.worst_point(self.u)
            raise SimulationError(
                f"step {step}: Newton of body '{name}' produced an inverted point (J ≤ 0) at "
                f"iteration {res.iterations}: point {p} (at {_where(self.pts.x[p])}, J = "
                f"{J:.3g}); try a smaller dt or a finer grid.", kind="inverted", step=step,
                body=name, point=p, residuals=res.residuals + [self.rnorm])
        if not np.isfinite(self.rnorm):
            bad = ~np.isfinite(self.r).all(axis=1)
            node, p = self._node_and_point(int(np.argmax(bad)))
            raise SimulationError(
                f"step {step}: Newton of body '{name}' produced a non-finite residual (NaN or "
                f"Inf) at iteration {res.iterations}, first at the node at {_where(node)} "
                f"(nearest point {p}); check the case for absurd values (gravity, material "
                "constants, velocities) or try a smaller dt.", kind="nan", step=step,
                body=name, point=p, residuals=res.residuals + [self.rnorm])
        res.residuals.append(self.rnorm)
        if self.residual_ratio(floor) <= 1.0:
            return True
        if limit and res.iterations >= st.max_iterations:
            node, p = self._node_and_point(int(np.argmax(np.abs(self.r).max(axis=1))))
            raise SimulationError(
                f"step {step}: Newton of body '{name}' did not converge in "
                f"{st.max_iterations} iterations (residual {self.rnorm:.3e}, first "
                f"{self.r0:.3e}; largest at the node at {_where(node)}, nearest point {p}); "
                "try a smaller dt, more newton_max_iterations or a looser newton_tolerance.",
                kind="newton", step=step, body=name, point=p, residuals=res.residuals)
        return False

    def residual_ratio(self, floor: float = 0.0) -> float:
        """‖R‖ over the stopping threshold max(tol ‖R_0‖, the round-off floor, ``floor``):
        ≤ 1 when converged."""
        self._threshold = self._stopping_threshold(floor)
        return self.rnorm / self._threshold

    def _stopping_threshold(self, floor: float = 0.0) -> float:
        """max(tol ‖R_0‖, the round-off floor, ``floor``)."""
        return max(self.settings.tolerance * self.r0, self.floor, floor, 1e-300)

    def _node_and_point(self, row: int) -> tuple[np.ndarray, int]:
        """Position of active ``row``'s node and the body's point nearest to it."""
        node = self.stepper.lattice.node_positions(self.box, self.active[row:row + 1])[0]
        return node, int(np.argmin(np.sum((self.pts.x - node) ** 2, axis=1)))

    def worst_point(self, u: np.ndarray) -> tuple[int, float]:
        """(index in the body, J) of the point with the smallest or a non-finite J at the
        iterate u: where a failure is (diagnosis only, plain NumPy)."""
        self.u_box[self.active] = u
        grad = np.einsum("pki,pkj->pij", self.u_box[self.nodes], self.dN)
        J = np.linalg.det((np.eye(self.d) + grad) @ self.F_n)
        bad = np.flatnonzero(~np.isfinite(J))
        p = int(bad[0]) if bad.size else int(np.argmin(J))
        return p, float(J[p])

    def solve(self) -> None:
        """Newton iterations without contact, until converged (or a SimulationError); with
        ``tangent = "auto"`` the second half of the iterations uses the projected tangent
        (not with the momentum form: it has no negative rotation mode to cure, and its
        stiffened rotation, a remedy for the contacts' compliance, would leave a free
        body's torque residual to the inertia's ratio c_m I/B alone)."""
        while not self.converged():
            if (self.result.iterations >= self.settings.max_iterations // 2
                    and not self.momentum_form):
                self.use_projected_tangent()
            self.newton_update()

    def newton_matrix(self) -> sp.bsr_matrix:
        """A = c_m M + s K_T(u) at the current iterate, Dirichlet rows and columns unit (one
        matrix object over the step's tangent array: the next call overwrites its values)."""
        self.internal_force(self.u, True)
        data = self.data
        if self.s_f != 1.0:
            data *= self.s_f
        if self.consistent:
            add_block_mass(data, self.m_blocks, self.c_m)
        else:
            add_diagonal(data, self.diag_slot, (self.m * self.c_m).ravel())
        constrain(data, self.indptr, self.indices, self.fixed.ravel())
        if self._bsr is None:
            # one matrix object over ``data`` for the step (its pattern does not change;
            # SciPy's checks on construction were ~2% of a compaction run, session 35): the
            # matrix returned is the latest one built
            size = self.u.size
            self._bsr = sp.bsr_matrix((data, self.indices, self.indptr), shape=(size, size))
        return self._bsr

    def newton_update(self) -> None:
        """One Newton iteration: tangent, linear solve, line search (with ``tangent =
        "auto"``, see :meth:`newton_direction` and :meth:`take_step`)."""
        self.take_step(self.newton_direction())

    def newton_direction(self, direct: bool = False) -> np.ndarray:
        """du = −A⁻¹ R(u) with the Newton matrix at the iterate (its factorization is kept
        for the contact response; ``direct`` asks for a direct factorization, not CG). With
        ``tangent = "auto"`` a failed exact-tangent solve is made again with the projected
        tangent, which stays for the rest of the step."""
        try:
            return self._direction(direct)
        except SimulationError:
            if not self.use_projected_tangent():
                raise
            return self._direction(direct)

    def _direction(self, direct: bool) -> np.ndarray:
        if self.momentum_form:
            du = self._dense_momentum_direction()
            if du is not None:
                return du
        A = self._A = self._matrix()
        solver, res = self.stepper.solver, self.result
        if self.momentum_form:
            return self._momentum_direction(A)
        try:
            du = solver.solve(A, -self.r.ravel(), self.diag_slot, direct).reshape(self.u.shape)
        except (np.linalg.LinAlgError, RuntimeError) as err:
            raise self._solve_failed(err) from err
        self._lu = solver.last_factorization
        res.linear_method = solver.last_method
        res.linear_iterations += solver.last_iterations
        return du

    def _momentum_direction(self, A) -> np.ndarray:
        """du = −A⁻¹R with the exact Newton matrix of the momentum form, by defect
        correction from its decoupled symmetric form A (rotations.py), whose
        factorization is kept for the contacts' compliance; once the rotation is stiffened
        (:meth:`stiffen_rotation`) du = −A_s⁻¹R with that form itself.

        Why not corrected then: the contacts' compliance and the response to their
        impulses come from A_s, whose stiffened rotation the correction (its ratio
        1 − c_m I/B ≈ 1 along the rotation) would only partly undo in the direction. The
        loop's operators then disagreed on the rotation, and its steps alternated in sign
        and grew ×1.7 an iteration until the motion limit stopped the step (the
        frictional D/h 10 squeeze retried a step at 0.1 and at 0.05 h a step, at Δt/16;
        session 52). With the stiffened form alone they agree and the loop converges,
        linearly in the rotation: no step retried on the squeeze grid."""
        res, rhs = self.result, -self.r.ravel()
        try:
            self._lu = symmetric_factorization(A)
            du = self._lu.solve(rhs)
            corrections = 0
            if not self._stiff_rotation:
                du, corrections = corrected_solve(self._exact, self._lu, rhs, du)
        except (np.linalg.LinAlgError, RuntimeError) as err:
            raise self._solve_failed(err) from err
        res.linear_method = "direct"
        res.linear_iterations += 1 + corrections
        return du.reshape(self.u.shape)

    def _dense_momentum_direction(self) -> np.ndarray | None:
        """:meth:`_momentum_direction`'s du for a body up to DENSE_LIMIT unknowns whose
        rotation is not stiffened, in one call that releases the GIL: A_s factorised as
        Ā's band and a rank-2k update where the band pays (banded.band_pays) and Ā is
        positive definite (dense_direction.banded_momentum_direction, banded.py: 0.40
        against 0.61 ms a grain of the dense compaction at D/h 10), else dense
        (dense_direction.momentum_direction: the general path's kernels in the same
        order); None where it does not apply, A_s is not positive definite or the iterate
        inverts a point (the general path then)."""
        n = self.u.size
        if self._stiff_rotation or n > DENSE_LIMIT or not self._in_one_call():
            return None
        rotations = self._rigid_rotations()
        block = self.c_m * rotations.inertia
        self.u_box[self.active] = self.u
        points = self._point_tangents(tangent=True)
        pattern = NewtonPattern(self.ptr, self.entries, self.slot, self.stepper.codes,
                                self.indptr, self.indices, self.diag_slot, self.data)
        terms = StepTerms(float(self.s_f), float(self.c_m), self.consistent,
                          (self.m * self.c_m).ravel(),
                          self.m_blocks if self.consistent else np.empty(0),
                          self.fixed.ravel())
        rotation_terms = Rotations(rotations.fields, rotations.dual, block)
        du, outcome = np.empty(n), INDEFINITE
        if self._band_applies():
            # A_s as Ā's band and a rank-2k update (banded.py), where Ā is positive definite
            factors = BandedDecoupled.workspace(n, self._lower_bandwidth(),
                                                rotations.fields.shape[1])
            outcome, corrections = banded_momentum_direction(
                lapack.DPBTRF, lapack.DPBTRS, points, pattern, terms, rotation_terms,
                -self.r.ravel(), factors, du)
            factorization = BandedDecoupled(*factors)
            self._band_refused = outcome == INDEFINITE
        if outcome == INDEFINITE:
            lower = np.empty((n, n), order="F")
            outcome, corrections = momentum_direction(
                lapack.DPOTRF, lapack.DPOTRS, points, pattern, terms, rotation_terms,
                -self.r.ravel(), np.empty((n, n)), lower, du)
            factorization = DenseCholesky(lower)
        if outcome != DONE:
            return None
        self._A_at, self._A, self._exact = self.u, None, None
        self._rotation_block = block
        self._lu = factorization
        res = self.result
        res.linear_method = "direct"
        res.linear_iterations += 1 + corrections
        return du.reshape(self.u.shape)

    def _solve_failed(self, err: Exception) -> SimulationError:
        """The diagnosis of a failed linear solve of the Newton system."""
        res = self.result
        return SimulationError(
            f"step {self.step}: linear solve of body '{self.stepper.name}' failed at "
            f"Newton iteration {res.iterations}: {err}", step=self.step,
            body=self.stepper.name, residuals=res.residuals)

    def take_step(self, du: np.ndarray) -> None:
        """u ← u + α du by the line search (one Newton iteration). With ``tangent = "auto"``,
        when every trial inverts a point (an indefinite exact-tangent Newton matrix under
        compression), the iterate stays and the projected tangent is used from here on."""
        self.result.iterations += 1
        before = (self.u, self.r, self.rnorm, self.jmin, self.pi, self._forces_at)
        if self._in_one_call():
            self.u, self.r, self.rnorm, self.jmin, f_int, w_int = self._momentum_line_search(du)
            self._forces_at = ((self.u, f_int, w_int)
                               if self.jmin > 0.0 and np.isfinite(self.rnorm) else None)
        else:
            self.u, _, self.r, self.rnorm, self.jmin, self.pi = line_search(
                self.u, du, self.r, self.pi, self.internal_force, self.residual,
                self.potential, self._threshold)
            self._forces_at = None
        if self.jmin <= 0.0 and self.use_projected_tangent():
            self.u, self.r, self.rnorm, self.jmin, self.pi, self._forces_at = before

    def _in_one_call(self) -> bool:
        """Whether the momentum form's per-body chains of kernels run as one call
        (dense_direction.py, momentum_line_search.py): with the momentum form, on serial
        kernels, so not for a body that the calling thread's parallel kernels share
        (threads.threads_for)."""
        return self.momentum_form and self._serial_kernels()

    def _serial_kernels(self) -> bool:
        """Whether the body's kernels run serial on the calling thread (threads.threads_for:
        fewer than PARALLEL_MIN_POINTS points, or one Numba thread)."""
        return self.nodes.shape[0] < PARALLEL_MIN_POINTS or numba.get_num_threads() == 1

    def _point_tangents(self, tangent: bool) -> PointTangents:
        """The body's points as the one-call kernels take them (momentum form; with or
        without the tangent)."""
        pts = self.pts
        return PointTangents(self.nodes, self.dN, self.u_box, self.F_n, self.vol_n, pts.law,
                             pts.lam, pts.mu, self.Pv, self.Av, self.n_chunks, self.projected,
                             tangent, True, dimension(self.d))

    def _momentum_line_search(self, du: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray, float, float, np.ndarray,
                                         float]:
        """:func:`line_search` for the momentum form (no potential: the residual decides)
        in one call that releases the GIL (momentum_line_search.py): (u, R, ‖R‖, min J,
        f^int, W) of the trial taken."""
        points = self._point_tangents(tangent=False)
        empty_int = np.empty(0, np.int64)
        terms = ResidualTerms(
            float(self.c_m), float(self.s_f), self.b, self.fixed, self.consistent, self.m,
            self.indptr if self.consistent else empty_int,
            self.indices if self.consistent else empty_int,
            self.m_blocks if self.consistent else np.empty(0), self.active, self.ptr,
            self.entries)
        u, r, f_int = np.empty_like(self.u), np.empty_like(self.u), np.empty_like(self.u)
        rnorm, jmin, w_int = residual_line_search(points, terms, self.u, du, self.r,
                                                  float(self._threshold), MAX_LINE_SEARCH,
                                                  self.f_int, u, r, f_int)
        return u, r, float(rnorm), float(jmin), f_int, float(w_int)

    def add_impulses(self, rows: np.ndarray | slice, Q: np.ndarray) -> None:
        """Add impulse changes Q (k, d) at distinct active ``rows`` (a slice: all) to b
        (−P in R for θ, −P/(γΔt) for Newmark); R and Π are affine in b, so they follow
        without a new evaluation of the internal force."""
        w = self.impulse_weight
        self.b[rows] += w * Q
        self.contact_impulse[rows] += Q
        self.r[rows] -= w * Q
        self.r[self.fixed] = 0.0
        self.rnorm = float(np.linalg.norm(self.r))
        self.pi -= float(np.sum(w * Q * self.u[rows]))

    def impulse_move(self, rows: np.ndarray, Q: np.ndarray,
                     response: ImpulseResponse | None) -> np.ndarray:
        """Δu caused by impulse changes Q at ``rows``: X Q with the response X = w A⁻¹ E of
        :meth:`contact_response` (Delassus; Q then at the sites where X is theirs), or
        w Q/(c_m m) at the rows alone (lumped)."""
        if response is not None:
            return response.move(Q.ravel()).reshape(self.u.shape)
        move = np.zeros_like(self.u)
        move[rows] = self.impulse_weight * Q / (self.c_m * self.m[rows])
        move[self.fixed] = 0.0
        return move

    # -- energy bookkeeping --------------------------------------------------------------
    def _consistent_velocity(self, p: np.ndarray) -> np.ndarray:
        """v = M_C⁻¹ p by conjugate gradients, preconditioned by the lumped mass (the row
        sums of M_C): M_C is symmetric positive definite, but with B-splines the nodes in
        the tails of the stencils carry tiny masses, and plain CG did not reach 1e-12 in
        500 iterations (session 10: the consistent-mass invariants test warned at every
        step); scaled by the lumped mass it converges."""
        n = p.size
        op = spla.LinearOperator((n, n), dtype=float, matvec=lambda x: self.mass_times(
            x.reshape(p.shape)).ravel().copy())
        lumped = np.broadcast_to(self.m, p.shape).ravel()
        jacobi = spla.LinearOperator((n, n), dtype=float, matvec=lambda x: x / lumped)
        v, info = spla.cg(op, p.ravel(), rtol=1e-12, atol=0.0, maxiter=500, M=jacobi)
        if info != 0:
            warnings.warn(f"step {self.step}: body '{self.stepper.name}': M_C v = p did not "
                          "converge; its integrator/transfer energy columns are approximate",
                          RuntimeWarning, stacklevel=2)
        return v.reshape(p.shape)

    def grid_dissipation(self) -> float:
        """Energy the grid update takes out of the body over the step, from the converged u:
            D = W_g + W_P + W_D − ΔK_grid − ΔW,
        W_g = (M g)·u the work of gravity, W_P = P·u/Δt that of the contact impulses, W_D
        that of the reactions at prescribed nodes (R of those rows, as impulses), K_grid =
        ½ vᵀMv at the start (v^n) and at the end (v^{n+1}) of the step, W the strain energy
        Σ V⁰ W(F). For the θ-scheme it is
            D = (θ − ½) ΔvᵀMΔv − (f_θ·u + ΔW),   f_θ = (1 − θ) f^int_n + θ f^int(u):
        the scheme's numerical damping plus the gap between the internal forces' work and
        the strain energy over the step (0 for θ = ½ and a quadratic energy; ≥ 0 for θ = 1
        and a convex one). Tests: tests/validation/test_energy.py."""
        u, dt = self.u, self.dt
        if self._forces_at is not None and self._forces_at[0] is u:  # the line search's
            _, f_int, w_int = self._forces_at
        else:
            f_int, _, w_int = self.internal_force(u, False)
        reaction = self.c_m * self.mass_times(u) - self.b - self.s_f * f_int
        if self.consistent:  # θ only: v^{n+1} = (u/Δt − (1 − θ) v^n)/θ with v^n = M_C⁻¹ p_n
            theta = self.settings.theta
            v1 = (u / dt - (1.0 - theta) * self.v_grid_n) / theta
        else:
            v1 = self.node_velocity(np.arange(u.shape[0]))
        kinetic_grid = 0.5 * float(np.sum(v1 * self.mass_times(v1)))
        prescribed = float(np.sum(reaction[self.fixed] * u[self.fixed])) / (
            self.impulse_weight * dt)
        work = (float(np.sum(self.f_ext * u)) + float(np.sum(self.contact_impulse * u)) / dt
                + prescribed)
        self._kinetic_grid = kinetic_grid
        self.result.prescribed_work = prescribed
        return work - (kinetic_grid - self.kinetic_grid_n) - (w_int - self.w_int_n)

    # -- G2P ---------------------------------------------------------------------------
    def finish(self) -> BodyStepResult:
        """Move the points with the converged solution (G2P) and return the diagnostics,
        with the energy the grid update and the transfers took out (the transfers: the
        points' kinetic energy minus the grid's at the start, the grid's minus the points'
        at the end; ≥ 0 for PIC)."""
        self.result.integrator_dissipation = self.grid_dissipation()
        st, d, dt, u, active = self.settings, self.d, self.dt, self.u, self.active
        n_box = self.box.size
        u_box = np.zeros((n_box, d))
        u_box[active] = u
        v_old = np.zeros((n_box, d))
        v_new = np.zeros((n_box, d))
        a_new = np.zeros((n_box, d))
        if self.consistent:
            update = UPDATE_PARTICLE_NEWMARK if self.newmark else UPDATE_PARTICLE_THETA
        else:
            update = UPDATE_FLIP_NEWMARK if self.newmark else UPDATE_FLIP_THETA
            if self.newmark:
                a1 = self.c_m * (u - dt * self.v_n) - (0.5 / st.beta - 1.0) * self.a_n
                # the contact impulse changes the velocity (P/m) but is not kept in the stored
                # acceleration: there it would replay the impact in the next step (a node
                # striking a wall rebounded at 0.8 of its speed; ALGORITHM.md §3, §5)
                a_new[active] = a1 - self.contact_impulse / (st.gamma * dt * self.m)
            v_old[active] = self.v_free  # so that fixed nodes pass their velocity on
            v_new[active] = self.node_velocity(np.arange(u.shape[0]))
        params = np.array([dt, st.flip, st.theta, st.beta, st.gamma])
        pts = self.pts
        with threads_for(self.nodes.shape[0]):
            jmin = grid_to_particles(self.nodes, self.N, self.dN, u_box, v_old, v_new, a_new,
                                     update, params, pts.law, pts.lam, pts.mu, pts.vol0,
                                     pts.x, pts.v, pts.a, pts.F, pts.sigma, pts.vol,
                                     self.n_chunks)
        if not jmin > 0.0:
            J = np.linalg.det(pts.F)
            bad = np.flatnonzero(~(J > 0.0))
            p = int(bad[np.argmin(np.nan_to_num(J[bad], nan=-np.inf))]) if bad.size else 0
            raise SimulationError(
                f"step {self.step}: body '{self.stepper.name}' has an inverted point "
                f"after the step: point {p} (at {_where(pts.x[p])}, J = {J[p]:.3e}); try a "
                "smaller dt or a finer grid.",
                kind="inverted", step=self.step, body=self.stepper.name, point=p)
        kinetic_points = 0.5 * float(np.sum(pts.mass[:, None] * pts.v * pts.v))
        self.result.transfer_dissipation = (self.kinetic_points_n - self.kinetic_grid_n
                                            + self._kinetic_grid - kinetic_points)
        return self.result


def _where(x: np.ndarray) -> str:
    """A position for a message: (0.0123, 0.0456)."""
    return "(" + ", ".join(f"{c:.6g}" for c in np.asarray(x, float)) + ")"

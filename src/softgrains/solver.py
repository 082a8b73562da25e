"""One time step of the whole model (ALGORITHM.md §3–7).

Deformable bodies take an implicit Newton step each, coupled through contact by the
Gauss–Seidel loop of §6 (contact/coupling.py) when [contact] is enabled and there are two
bodies or more; kinematic bodies move rigidly at their prescribed velocity. The solver never
prints and never writes files.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
from threadpoolctl import threadpool_limits

from softgrains.contact.coupling import (
    ContactDiagnostics,
    ContactState,
    CouplingSettings,
    solve_coupled,
)
from softgrains.contact.detection import nodal_field
from softgrains.geometry import translated
from softgrains.grid.shape_functions import stencil_width
from softgrains.grid.stencils import BodyStencils, body_stencils
from softgrains.integrator.implicit import BodyPoints, BodyStep, BodyStepper, BodyStepResult
from softgrains.model import Model, State
from softgrains.threads import over_bodies


@dataclass
class StepDiagnostics:
    """What one step did: Newton iterations (max over bodies) and per-body details."""

    newton_iterations: int = 0
    bodies: dict[str, BodyStepResult] = field(default_factory=dict)
    contact: ContactDiagnostics = field(default_factory=ContactDiagnostics)
    contacts: ContactState | None = None

    def contact_forces(self, n_bodies: int, dim: int, dt: float) -> np.ndarray:
        """Total contact force each body received over the step: Σ ±P/Δt (B, d)."""
        forces = np.zeros((n_bodies, dim))
        if self.contacts is not None and len(self.contacts.nodes):
            c = self.contacts
            np.add.at(forces, c.nodes.alpha, c.impulse / dt)
            np.add.at(forces, c.nodes.beta, -c.impulse / dt)
        return forces

    @property
    def linear_method(self) -> str:
        return ",".join(sorted({r.linear_method for r in self.bodies.values() if r.linear_method}))


class Solver:
    """Implicit MPM solver over all bodies of a Model."""

    def __init__(self, model: Model, motion_limit: float = 0.0) -> None:
        """``motion_limit``: the farthest a point may move in a step (length; 0: unbounded),
        within which the coupling loop keeps the bodies' iterates."""
        self.model = model
        # Our BLAS calls are small vector operations; a multi-threaded BLAS spinning beside the
        # Numba threads slowed a 20k-point step five-fold (docs/dev-notes.md).
        self._blas_limit = threadpool_limits(limits=1, user_api="blas")
        self.steppers = {
            b.index: BodyStepper(b.name, model.lattice, model.shape_kind, model.integrator,
                                 model.constraints.get(b.index, []))
            for b in model.bodies if b.deformable
        }
        c = model.contact
        self.coupling = CouplingSettings() if c is None else CouplingSettings(
            relation=c.local_relation, tolerance=c.tolerance, max_iterations=c.max_iterations,
            on_failure=c.on_failure, normal=c.normal, overlap_removal=c.overlap_removal,
            overlap_tolerance=c.overlap_tolerance, keep_closed=c.keep_closed, solver=c.solver,
            solver_iterations=c.solver_iterations, grain_sites=c.grain_sites,
            grain_passes=c.grain_passes,
            wall_sites=c.wall_sites, end_gap_check=c.end_gap_check, motion_limit=motion_limit)

    def body_points(self, state: State, index: int) -> BodyPoints:
        m, sl = self.model, self.model.bodies[index].points
        return BodyPoints(x=state.x[sl], v=state.v[sl], a=state.a[sl], F=state.F[sl],
                          sigma=state.sigma[sl], vol=state.vol[sl], mass=m.mass[sl],
                          vol0=m.vol0[sl], law=m.law[sl], lam=m.lam[sl], mu=m.mu[sl])

    def step(self, state: State, dt: float, cutoff: float | None = None) -> StepDiagnostics:
        """Advance the state by dt in place (bodies coupled by contact when enabled);
        ``cutoff``: the farthest gap at which a point contact is taken (None: the kernel's
        reach)."""
        model = self.model
        diag = StepDiagnostics()
        deformable = [b.index for b in model.bodies if b.deformable]
        threads = numba.get_num_threads()
        # each body's set-up (stencils, P2G, pattern; kernels that release the GIL) and,
        # below, its G2P on the run's threads
        steps = dict(zip(deformable, over_bodies(
            lambda i: BodyStep(self.steppers[i], self.body_points(state, i), model.gravity,
                               dt, state.step, threads), deformable), strict=True))
        contact = model.contact
        if contact is not None and contact.enabled and len(model.bodies) > 1:
            fields = []
            for b in model.bodies:
                if b.deformable:
                    s = steps[b.index]
                    stencils = BodyStencils(s.box, s.nodes, s.N, s.dN)
                else:
                    stencils = body_stencils(model.lattice, model.shape_kind,
                                             state.x[b.points], b.name, state.step)
                fields.append(nodal_field(b.index, stencils, model.mass[b.points]))
            walls = {b.index: (state.body_velocity[b.index],
                               translated(b.shape, state.body_offset[b.index]))
                     for b in model.bodies if not b.deformable}
            diag.contacts, diag.contact = solve_coupled(
                model.lattice, steps, fields, walls, self.coupling,
                lambda a, b: model.friction[a, b], state.step, dt,
                gap_points={b.index: state.x[b.points] for b in model.bodies}
                if contact.gap else None,
                spacing=model.lattice.h / model.points_per_cell,
                reach=0.5 * stencil_width(model.shape_kind) * model.lattice.h
                * np.sqrt(model.dim), cutoff=cutoff, warm=state.contacts,
                names=[b.name for b in model.bodies],
                round_bodies={b.index for b in model.bodies if b.seeding == "rings"})
            state.contacts = diag.contacts
        else:
            for s in steps.values():
                s.solve()
        finished = dict(zip(deformable, over_bodies(lambda i: steps[i].finish(), deformable),
                            strict=True))
        for body in model.bodies:
            if body.deformable:
                res = finished[body.index]
                diag.bodies[body.name] = res
                diag.newton_iterations = max(diag.newton_iterations, res.iterations)
            else:
                vel = state.body_velocity[body.index]
                state.x[body.points] += dt * vel
                state.v[body.points] = vel
                state.body_offset[body.index] += dt * vel
        state.time += dt
        state.step += 1
        return diag


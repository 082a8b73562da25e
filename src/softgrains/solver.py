"""One time step of the whole model (ALGORITHM.md §3, §7): every body independently.

Deformable bodies take an implicit Newton step each (bodies do not interact yet: the contact
issue adds the Gauss–Seidel coupling of §6); kinematic bodies move rigidly at their
prescribed velocity. The solver never prints and never writes files.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from threadpoolctl import threadpool_limits

from softgrains.integrator.implicit import BodyPoints, BodyStepper, BodyStepResult
from softgrains.model import Model, State


@dataclass
class StepDiagnostics:
    """What one step did: Newton iterations (max over bodies) and per-body details."""

    newton_iterations: int = 0
    bodies: dict[str, BodyStepResult] = field(default_factory=dict)

    @property
    def linear_method(self) -> str:
        return ",".join(sorted({r.linear_method for r in self.bodies.values() if r.linear_method}))


class Solver:
    """Implicit MPM solver over all bodies of a Model."""

    def __init__(self, model: Model) -> None:
        self.model = model
        # Our BLAS calls are small vector operations; a multi-threaded BLAS spinning beside the
        # Numba threads slowed a 20k-point step five-fold (docs/dev-notes.md).
        self._blas_limit = threadpool_limits(limits=1, user_api="blas")
        self.steppers = {
            b.index: BodyStepper(b.name, model.lattice, model.shape_kind, model.integrator,
                                 model.constraints.get(b.index, []))
            for b in model.bodies if b.deformable
        }

    def body_points(self, state: State, index: int) -> BodyPoints:
        m, sl = self.model, self.model.bodies[index].points
        return BodyPoints(x=state.x[sl], v=state.v[sl], a=state.a[sl], F=state.F[sl],
                          sigma=state.sigma[sl], vol=state.vol[sl], mass=m.mass[sl],
                          vol0=m.vol0[sl], law=m.law[sl], lam=m.lam[sl], mu=m.mu[sl])

    def step(self, state: State, dt: float) -> StepDiagnostics:
        """Advance the state by dt in place."""
        diag = StepDiagnostics()
        for body in self.model.bodies:
            if body.deformable:
                res = self.steppers[body.index].step(
                    self.body_points(state, body.index), self.model.gravity, dt, state.step)
                diag.bodies[body.name] = res
                diag.newton_iterations = max(diag.newton_iterations, res.iterations)
            else:
                vel = state.body_velocity[body.index]
                state.x[body.points] += dt * vel
                state.v[body.points] = vel
        state.time += dt
        state.step += 1
        return diag


"""Simulation: Model + State + Solver, the run loop and its observers (ARCHITECTURE.md).

Outputs (INTERFACE.md): case.toml (resolved), series.csv, bodies.csv, snapshots/ (VTK + .pvd),
summary.json, run.log, checkpoint.h5; rows are flushed as they are written. A
SimulationError stops the run with a diagnosis in run.log and summary.json (status "failed")
and is re-raised (exit 3); the last good checkpoint stays. SIGINT/SIGTERM stop the run
between two steps with a final checkpoint (status "interrupted"). ``run(resume=True)``
continues from ``checkpoint.h5`` (checkpointing.py, docs/reliability.md).
"""

from __future__ import annotations

import math
import re
import time as _time
from pathlib import Path

import numba
import numpy as np

from softgrains import checkpointing
from softgrains.case import case_to_toml
from softgrains.errors import CaseError, SimulationError
from softgrains.interrupt import StopRequest
from softgrains.io import (
    CHECKPOINT_NAME,
    CsvTable,
    Progress,
    PvdSeries,
    close_run_log,
    open_run_log,
    peak_memory_mib,
    read_checkpoint,
    read_pvd,
    software_versions,
    truncate_after_step,
    write_checkpoint,
    write_json_atomic,
    write_points_vtu,
)
from softgrains.model import build
from softgrains.observe.bodies import body_columns, body_records
from softgrains.observe.chains import chain_lines
from softgrains.observe.compaction import COMPACTION_COLUMNS
from softgrains.observe.contacts import CONTACT_COLUMNS, contact_records, contact_rows
from softgrains.observe.energies import kinetic_energy, spin_energies, strain_energy
from softgrains.observe.shapes import GRAIN_COLUMNS, grain_rows
from softgrains.observe.stress import project_per_grain, von_mises
from softgrains.protocol import UniaxialCompaction
from softgrains.solver import Solver, StepDiagnostics

RETRYABLE = {"nan", "inverted", "newton", "contact", "motion"}  # a smaller Δt may cure
# without a progress bar (not a terminal) run.log and the console get a progress line
# every twentieth of the run's steps, and at least this often (seconds): a 1000-grain
# compaction takes 10-20 s a step, so a twentieth of its 10 000 steps is hours
PROGRESS_LOG_SECONDS = 60.0
GROW_AFTER_STEPS = 5  # converged steps in a row before the controller doubles Δt again
# ... twice as many after each growth whose first step failed, up to this (a difficulty
# that persists, e.g. the frictionless compaction near 300 σ0, where each attempt at the
# nominal Δt failed after 7-13 s of coupling iterations, 4 times in 20 steps: session 40)
GROW_AFTER_MAX = 80
# the case keys of a protocol's stop: a finished run resumed with one changed goes on
STOP_KEYS = ("protocol.stop_stress_ratio", "protocol.stop_packing_fraction")
# contact.adaptive_reach (session 26): a step's point contacts are taken up to the gap
# REACH_MARGIN × the relative motion its points are expected to make (at least REACH_FLOOR
# cells): the full kernel reach (~2.1 h with B-splines) made 2700 contacts in a dense
# compaction step where 480 carry an impulse and the rest sit 0.25-2 h apart while the
# grains move ~0.1 h a step; cut at 0.5 h: 1400 contacts, the same iterations, steps ~30%
# faster
REACH_MARGIN = 2.0
REACH_FLOOR = 0.5
SERIES_COLUMNS = [
    "step", "time", "dt", "newton_iterations", "contact_iterations", "contact_residual",
    "n_contacts", "kinetic_energy", "strain_energy", "gravity_energy", "total_energy",
    "momentum_x", "momentum_y", "newton_residual", "linear_solver", "contact_sweeps",
    "contact_nodes", "contact_sticking", "contact_sliding", "contact_converged", "wall_time",
    "wall_work", "contact_dissipation", "integrator_dissipation", "transfer_dissipation",
    "least_contact_gap", "gap_correction_work", "least_unsampled_gap",
]


class Simulation:
    """A run of a validated case: ``Simulation(case, out).run()``; or ``step()`` in a loop."""

    def __init__(self, case, out: str | Path | None = None) -> None:
        self.case = case
        self.out = Path(out) if out is not None else None
        threads = case.simulation.threads
        if threads:
            numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        self.model, self.state = build(case)
        self.solver = Solver(self.model, motion_limit=case.simulation.max_step_motion
                             * self.model.lattice.h)
        self.dt = self.last_dt = case.simulation.dt
        self.n_steps = case.simulation.n_steps
        self._rows: list[dict[str, object]] = []
        self._gravity_energy0 = 0.0
        self.last_diagnostics = StepDiagnostics()
        self.protocol = None
        self._protocol_row: dict[str, object] = {}
        self.unconverged_contact_steps = 0
        # since the start: the work done on the bodies by the kinematic walls (through
        # contact) and by prescribed (Dirichlet) nodes, the energy the contacts took out
        # (coupling._contact_work), the grid update's own dissipation and the loss in the
        # point ↔ grid transfers (BodyStep.finish); with the energies of the deformable
        # bodies E (kinetic + strain + gravity):
        #   ΔE = wall_work − contact_dissipation − integrator_dissipation − transfer_dissipation
        self.wall_work = 0.0
        self.contact_dissipation = 0.0
        self.gap_correction_work = 0.0  # of it, what contact.end_gap_check's corrections put in
        self.integrator_dissipation = 0.0
        self.transfer_dissipation = 0.0
        self.largest_penetration = 0.0  # −(least gap at an active contact) over the run, m
        # −(least gap of the outer points one pass leaves out) over the run, m (NaN: no
        # grain pair took one pass; contact.grain_passes)
        self.largest_unsampled_penetration = math.nan
        self.resumed_from: int | None = None  # the checkpoint's step when resumed
        self.checkpoint_step: int | None = None  # the step of the last checkpoint written
        self.retried_steps = 0  # steps retried with a halved Δt (retry_halvings)
        # contact.adaptive_reach: the last step's largest grain point motion / Δt (None:
        # not known, the full reach), the steps redone with the full reach, and whether
        # the step being made is one
        self.grain_speed: float | None = None
        self.reach_retries = 0
        self._full_reach = False
        self.dt_factor = 1.0  # the step-size controller's Δt / nominal Δt
        self.steps_at_factor = 0  # steps converged in a row since dt_factor last changed
        self.grow_after = GROW_AFTER_STEPS  # ... before dt_factor doubles again
        self.just_grown = False  # dt_factor doubled before this step
        self.smallest_dt_factor = 1.0
        self.retry_events: list[str] = []  # their messages, logged by run()
        self.checkpoint_errors = 0  # checkpoint writes that failed (logged, run goes on)
        self.stop_signal: int | None = None  # the signal that stopped run(), if any
        self._first_step = 0
        if case.protocol is not None:
            self.protocol = UniaxialCompaction(case.protocol, self.model, case.layout.width,
                                               case.contact.friction, self.dt)

    @property
    def columns(self) -> list[str]:
        """The columns of series.csv for this case."""
        return SERIES_COLUMNS + (COMPACTION_COLUMNS if self.protocol is not None else [])

    # -- observables -------------------------------------------------------------------
    def series_row(self, wall_time: float = 0.0) -> dict[str, object]:
        m, s, dg = self.model, self.state, self.last_diagnostics
        deformable = m.deformable_points
        # energies and momentum of the deformable bodies (kinematic walls are driven)
        ek = kinetic_energy(m.mass[deformable], s.v[deformable])
        es = strain_energy(m.law[deformable], s.F[deformable], m.lam[deformable],
                           m.mu[deformable], m.vol0[deformable])
        eg = -float(np.sum(m.mass[deformable] * (s.x[deformable] @ m.gravity)))
        mom = (m.mass[deformable, None] * s.v[deformable]).sum(axis=0)
        residual = max((r.residuals[-1] for r in dg.bodies.values() if r.residuals), default=0.0)
        return {
            "step": s.step, "time": s.time, "dt": self.last_dt,
            "newton_iterations": dg.newton_iterations,
            "contact_iterations": dg.contact.iterations,
            "contact_residual": dg.contact.residual, "n_contacts": dg.contact.active,
            "kinetic_energy": ek,
            "strain_energy": es, "gravity_energy": eg, "total_energy": ek + es + eg,
            "momentum_x": mom[0], "momentum_y": mom[1], "newton_residual": residual,
            "linear_solver": dg.linear_method or "-", "contact_sweeps": dg.contact.sweeps,
            "contact_nodes": dg.contact.n_contacts, "contact_sticking": dg.contact.sticking,
            "contact_sliding": dg.contact.sliding,
            "contact_converged": int(dg.contact.converged), "wall_time": wall_time,
            "wall_work": self.wall_work, "contact_dissipation": self.contact_dissipation,
            "integrator_dissipation": self.integrator_dissipation,
            "transfer_dissipation": self.transfer_dissipation,
            "least_contact_gap": _least_active_gap(dg.contacts),
            "gap_correction_work": self.gap_correction_work,
            "least_unsampled_gap": dg.contact.least_unsampled_gap,
            **self._protocol_observables(),
        }

    def _protocol_observables(self) -> dict[str, object]:
        if self.protocol is None:
            return {}
        if not self._protocol_row:  # before the first step: no forces yet
            m = self.model
            self._protocol_row = self.protocol.observe(
                self.state, np.zeros((len(m.bodies), m.dim)), None)
        return self._protocol_row

    @property
    def series(self) -> dict[str, np.ndarray]:
        """The recorded series rows as column arrays."""
        if not self._rows:
            return {}
        return {k: np.array([r[k] for r in self._rows]) for k in self._rows[0]}

    def snapshot_data(self) -> dict[str, np.ndarray]:
        m, s = self.model, self.state
        kinematic = np.array([not b.deformable for b in m.bodies], np.int32)[m.body_id]
        # the stress smoothed per grain on a grid of spacing h (closer to a FE solution
        # than the raw points; on the point spacing it barely smooths:
        # benchmarks/stress_scatter.py)
        smoothed = project_per_grain(s.x, s.vol, s.sigma, m.body_id, m.lattice.h)
        return {"body": m.body_id.astype(np.int32), "kinematic": kinematic,
                "velocity": s.v, "stress": s.sigma, "von_mises": von_mises(s.sigma),
                "stress_smoothed": smoothed, "von_mises_smoothed": von_mises(smoothed),
                "J": np.linalg.det(s.F), "F": s.F, "mass": m.mass, "volume": s.vol}

    # -- stepping ----------------------------------------------------------------------
    def step(self) -> StepDiagnostics:
        """One implicit step (the protocol drives the walls first); raises SimulationError
        on failure. The step-size controller: a step that fails in a way a smaller Δt may
        cure is undone and retried with Δt halved, down to the nominal Δt / 2^k with
        k = ``simulation.retry_halvings``; after ``GROW_AFTER_STEPS`` steps in a row that
        succeed, Δt is doubled again, up to the nominal Δt (where the step right after a
        growth fails, the next growth waits twice as many steps, up to GROW_AFTER_MAX; a
        growth that holds brings the wait back to GROW_AFTER_STEPS). Each change is noted in
        ``retry_events`` (logged by run()) and counted in summary.json. A step that would
        move a grain's point more than ``max_step_motion`` cells is shortened as many
        halvings as that takes: before it, as far as the grains' velocities tell
        (:meth:`_shorten_for_velocities`), and after it, by the motion it made. With
        ``contact.adaptive_reach`` the step's point contacts are searched only as far as
        the last step's motion predicts; a step that moved farther is redone with the
        full reach (:meth:`_check_reach`)."""
        halvings = self.case.simulation.retry_halvings
        self._shorten_for_velocities(halvings)
        adaptive = self._adaptive_reach()
        saved = checkpointing.snapshot(self) if halvings or adaptive else None
        self._full_reach = not adaptive
        while True:
            try:
                dg = self._advance(self._factor_to_end(self.dt_factor))
            except SimulationError as error:
                kind = error.diagnosis.get("kind")
                if kind == "reach":  # redone with the full reach (contact.adaptive_reach)
                    rows, redone = self._rows, self.reach_retries + 1
                    checkpointing.restore(self, *saved)
                    self._rows, self.reach_retries, self._full_reach = rows, redone, True
                    self.retry_events.append(f"{str(error).splitlines()[0]}\n  redoing "
                                             f"step {self.state.step} with the full reach")
                    continue
                cuts = _halvings_for(error.diagnosis["motion"]) if kind == "motion" else 1
                factor = max(self.dt_factor * 0.5 ** cuts, 0.5 ** halvings)
                if factor >= self.dt_factor or kind not in RETRYABLE:
                    raise
                rows, retried, redone = self._rows, self.retried_steps + 1, self.reach_retries
                smallest = min(self.smallest_dt_factor, factor)
                backed_off = self.just_grown and self.grow_after < GROW_AFTER_MAX
                wait = min(2 * self.grow_after, GROW_AFTER_MAX) if backed_off else \
                    self.grow_after
                checkpointing.restore(self, *saved)  # the state before the failed attempt
                self._rows, self.retried_steps, self.reach_retries = rows, retried, redone
                self.dt_factor, self.steps_at_factor = factor, 0
                self.grow_after, self.just_grown = wait, False
                self.smallest_dt_factor = smallest
                self.retry_events.append(
                    f"{str(error).splitlines()[0]}\n  retrying step {self.state.step} with "
                    f"dt x {self.dt_factor:g} (step-size controller, [simulation] "
                    "retry_halvings)" + (f"; it failed right after dt grew: dt grows back "
                                         f"after {wait} converged steps" if backed_off else ""))
                continue
            if self.just_grown:  # the growth held
                self.grow_after, self.just_grown = GROW_AFTER_STEPS, False
            self.steps_at_factor += 1
            if self.dt_factor < 1.0 and self.steps_at_factor >= self.grow_after:
                self.dt_factor = min(1.0, 2.0 * self.dt_factor)
                self.retry_events.append(
                    f"step {self.state.step}: {self.steps_at_factor} steps converged, dt x "
                    f"{self.dt_factor:g} from here (step-size controller)")
                self.steps_at_factor, self.just_grown = 0, True
            return dg

    def _frictionless_one_pass(self) -> bool:
        """True when ``contact.grain_passes = "one"`` meets a frictionless grain pair."""
        contact, model = self.case.contact, self.model
        if contact is None or contact.grain_passes != "one" or model.friction is None:
            return False
        grains = [b.index for b in model.bodies if b.deformable]
        mu = model.friction[np.ix_(grains, grains)]
        return bool((mu[np.triu_indices(len(grains), 1)] == 0.0).any())

    def _nominal_dt(self) -> float:
        """The step's Δt before the controller's factor: the protocol's (its phase may set
        its own) or the case's."""
        return self.protocol.time_step() if self.protocol is not None else self.dt

    def _factor_to_end(self, factor: float) -> float:
        """``factor`` limited so that the step does not pass ``simulation.end_time``: after
        retries at a shortened Δt the steps no longer land on it, and a run (or a load
        path) must end where the case says: t + factor Δt ≤ t_end."""
        sim = self.case.simulation
        if sim.steps is not None:
            return factor
        dt = self._nominal_dt()
        remaining = sim.end_time - self.state.time
        if 0.0 < remaining < factor * dt * (1.0 - 1e-9):
            return remaining / dt
        return factor

    def _shorten_for_velocities(self, halvings: int) -> None:
        """Halve Δt before the step, within ``retry_halvings``, while the grains' current
        velocities would carry a point farther than ``max_step_motion`` cells:
        max_p |v_p| Δt ≤ max_step_motion h (u = Δt v for a point in free flight, e.g. a
        rattler spinning after a rearrangement). Noted in ``retry_events``."""
        grains = self.model.deformable_points
        if not halvings or not grains.size or len(self.model.bodies) < 2:
            return
        dt = self._nominal_dt()
        speed = float(np.sqrt(np.einsum("ij,ij->i", self.state.v[grains],
                                        self.state.v[grains]).max()))
        reach = self.case.simulation.max_step_motion * self.model.lattice.h
        cuts = _halvings_for(speed * dt * self.dt_factor / reach)
        factor = max(self.dt_factor * 0.5 ** cuts, 0.5 ** halvings)
        if factor < self.dt_factor:
            self.dt_factor, self.steps_at_factor, self.just_grown = factor, 0, False
            self.smallest_dt_factor = min(self.smallest_dt_factor, factor)
            self.retry_events.append(
                f"step {self.state.step}: a grain moving at {speed:.3g} m/s would cross "
                f"{speed * dt / self.model.lattice.h:.3g} cells at the nominal dt: dt x "
                f"{factor:g} (step-size controller, [simulation] max_step_motion)")

    def _advance(self, factor: float) -> StepDiagnostics:
        """The step itself, with the nominal Δt times ``factor``."""
        if self.protocol is not None:
            self.protocol.before_step(self.state)
        dt = self._nominal_dt()
        dt = self.last_dt = dt * factor
        step = self.state.step
        grains = self.model.deformable_points
        x_start = self.state.x[grains]
        cutoff = None if self._full_reach else REACH_MARGIN * self._relative_motion(
            self.grain_speed * dt, dt)
        if cutoff is not None:
            cutoff = max(cutoff, REACH_FLOOR * self.model.lattice.h)
        try:
            dg = self.last_diagnostics = self.solver.step(self.state, dt, cutoff)
        except MemoryError:
            raise SimulationError(
                f"step {step}: out of memory ({self.model.n_points} points); try a larger "
                "cell_size, fewer points_per_cell or fewer grains.", kind="memory",
                step=step) from None
        s = self.state
        finite = np.isfinite(s.x).all(axis=1) & np.isfinite(s.v).all(axis=1)
        if not finite.all():
            p = int(np.flatnonzero(~finite)[0])
            body = self.model.bodies[int(self.model.body_id[p])]
            raise SimulationError(
                f"step {step}: non-finite position or velocity of point "
                f"{p - body.points.start} of body '{body.name}'; try a smaller dt or a finer "
                "grid.", kind="nan", step=step, body=body.name, point=p - body.points.start)
        motion = self._check_motion(step, grains, x_start)
        self._check_reach(step, motion, cutoff, dt)
        self.grain_speed = motion / dt
        if not dg.contact.converged:
            self.unconverged_contact_steps += 1
        self.wall_work += dg.contact.wall_work + sum(r.prescribed_work
                                                     for r in dg.bodies.values())
        self.contact_dissipation += dg.contact.dissipation
        self.gap_correction_work += dg.contact.correction_work
        self.integrator_dissipation += sum(r.integrator_dissipation for r in dg.bodies.values())
        self.transfer_dissipation += sum(r.transfer_dissipation for r in dg.bodies.values())
        self.largest_penetration = max(self.largest_penetration,
                                       -_least_active_gap(dg.contacts, default=0.0))
        self.largest_unsampled_penetration = float(np.fmax(
            self.largest_unsampled_penetration, -dg.contact.least_unsampled_gap))
        if self.protocol is not None:
            m, s = self.model, self.state
            grains = m.deformable_points
            forces = dg.contact_forces(len(m.bodies), m.dim, dt)
            ek = self.unsettled_kinetic_energy()
            es = strain_energy(m.law[grains], s.F[grains], m.lam[grains], m.mu[grains],
                               m.vol0[grains])
            self._protocol_row = self.protocol.after_step(s, forces, dg.contacts, ek, es)
        return dg

    def unsettled_kinetic_energy(self) -> np.ndarray:
        """Per body its kinetic energy, less the spin (observe.energies.spin_energies) of a
        body whose friction with every body is 0 (its every contact frictionless): nothing
        couples that spin to the packing, so, as a rattler's motion, it is no sign that the
        packing has not settled."""
        m, s = self.model, self.state
        ek = np.zeros(len(m.bodies))
        np.add.at(ek, m.body_id, 0.5 * m.mass * np.einsum("ij,ij->i", s.v, s.v))
        free = (np.ones(len(m.bodies), bool) if m.friction is None
                else ~np.any(m.friction != 0.0, axis=1))
        return ek - free * spin_energies(m.mass, s.x, s.v, m.body_id, len(m.bodies))

    def _adaptive_reach(self) -> bool:
        """Whether this step may look for its point contacts short of the full reach
        (contact.adaptive_reach, and the last step's motion known)."""
        contact = self.case.contact
        return (contact is not None and contact.adaptive_reach and contact.enabled
                and self.grain_speed is not None and len(self.model.bodies) > 1)

    def _relative_motion(self, motion: float, dt: float) -> float:
        """The farthest two bodies' surfaces can approach in a step whose grain points move
        at most ``motion``: max(2 motion, motion + the fastest kinematic body's Δt |v|)
        (a point against another grain's surface, which moves with that grain's points, or
        against a wall)."""
        speeds = [float(np.linalg.norm(self.state.body_velocity[b.index]))
                  for b in self.model.bodies if not b.deformable]
        return max(2.0 * motion, motion + dt * max(speeds, default=0.0))

    def _check_reach(self, step: int, motion: float, cutoff: float | None, dt: float) -> None:
        """Raise a SimulationError (kind "reach": the step is redone with the full reach)
        if the step's points moved farther than its contact cutoff allowed: a pair of
        bodies whose gap exceeded the cutoff at the start may have met within the step."""
        if cutoff is None or self._relative_motion(motion, dt) <= cutoff:
            return
        h = self.model.lattice.h
        raise SimulationError(
            f"step {step}: a grain point moved {motion / h:.3g} cells, more than the contact "
            f"search of the step assumed (contacts up to a gap of {cutoff / h:.3g} cells, "
            "contact.adaptive_reach)", kind="reach", step=step)

    def _check_motion(self, step: int, grains: np.ndarray, x_start: np.ndarray) -> float:
        """Raise a SimulationError (kind "motion", which the step-size controller retries
        with a smaller Δt) if a grain's point moved farther than ``max_step_motion`` cells
        in the step: |x_p^{n+1} − x_p^n| ≤ max_step_motion h. A body alone on the grid
        meets no contact and may move farther (a cantilever under gravity in a few steps).
        Returns the largest motion (0 for a body alone)."""
        if not grains.size or len(self.model.bodies) < 2:
            return 0.0
        motion = np.linalg.norm(self.state.x[grains] - x_start, axis=1)
        worst = int(np.argmax(motion))
        h, limit = self.model.lattice.h, self.case.simulation.max_step_motion
        if motion[worst] <= limit * h:
            return float(motion[worst])
        p = int(grains[worst])
        body = self.model.bodies[int(self.model.body_id[p])]
        raise SimulationError(
            f"step {step}: point {p - body.points.start} of body '{body.name}' moved "
            f"{motion[worst] / h:.3g} cells in one step (at {self.state.x[p][0]:.6g}, "
            f"{self.state.x[p][1]:.6g}), more than [simulation] max_step_motion = {limit:g}:"
            " contacts within a step are found only about a cell ahead; try a smaller dt.",
            kind="motion", step=step, body=body.name, point=p - body.points.start,
            motion=motion[worst] / (limit * h))

    @property
    def at_end(self) -> bool:
        """True at the end of the run: end_time or steps reached, or the protocol's stop."""
        sim = self.case.simulation
        if sim.steps is not None:
            return self.state.step >= sim.steps or self.finished
        return self.state.time >= sim.end_time - 1e-9 * self.dt or self.finished

    @property
    def finished(self) -> bool:
        """True when the protocol's stop criterion has been met."""
        return self.protocol is not None and self.protocol.finished

    # -- checkpoints ---------------------------------------------------------------------
    def write_checkpoint(self, path: str | Path, wall_time: float = 0.0) -> None:
        """Write the complete state to ``path`` (HDF5, atomically replaced)."""
        arrays, meta = checkpointing.capture(self, wall_time)
        write_checkpoint(path, arrays, meta)
        self.checkpoint_step = self.state.step

    def resume(self, path: str | Path) -> tuple[dict[str, object], list[str]]:
        """Restore the state of the checkpoint ``path`` (CaseError if it is missing or from
        another case); returns its metadata and the case keys that changed since."""
        arrays, meta = read_checkpoint(path)
        changes = checkpointing.check_compatible(self, meta, path)
        checkpointing.restore(self, arrays, meta)
        self.resumed_from = self.checkpoint_step = self.state.step
        stops = [c for c in changes if c.split(":")[0] in STOP_KEYS]
        if self.protocol is not None and self.protocol.finished and stops:
            # a run that had met its stop goes on under the changed one (its next step
            # checks it again: a stop met already ends the run after that step)
            self.protocol.reopen(", ".join(stops))
        return meta, changes

    def run(self, resume: bool = False) -> dict[str, object]:
        """Run to the end, writing all outputs when an output folder was given; with
        ``resume``, continue from the output folder's checkpoint.h5."""
        out = self.out
        cfg = self.case.output
        log = None
        tables: list[CsvTable] = []
        series = bodies = pvd = None
        wall_offset, changes = 0.0, []
        if resume:
            if out is None:
                raise CaseError("resume needs the output folder of the run (--out DIR)")
            meta, changes = self.resume(out / CHECKPOINT_NAME)
            wall_offset = float(meta.get("wall_time_s", 0.0))
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            (out / "case.toml").write_text(case_to_toml(self.case))
            for stale in out.glob(f".{CHECKPOINT_NAME}.*.tmp"):  # a write cut by a kill
                stale.unlink(missing_ok=True)
            series = self._table(out / "series.csv", self.columns, resume)
            bodies = self._table(out / "bodies.csv", body_columns(self.model.dim), resume)
            tables = [series, bodies]
            if resume:
                _drop_outputs_after(out, self.state.step)
            if cfg.snapshot_interval > 0:
                (out / "snapshots").mkdir(exist_ok=True)
                pvd = _pvd(out / "snapshots" / "points.pvd", resume)
                contacts_pvd = _pvd(out / "snapshots" / "contacts.pvd", resume)
                chains_pvd = _pvd(out / "snapshots" / "chains.pvd", resume)
        progress = Progress(self.n_steps, enabled=cfg.progress)
        if out is not None:
            log = open_run_log(out, verbose_console=not progress.active)
            if resume:
                log.info("resumed from step %d (t = %.9g s) of %s", self.state.step,
                         self.state.time, out / CHECKPOINT_NAME)
                for change in changes:
                    log.warning("case changed since the checkpoint: %s", change)
            settings = self.model.integrator
            log.info("softgrains run: %d bodies, %d points, %d steps of dt = %g s, "
                     "integrator %s, %s stress form", len(self.model.bodies),
                     self.model.n_points, self.n_steps, self.dt, settings.kind,
                     "momentum" if settings.momentum_form else "consistent")
            if self._frictionless_one_pass():
                log.warning("[contact] grain_passes = \"one\" on frictionless grain pairs is "
                            "experimental: it holds loaded grains (the momentum form, or "
                            "with the consistent form the surface sides' levers), but "
                            "with the consistent form its loaded contacts reached the gap "
                            "limit on the frictionless example (0.040 h against 0.027 h "
                            "with two passes); \"auto\" (the default) takes two passes "
                            "there (docs/dev-notes.md, #11 next steps)")

        def record(wall):
            row = self.series_row(wall + wall_offset)
            self._rows.append(row)
            if series is not None:
                series.append(row)
                forces = self.last_diagnostics.contact_forces(
                    len(self.model.bodies), self.model.dim, self.last_dt)
                for r in body_records(self.model, self.state, forces):
                    bodies.append(r)
            return row

        def snapshot():
            step = self.state.step
            name = f"points_{step:08d}.vtu"
            write_points_vtu(out / "snapshots" / name, self.state.x, self.snapshot_data())
            pvd.add(self.state.time, name)
            # contact forces: a point set of the contact nodes beside the material points,
            # and the per-contact table of INTERFACE.md
            records = contact_records(self.model, self.last_diagnostics.contacts,
                                      self.last_dt)
            name = f"contacts_{step:08d}.vtu"
            write_points_vtu(out / "snapshots" / name, records["position"],
                             {k: v for k, v in records.items() if k != "position"})
            contacts_pvd.add(self.state.time, name)
            # the force chains as lines (issue #13): one per pair of bodies pressing
            chains = chain_lines(self.model, self.state, records)
            name = f"chains_{step:08d}.vtu"
            write_points_vtu(out / "snapshots" / name, chains.points, {}, chains.lines,
                             chains.data)
            chains_pvd.add(self.state.time, name)
            table = CsvTable(out / "contacts" / f"contacts_{step:08d}.csv", CONTACT_COLUMNS)
            for row in contact_rows(self.model, self.state, records):
                table.append(row)
            table.close()
            # each grain's shape (issue #13): area, perimeter, asphericity, contacts
            rows = grain_rows(self.model, self.state, self.last_diagnostics.contacts)
            if rows:
                (out / "grains").mkdir(exist_ok=True)
                table = CsvTable(out / "grains" / f"grains_{step:08d}.csv", GRAIN_COLUMNS)
                for row in rows:
                    table.append(row)
                table.close()

        def checkpoint(wall):
            if out is not None and self.checkpoint_step != self.state.step:
                last_checkpoint[0] = _time.perf_counter()
                try:
                    self.write_checkpoint(out / CHECKPOINT_NAME, wall + wall_offset)
                except OSError as error:  # disk full, permissions: the run itself goes on
                    self.checkpoint_errors += 1
                    if log is not None:
                        log.warning("could not write the checkpoint at step %d (%s); the "
                                    "previous one, if any, is kept", self.state.step, error)

        t0 = _time.perf_counter()
        last_checkpoint = [t0]
        self._t_after_first_step = None
        self._first_step = self.state.step  # steps before run() (or the resumed ones) excluded
        status, message = "completed", ""
        log_every = max(1, self.n_steps // 20)
        last_log = [0.0]  # wall time of the last progress line
        stop = StopRequest()
        try:
            if not resume:
                record(0.0)
                if pvd is not None:
                    snapshot()
            events = self.protocol.events if self.protocol is not None else []
            while not self.at_end:
                phase = self.protocol.phase if self.protocol is not None else None
                self.step()
                k = self.state.step
                wall = _time.perf_counter() - t0
                if self._t_after_first_step is None:
                    self._t_after_first_step = wall
                last = self.at_end
                dg = self.last_diagnostics
                if not dg.contact.converged and log is not None:
                    saved = _save_contact_problem(out, k - 1, dg.contact.problem)
                    log.warning("%s (going on: [contact] on_failure = \"warn\")%s",
                                dg.contact.message, saved)
                    dg.contact.problem = None
                changed = self.protocol is not None and self.protocol.phase != phase
                if k % cfg.interval == 0 or last or changed:
                    row = record(wall)
                    progress.update(k, self.state.time, **self._progress_figures(row))
                while events and log is not None:
                    log.info("%s", events.pop(0))
                while self.retry_events and log is not None:
                    log.warning("%s", self.retry_events.pop(0))
                if pvd is not None and (k % cfg.snapshot_interval == 0 or last or changed):
                    snapshot()
                if log is not None and not progress.active and (
                        k % log_every == 0 or wall - last_log[0] >= PROGRESS_LOG_SECONDS):
                    last_log[0] = wall
                    log.info("step %d/%d  t = %.6g s  newton %d  contact %d  (%.1f s)%s", k,
                             self.n_steps, self.state.time, dg.newton_iterations,
                             dg.contact.iterations, wall, self._log_figures())
                if self.finished:
                    break
                if stop.requested:
                    status = "interrupted"
                    message = f"stopped by {stop.name} at step {k}"
                    break
                minutes = cfg.checkpoint_minutes
                if ((cfg.checkpoint_interval and k % cfg.checkpoint_interval == 0)
                        or (minutes and _time.perf_counter() - last_checkpoint[0]
                            >= 60.0 * minutes)):
                    checkpoint(wall)
            if status == "interrupted":
                if log is not None:
                    log.warning("%s; continue with --resume", message)
            elif self.protocol is not None and not self.protocol.finished and log is not None:
                log.warning("the run reached its end (simulation.end_time / steps) in the %s "
                            "phase before the protocol's stop criterion; raise end_time to "
                            "go further", self.protocol.phase)
            if status == "completed" and self.unconverged_contact_steps:
                # on_failure = "warn": never a plain "completed"
                status = f"completed with {self.unconverged_contact_steps} unconverged steps"
                message = ("the coupled contact loop did not converge on "
                           f"{self.unconverged_contact_steps} steps, which were kept "
                           "([contact] on_failure = \"warn\"); their rows have "
                           "contact_converged = 0 in series.csv")
                if log is not None:
                    log.warning("%s", message)
            if log is not None and self.model.contact is not None:
                log.info("largest overlap at a contact carrying an impulse: %.3g h (the "
                         "contact's own boundary-gap estimate; series.csv "
                         "least_contact_gap)", self.largest_penetration / self.model.lattice.h)
                if not math.isnan(self.largest_unsampled_penetration):
                    log.info("largest overlap of the grains' outer points that one pass "
                             "leaves out (not contacts; contact.grain_passes): %.3g h "
                             "(series.csv least_unsampled_gap)",
                             self.largest_unsampled_penetration / self.model.lattice.h)
            checkpoint(_time.perf_counter() - t0)
        except SimulationError as err:
            status = "failed"
            message = str(err) + _save_contact_problem(
                out, err.diagnosis.get("step"), err.diagnosis.get("contact_problem"))
            while self.retry_events and log is not None:  # the retries that did not help
                log.warning("%s", self.retry_events.pop(0))
            if self.checkpoint_step is not None and out is not None:
                message += (f"\nthe last good checkpoint (step {self.checkpoint_step}) is "
                            f"{out / CHECKPOINT_NAME}: change the case (e.g. a smaller dt) "
                            "and continue with --resume")
            err.args = (message,)
            if log is not None:
                log.error("%s", message)
            raise
        except KeyboardInterrupt:
            status, message = "interrupted", "stopped by the user (no final checkpoint)"
            raise
        finally:
            stop.restore()
            progress.close()
            for t in tables:
                t.close()
            wall = _time.perf_counter() - t0
            summary = self._summary(status, message, wall)
            if out is not None:
                write_json_atomic(out / "summary.json", summary)
                log.info("%s after %d steps in %.2f s (first step, with JIT compilation: "
                         "%.2f s; then %.3g s/step, %.3g point updates/s; peak memory %s MiB)",
                         status, self.state.step, wall, summary["first_step_s"] or 0.0,
                         summary["time_per_step_s"], summary["point_updates_per_second"],
                         f"{summary['peak_memory_mib']:.0f}"
                         if summary["peak_memory_mib"] is not None else "?")
                close_run_log(log)
        self.stop_signal = stop.signum
        return summary

    def _table(self, path: Path, columns: list[str], resume: bool) -> CsvTable:
        """A new table, or on resume the existing one cut back to the checkpoint's step."""
        if not resume or not path.is_file():
            return CsvTable(path, columns)
        try:
            truncate_after_step(path, columns, self.state.step)
        except ValueError as error:
            raise CaseError(f"cannot resume: {error}") from None
        return CsvTable(path, columns, append=True)

    def _progress_figures(self, row: dict[str, object]) -> dict[str, object]:
        if self.protocol is None:
            return {"E": f"{row['total_energy']:.4g}"}
        sigma0 = self.protocol.settings.sigma0
        return {"phase": row["phase"], "phi": f"{row['phi']:.4f}",
                "σ/σ0": f"{row['stress_yy'] / sigma0:.3g}"}

    def _log_figures(self) -> str:
        if self.protocol is None or not self._protocol_row:
            return ""
        r = self._protocol_row
        return (f"  {r['phase']}: phi = {r['phi']:.4f}, sigma_yy = {r['stress_yy']:.4g} Pa, "
                f"Z = {r['coordination']:.2f}")

    def _summary(self, status: str, message: str, wall: float) -> dict[str, object]:
        steps = self.state.step - self._first_step  # in this run() call
        last = self._rows[-1] if self._rows else {}
        # the first step includes the JIT compilation of the kernels (once per machine)
        first = self._t_after_first_step
        if first is not None and steps > 1:
            later, n_later = wall - first, steps - 1
        else:
            later, n_later = wall, steps
        per_step = later / n_later if n_later else math.nan
        return {
            "status": status, "message": message, "steps": self.state.step,
            "time": self.state.time, "resumed_from_step": self.resumed_from,
            "last_checkpoint_step": self.checkpoint_step,
            "dt": self.dt, "bodies": len(self.model.bodies), "points": self.model.n_points,
            "wall_time_s": wall, "first_step_s": first, "time_per_step_s": per_step,
            "point_updates_per_second": self.model.n_points / per_step if per_step > 0 else 0.0,
            "threads": numba.get_num_threads(), "peak_memory_mib": peak_memory_mib(),
            "final": last,
            "unconverged_contact_steps": self.unconverged_contact_steps,
            "checkpoint_errors": self.checkpoint_errors,
            "retried_steps": self.retried_steps,
            "contact_reach_retries": self.reach_retries,
            "smallest_dt_factor": self.smallest_dt_factor,
            "largest_contact_penetration_h": self.largest_penetration / self.model.lattice.h,
            "largest_unsampled_penetration_h": _or_none(self.largest_unsampled_penetration
                                                        / self.model.lattice.h),
            "protocol": self.protocol.summary() if self.protocol is not None else None,
            "software": software_versions(),
        }


_STEP_IN_NAME = re.compile(r"_(\d+)\.(vtu|csv)$")


def _halvings_for(ratio: float) -> int:
    """How many halvings of Δt bring a motion ``ratio`` times the limit within it (0 when
    ratio ≤ 1): ⌈log₂ ratio⌉."""
    return max(0, math.ceil(math.log2(ratio))) if ratio > 1.0 else 0


def _or_none(value: float) -> float | None:
    """JSON has no NaN: None where a figure does not exist."""
    return None if math.isnan(value) else value


def _least_active_gap(contacts, default: float = math.nan) -> float:
    """The least boundary gap (m) at the contacts that carry an impulse this step, measured
    at the start of the step, i.e. where the previous step left them (gap.py; < 0: an
    estimated overlap); ``default`` when no contact carries one."""
    if contacts is None or len(contacts.nodes) == 0 or contacts.gap.size == 0:
        return default
    active = np.any(contacts.impulse != 0.0, axis=1)
    return float(contacts.gap[active].min()) if active.any() else default


def _step_of(name: str) -> int:
    """The step in an output file name such as points_00000120.vtu (-1 if none)."""
    match = _STEP_IN_NAME.search(str(name))
    return int(match.group(1)) if match else -1


def _save_contact_problem(out: Path | None, step, problem) -> str:
    """Write the contact problem of a step whose coupled solve did not converge to
    out/contact_problems/step_<N>.npz (replay: ContactProblem.load, contact.solve); returns
    the sentence for the message ('' when there is nothing to write or no folder)."""
    if out is None or problem is None:
        return ""
    folder = out / "contact_problems"
    folder.mkdir(exist_ok=True)
    path = folder / f"step_{int(step):08d}.npz"
    problem.save(path)
    return (f"\nthe contact problem of its last iteration is in {path} (replay it with "
            "softgrains.contact.ContactProblem.load and softgrains.contact.solve)")


def _drop_outputs_after(out: Path, step: int) -> None:
    """Delete the snapshot and contact files written after ``step`` (a resumed run writes
    them again)."""
    for folder in (out / "snapshots", out / "contacts", out / "grains"):
        if folder.is_dir():
            for path in folder.iterdir():
                if _step_of(path.name) > step:
                    path.unlink()


def _pvd(path: Path, resume: bool) -> PvdSeries:
    """A new .pvd index, or on resume the existing one without the entries past the
    checkpoint (their files were deleted by _drop_outputs_after)."""
    entries = []
    if resume and path.is_file():
        entries = [(t, f) for t, f in read_pvd(path) if (path.parent / f).is_file()]
    return PvdSeries(path, entries)

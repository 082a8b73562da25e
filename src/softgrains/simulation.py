"""Simulation: Model + State + Solver, the run loop and its observers (ARCHITECTURE.md).

Outputs (INTERFACE.md): case.toml (resolved), series.csv, bodies.csv, snapshots/ (VTK + .pvd),
summary.json, run.log; rows are flushed as they are written. A SimulationError stops the run
with a diagnosis in run.log and summary.json (status "failed") and is re-raised (exit 3).
"""

from __future__ import annotations

import math
import time as _time
from pathlib import Path

import numba
import numpy as np

from softgrains.case import case_to_toml
from softgrains.errors import SimulationError
from softgrains.io import (
    CsvTable,
    Progress,
    PvdSeries,
    close_run_log,
    open_run_log,
    software_versions,
    write_json_atomic,
    write_points_vtu,
)
from softgrains.model import build
from softgrains.observe.bodies import body_columns, body_records
from softgrains.observe.energies import kinetic_energy, strain_energy
from softgrains.observe.stress import von_mises
from softgrains.solver import Solver, StepDiagnostics

SERIES_COLUMNS = [
    "step", "time", "dt", "newton_iterations", "contact_iterations", "contact_residual",
    "n_contacts", "kinetic_energy", "strain_energy", "gravity_energy", "total_energy",
    "momentum_x", "momentum_y", "newton_residual", "linear_solver", "wall_time",
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
        self.solver = Solver(self.model)
        self.dt = case.simulation.dt
        self.n_steps = case.simulation.n_steps
        self._rows: list[dict[str, object]] = []
        self._gravity_energy0 = 0.0
        self.last_diagnostics = StepDiagnostics()

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
            "step": s.step, "time": s.time, "dt": self.dt,
            "newton_iterations": dg.newton_iterations,
            "contact_iterations": dg.contact.iterations,
            "contact_residual": dg.contact.residual, "n_contacts": dg.contact.active,
            "kinetic_energy": ek,
            "strain_energy": es, "gravity_energy": eg, "total_energy": ek + es + eg,
            "momentum_x": mom[0], "momentum_y": mom[1], "newton_residual": residual,
            "linear_solver": dg.linear_method or "-", "wall_time": wall_time,
        }

    @property
    def series(self) -> dict[str, np.ndarray]:
        """The recorded series rows as column arrays."""
        if not self._rows:
            return {}
        return {k: np.array([r[k] for r in self._rows]) for k in self._rows[0]}

    def snapshot_data(self) -> dict[str, np.ndarray]:
        m, s = self.model, self.state
        return {"body": m.body_id.astype(np.int32), "velocity": s.v, "stress": s.sigma,
                "von_mises": von_mises(s.sigma), "J": np.linalg.det(s.F), "mass": m.mass}

    # -- stepping ----------------------------------------------------------------------
    def step(self) -> StepDiagnostics:
        """One implicit step; raises SimulationError on failure."""
        self.last_diagnostics = self.solver.step(self.state, self.dt)
        if not np.all(np.isfinite(self.state.x)) or not np.all(np.isfinite(self.state.v)):
            raise SimulationError(
                f"step {self.state.step}: non-finite positions or velocities; try a smaller "
                "dt or a finer grid.", step=self.state.step)
        return self.last_diagnostics

    def run(self) -> dict[str, object]:
        """Run to the end, writing all outputs when an output folder was given."""
        out = self.out
        cfg = self.case.output
        log = None
        tables: list[CsvTable] = []
        series = bodies = pvd = None
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            (out / "case.toml").write_text(case_to_toml(self.case))
            series = CsvTable(out / "series.csv", SERIES_COLUMNS)
            bodies = CsvTable(out / "bodies.csv", body_columns(self.model.dim))
            tables = [series, bodies]
            if cfg.snapshot_interval > 0:
                (out / "snapshots").mkdir(exist_ok=True)
                pvd = PvdSeries(out / "snapshots" / "points.pvd")
        progress = Progress(self.n_steps, enabled=cfg.progress)
        if out is not None:
            log = open_run_log(out, verbose_console=not progress.active)
            log.info("softgrains run: %d bodies, %d points, %d steps of dt = %g s, "
                     "integrator %s", len(self.model.bodies), self.model.n_points,
                     self.n_steps, self.dt, self.model.integrator.kind)

        def record(wall):
            row = self.series_row(wall)
            self._rows.append(row)
            if series is not None:
                series.append(row)
                forces = self.last_diagnostics.contact_forces(
                    len(self.model.bodies), self.model.dim, self.dt)
                for r in body_records(self.model, self.state, forces):
                    bodies.append(r)
            return row

        def snapshot():
            name = f"points_{self.state.step:08d}.vtu"
            write_points_vtu(out / "snapshots" / name, self.state.x, self.snapshot_data())
            pvd.add(self.state.time, name)

        t0 = _time.perf_counter()
        self._t_after_first_step = None
        status, message = "completed", ""
        log_every = max(1, self.n_steps // 20)
        try:
            record(0.0)
            if pvd is not None:
                snapshot()
            for _ in range(self.n_steps):
                self.step()
                k = self.state.step
                wall = _time.perf_counter() - t0
                if self._t_after_first_step is None:
                    self._t_after_first_step = wall
                if k % cfg.interval == 0 or k == self.n_steps:
                    row = record(wall)
                    progress.update(k, self.state.time, E=f"{row['total_energy']:.4g}")
                if pvd is not None and (k % cfg.snapshot_interval == 0 or k == self.n_steps):
                    snapshot()
                if log is not None and not progress.active and k % log_every == 0:
                    log.info("step %d/%d  t = %.6g s  newton %d  (%.1f s)", k, self.n_steps,
                             self.state.time, self.last_diagnostics.newton_iterations, wall)
        except SimulationError as err:
            status, message = "failed", str(err)
            if log is not None:
                log.error("%s", err)
            raise
        except KeyboardInterrupt:
            status, message = "interrupted", "stopped by the user"
            raise
        finally:
            progress.close()
            for t in tables:
                t.close()
            wall = _time.perf_counter() - t0
            summary = self._summary(status, message, wall)
            if out is not None:
                write_json_atomic(out / "summary.json", summary)
                log.info("%s after %d steps in %.2f s (first step, with JIT compilation: "
                         "%.2f s; then %.3g s/step, %.3g point updates/s)", status,
                         self.state.step, wall, summary["first_step_s"] or 0.0,
                         summary["time_per_step_s"], summary["point_updates_per_second"])
                close_run_log(log)
        return summary

    def _summary(self, status: str, message: str, wall: float) -> dict[str, object]:
        steps = self.state.step
        last = self._rows[-1] if self._rows else {}
        # the first step includes the JIT compilation of the kernels (once per machine)
        first = self._t_after_first_step
        if first is not None and steps > 1:
            later, n_later = wall - first, steps - 1
        else:
            later, n_later = wall, steps
        per_step = later / n_later if n_later else math.nan
        return {
            "status": status, "message": message, "steps": steps, "time": self.state.time,
            "dt": self.dt, "bodies": len(self.model.bodies), "points": self.model.n_points,
            "wall_time_s": wall, "first_step_s": first, "time_per_step_s": per_step,
            "point_updates_per_second": self.model.n_points / per_step if per_step > 0 else 0.0,
            "threads": numba.get_num_threads(), "final": last,
            "software": software_versions(),
        }

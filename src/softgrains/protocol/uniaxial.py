"""Uniaxial compaction (ALGORITHM.md §8): pre-compaction under σ0, then a top wall at
constant speed.

Pre-compaction (steps of precompaction_dt: only its end state matters, and θ = 1 with large
steps damps the grains' vibrations): the top wall approaches at the largest speed v_max until
the running average σ̄ of σ_yy (weight SMOOTHING) first reaches σ0/2; then a proportional
law controls the stress:
    v = −v_max clip(G (σ0 − σ̄)/σ0, −1, 1),   G = SERVO_GAIN.
The loop gain K v_max Δt G/σ0 (K = dσ/dy of the packing, ~1e8 Pa/m for 30 disks of 1 cm
at 5 kPa) must stay below 1: a secant estimate of K made the wall oscillate (σ between 0
and 4 σ0), measured 2026-11-23.
With ``precompaction_friction`` every body pair has that Coulomb coefficient until the
pre-compaction ends, and the case's own from then on (a sample prepared without friction:
the frictional jammed state at σ0 depends on h, docs/dev-notes.md, session 39).
Equilibrium when |σ − σ0| ≤ tol σ0 and the kinetic energy of the grains that are not
rattlers ≤ ratio × strain energy; then h0 (wall gap) and φ0 are recorded and the
compaction starts: v = −wall_speed (reached linearly in wall_speed_ramp seconds) until
σ_yy ≥ stop_stress_ratio σ0 or φ ≥ stop_packing_fraction.
"""

from __future__ import annotations

import copy

import numpy as np

from softgrains.observe.compaction import (
    box_stresses,
    coordination_and_rattlers,
    packing_coverage,
)
from softgrains.sample import WALLS

PRECOMPACTION, COMPACTION = "precompaction", "compaction"
SERVO_GAIN = 0.25
SMOOTHING = 0.3  # weight of the newest σ_yy in the running average that drives the control


class UniaxialCompaction:
    """Drives the top wall of a [sample] box; measures the compaction observables."""

    def __init__(self, settings, model, width: float, friction: float, dt: float) -> None:
        self.settings, self.model, self.width, self.dt = settings, model, width, dt
        by_name = {b.name: b.index for b in model.bodies}
        self.walls = {name: by_name[name] for name in WALLS}
        self.is_grain = np.array([b.deformable for b in model.bodies])
        self.grain_points = model.deformable_points
        self.phase = PRECOMPACTION
        self.finished = False
        self.stop_reason = ""
        self.h0 = self.phi0 = None
        self.equilibrium = None
        self.label = settings.label or (f"μ = {friction:g}")
        self.events: list[str] = []
        self._sigma = 0.0
        self._engaged = False  # the stress control has taken over from the approach
        self._smooth = 0.0  # σ_yy averaged over the last steps (impacts make it jump)
        self._pre_steps = 0
        self._t_compaction = 0.0
        # the case's μ per body pair, for the compaction (the model's array is set in place)
        self._friction = None if model.friction is None else model.friction.copy()
        self._apply_friction()

    def _apply_friction(self) -> None:
        """μ of the current phase into the model: ``precompaction_friction`` for every pair
        during the pre-compaction where it is set, else the case's."""
        mu = self.settings.precompaction_friction
        if mu is None or self._friction is None:
            return
        if self.phase == PRECOMPACTION:
            self.model.friction[...] = mu
        else:
            self.model.friction[...] = self._friction

    # -- control -------------------------------------------------------------------------
    def time_step(self) -> float:
        """Δt of the coming step: pre-compaction may take larger steps (quasi-static)."""
        s = self.settings
        if self.phase == PRECOMPACTION:
            return s.precompaction_dt if s.precompaction_dt is not None else self.dt
        return self.dt

    def before_step(self, state) -> None:
        """Set the top wall's velocity for the coming step."""
        s, top = self.settings, self.walls["wall_top"]
        if self.phase == COMPACTION:
            # from rest to wall_speed in wall_speed_ramp seconds: a sudden start sends an
            # impact wave (σ ≈ ρ c v, ~30 σ0 at 5 m/s in the examples) through the sample
            elapsed = state.time + 0.5 * self.dt - self._t_compaction
            ramp = s.wall_speed_ramp
            v = -s.wall_speed * (min(1.0, elapsed / ramp) if ramp > 0 else 1.0)
        else:
            error = (s.sigma0 - self._smooth) / s.sigma0
            if not self._engaged and self._smooth >= 0.5 * s.sigma0:
                self._engaged = True
            gain = SERVO_GAIN if self._engaged else 1.0
            v = -s.precompaction_speed * float(np.clip(gain * error, -1.0, 1.0))
        state.body_velocity[top] = [0.0, v]

    # -- measurement -----------------------------------------------------------------------
    def after_step(self, state, forces: np.ndarray, contacts, kinetic: np.ndarray,
                   strain: float) -> dict[str, object]:
        """Observables of the step just taken; advances the phase. ``forces`` (B, d);
        ``kinetic``: kinetic energy per body, less the spin of a grain whose contacts are
        all frictionless (rattlers do not count for equilibrium: a free grain keeps its
        velocity, a frictionless round grain its spin)."""
        s = self.settings
        phase = self.phase
        obs, rattlers = self._observe(state, forces, contacts)
        self._sigma = obs["stress_yy"]
        self._smooth += SMOOTHING * (self._sigma - self._smooth)
        if phase == PRECOMPACTION:
            self._pre_steps += 1
            balanced = abs(self._sigma - s.sigma0) <= s.stress_tolerance * s.sigma0
            kinetic = float(kinetic[self.is_grain & ~rattlers].sum())
            calm = kinetic <= s.kinetic_ratio * strain
            out_of_time = (s.precompaction_max_steps is not None
                           and self._pre_steps >= s.precompaction_max_steps)
            if (balanced and calm) or out_of_time:
                self.h0, self.phi0 = obs["wall_gap"], obs["phi"]
                self.phase = COMPACTION
                self._t_compaction = state.time
                how = ("equilibrium" if balanced and calm else
                       f"NOT in equilibrium after precompaction_max_steps = "
                       f"{s.precompaction_max_steps} (|σ − σ0|/σ0 = "
                       f"{abs(self._sigma - s.sigma0) / s.sigma0:.3g}, kinetic/strain energy "
                       f"= {kinetic / max(strain, 1e-300):.3g})")
                self.equilibrium = balanced and calm
                self._apply_friction()
                switched = ("" if s.precompaction_friction is None else
                            f", friction from μ = {s.precompaction_friction:g} to the case's")
                self.events.append(
                    f"pre-compaction done ({how}) at t = {state.time:.6g} s: σ_yy = "
                    f"{self._sigma:.4g} Pa, h0 = {self.h0:.6g} m, φ0 = {self.phi0:.4f}; "
                    f"compaction at {s.wall_speed:g} m/s{switched}")
        else:
            if (s.stop_stress_ratio is not None
                    and self._sigma >= s.stop_stress_ratio * s.sigma0):
                self.stop_reason = f"σ_yy/σ0 = {self._sigma / s.sigma0:.4g} reached"
            elif s.stop_packing_fraction is not None and obs["phi"] >= s.stop_packing_fraction:
                self.stop_reason = f"φ = {obs['phi']:.4f} reached"
            if self.stop_reason:
                self.finished = True
                self.events.append(f"compaction stopped at t = {state.time:.6g} s: "
                                   f"{self.stop_reason}")
        obs["phase"] = phase
        return obs

    def reopen(self, why: str) -> None:
        """Go on with the compaction after its stop was met (a resume whose case changed the
        stop criteria, ``why``); the next step checks the criteria again."""
        self.events.append(f"compaction goes on past its stop ({self.stop_reason}): {why}")
        self.finished, self.stop_reason = False, ""

    def observe(self, state, forces: np.ndarray, contacts) -> dict[str, object]:
        """The observables of the current state (no side effect)."""
        return self._observe(state, forces, contacts)[0]

    def _observe(self, state, forces, contacts) -> tuple[dict[str, object], np.ndarray]:
        """The observables and the rattler mask over bodies."""
        obs: dict[str, object] = {"phase": self.phase}
        obs.update(box_stresses(self.model, state, self.walls, self.grain_points, self.width,
                                forces))
        obs.update(packing_coverage(self.model, state, self.walls, self.grain_points))
        values, rattlers = coordination_and_rattlers(contacts, self.is_grain)
        obs.update(values)
        obs["top_wall_velocity"] = float(state.body_velocity[self.walls["wall_top"], 1])
        return obs, rattlers

    # -- checkpoints ----------------------------------------------------------------------
    _STATE = ("phase", "finished", "stop_reason", "h0", "phi0", "equilibrium", "events",
              "_sigma", "_engaged", "_smooth", "_pre_steps", "_t_compaction")

    def state_dict(self) -> dict[str, object]:
        """What the protocol carries from one step to the next (for a checkpoint)."""
        return {name: getattr(self, name) for name in self._STATE}

    def load_state_dict(self, values: dict[str, object]) -> None:
        """Restore :meth:`state_dict`'s values (resume from a checkpoint, or a retried
        step). The event list is refilled in place: the run loop holds it."""
        for name in self._STATE:
            if name == "events":
                self.events[:] = list(values[name])
            else:
                setattr(self, name, copy.deepcopy(values[name]))
        self._apply_friction()

    def summary(self) -> dict[str, object]:
        s = self.settings
        return {"kind": s.kind, "sigma0": s.sigma0, "phi0": self.phi0, "h0": self.h0,
                "wall_speed": s.wall_speed, "label": self.label, "phase": self.phase,
                "finished": self.finished, "stop_reason": self.stop_reason,
                "precompaction_equilibrium": self.equilibrium,
                "precompaction_friction": s.precompaction_friction}

"""Pydantic models of a case file, as specified in ``docs/case-schema.md``.

All quantities are SI (m, s, kg, Pa). Every model forbids unknown keys and is strict: a string is
never turned into a number, but an integer is accepted (and stored as a float) where a float is
expected. Checks that involve several keys raise :class:`Problems`, which ``softgrains.case.load``
turns into one message line per offending key.
"""

from __future__ import annotations

import difflib
import math
from typing import Annotated, Literal, NamedTuple

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, model_validator

MAX_POINTS = 2e7
"""Largest accepted estimated number of material points (all bodies together)."""
MAX_NODES = 5e7
"""Largest accepted number of grid nodes."""
MAX_STEPS = 1e9
"""Largest accepted number of time steps."""
AXES = ("x", "y", "z")
"""Names of the velocity components, in axis order."""
DEPOSIT_CLEARANCE = 0.05
"""[sample] clearance by default, in mean diameters: the gap the deposit leaves between
grains and walls. Independent of the grid, so that a sample is the same at every cell size
(it was one point spacing until session 40: halving h changed the deposit, and with it the
frictional jammed state, φ0 −3.7% in the mean of six seeds); 0.05 d is one point spacing at
D/h 10 with 2 points per cell, the examples' resolution."""
SHAPE_KEYS: dict[str, tuple[str, ...]] = {
    "disk": ("center", "radius"),
    "rectangle": ("lower", "upper"),
    "polygon": ("vertices",),
}
"""The geometry keys each body shape needs (and no other shape may have)."""

MISSING = object()
"""Stands for the value of a key that is absent."""


class Problem(NamedTuple):
    """One invalid key: its path (relative to the model that found it), its value, what is wrong."""

    loc: tuple[str | int, ...]
    value: object
    message: str


class Problems(ValueError):
    """Cross-field check failures, raised from a model validator; one :class:`Problem` per key."""

    def __init__(self, problems: list[Problem]) -> None:
        super().__init__("; ".join(f"{'.'.join(map(str, p.loc))}: {p.message}" for p in problems))
        self.problems = problems


def _outer_ring_problems(seeding: str, outer_ring_density: int) -> list[Problem]:
    """outer_ring_density other than 1 without ring seeding (bodies and [sample])."""
    if outer_ring_density != 1 and seeding != "rings":
        return [Problem(("outer_ring_density",), outer_ring_density,
                        "only for seeding = 'rings': remove it")]
    return []


def _zero_vector() -> list[float]:
    """The default for vectors; of length 2, the only dimension supported so far."""
    return [0.0, 0.0]


PositiveFloat = Annotated[float, Field(gt=0)]


class _Section(BaseModel):
    """Common configuration: unknown keys are errors, no str -> number coercion, no inf/nan."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class SimulationSettings(_Section):
    """``[simulation]``: time stepping and solver settings."""

    dimension: Literal[2] = Field(2, description="spatial dimension (only 2 for now)")
    dt: float = Field(gt=0, description="time step [s]")
    end_time: float | None = Field(None, gt=0, description="simulated time [s]; or give steps")
    steps: int | None = Field(None, ge=1, le=MAX_STEPS, description="number of time steps")
    integrator: Literal["theta", "newmark"] = Field("theta", description="time integrator")
    theta: float = Field(1.0, ge=0.5, le=1.0, description="theta of the Moreau-Jean scheme "
                         "(1: dissipative, resting contacts settle; 1/2: energy-conserving)")
    newmark_beta: float = Field(0.25, gt=0.0, le=0.5, description="Newmark beta")
    newmark_gamma: float = Field(0.5, ge=0.5, le=1.0, description="Newmark gamma")
    mass_matrix: Literal["lumped", "consistent"] = Field(
        "lumped", description="nodal mass matrix: lumped (FLIP/PIC) or consistent (theta only)")
    flip: float = Field(
        1.0, ge=0.0, le=1.0, description="FLIP fraction of the FLIP/PIC blend (lumped mass only)")
    seed: int = Field(0, ge=0, description="random seed")
    threads: int = Field(0, ge=0, description="worker threads (0 = all cores)")
    newton_tolerance: float = Field(1e-8, gt=0.0, lt=1.0, description="relative residual")
    newton_max_iterations: int = Field(25, ge=1, le=200, description="Newton iteration limit")
    linear_solver: Literal["auto", "direct", "cg"] = Field("auto", description="linear solver")
    retry_halvings: int = Field(
        4, ge=0, le=10, description="step-size controller: a step that fails (NaN, "
        "inverted point, Newton or contact not converged) is undone and retried with dt "
        "halved, down to dt / 2^retry_halvings; dt doubles back after 5 converged steps "
        "(logged; 0: no retry)")
    max_step_motion: float = Field(
        1.0, gt=0.0, le=10.0, description="the farthest a grain's point may move in one "
        "step, in cells h: a step that moves one farther is undone and retried with dt "
        "halved (the contacts are found at the step's start, within about one cell, and "
        "a point crossing more than a cell leaves the grid's view of it behind; on "
        "quasi-static steps a snap-through or a spinning rattler moves grains several "
        "cells); when the retry_halvings are spent the run stops. Not checked when the "
        "case has a single body")
    stress_form: Literal["auto", "consistent", "momentum"] = Field(
        "auto", description="internal forces of the step: consistent (the exact gradient "
        "of the strain energy) or momentum (the end state's second Piola–Kirchhoff stress "
        "pushed forward by the start-of-step F, whose moment about the start nodes "
        "vanishes, so that the θ = 1 step keeps a free grain's angular momentum and a "
        "loaded grain has no spinning solution; θ = 1 only; bodies with prescribed nodes "
        "and linear-elastic bodies keep the consistent form); auto: momentum where "
        "integrator = \"theta\" and theta = 1, else consistent")
    tangent: Literal["auto", "projected", "exact"] = Field(
        "auto", description="Newton matrix: exact (quadratic convergence), per-point "
        "tangents made positive semi-definite (robust under compression, linear "
        "convergence), or auto: exact, switching to projected within a step whose "
        "iterations fail to converge, and for a body whose compliance at its contacts "
        "is indefinite once a contact solve stalls")

    @property
    def n_steps(self) -> int:
        """Number of time steps: ``steps``, or ``end_time / dt`` rounded up."""
        if self.steps is not None:
            return self.steps
        assert self.end_time is not None  # guaranteed by validation
        return max(1, math.ceil(self.end_time / self.dt * (1 - 1e-12)))

    @model_validator(mode="after")
    def _check_mass_matrix(self) -> SimulationSettings:
        if self.integrator == "newmark" and self.mass_matrix == "consistent":
            message = ('not available with integrator = "newmark": its point-level '
                       'acceleration history grows in modes the grid cannot see; use "lumped", '
                       'or integrator = "theta"')
            raise Problems([Problem(("mass_matrix",), self.mass_matrix, message)])
        return self

    @model_validator(mode="after")
    def _check_stress_form(self) -> SimulationSettings:
        if self.stress_form == "momentum" and (self.integrator != "theta" or self.theta != 1.0):
            message = ('the momentum form is the θ = 1 step\'s (its moment vanishes about the '
                       'start nodes, where backward Euler balances angular momentum): set '
                       'integrator = "theta" and theta = 1.0, or stress_form = "consistent"')
            raise Problems([Problem(("stress_form",), self.stress_form, message)])
        return self

    @model_validator(mode="after")
    def _check_duration(self) -> SimulationSettings:
        if self.end_time is not None and self.steps is not None:
            message = f"give either end_time or steps, not both (end_time = {self.end_time:g})"
            raise Problems([Problem(("steps",), self.steps, message)])
        if self.end_time is None and self.steps is None:
            message = "required: give end_time (simulated time, s) or steps"
            raise Problems([Problem(("end_time",), MISSING, message)])
        if self.end_time is not None:
            if self.end_time < self.dt:
                message = f"must be >= dt = {self.dt:g}"
                raise Problems([Problem(("end_time",), self.end_time, message)])
            if self.end_time / self.dt > MAX_STEPS:
                message = (
                    f"gives {self.end_time / self.dt:.3g} steps of dt = {self.dt:g}; at most "
                    f"{MAX_STEPS:.0e} allowed: shorten end_time or raise dt"
                )
                raise Problems([Problem(("end_time",), self.end_time, message)])
        return self


class GridSettings(_Section):
    """``[grid]``: the background grid, a box ``[origin, origin + size]`` of square cells."""

    cell_size: float = Field(gt=0, description="cell size h [m]")
    origin: list[float] = Field(default_factory=_zero_vector, description="lower corner [m]")
    size: list[PositiveFloat] | None = Field(
        None, description="extent of the domain per axis [m] (default with [sample]: the box)")
    shape_function: Literal["linear", "bspline2"] = Field(
        "bspline2", description="shape functions: quadratic B-splines (smooth gradients; "
        "linear hats let loaded bodies drift a fraction of a cell a step as points cross cell "
        "edges: docs/dev-notes.md) or linear hats")
    points_per_cell: int = Field(2, ge=1, le=6, description="material points per cell per axis")

    @property
    def upper(self) -> list[float]:
        """Upper corner of the domain, ``origin + size`` [m]."""
        return [o + s for o, s in zip(self.origin, self.size, strict=True)]

    def node_counts(self) -> list[int]:
        """Grid nodes per axis, ``ceil(size / cell_size) + 1``."""
        return [math.ceil(s / self.cell_size * (1 - 1e-12)) + 1 for s in self.size]


class Material(_Section):
    """``[materials.NAME]``: a hyperelastic (or linear-elastic) material."""

    law: Literal["neo-hookean", "linear-elastic"] = Field("neo-hookean", description="law")
    young: float = Field(gt=0, description="Young's modulus [Pa]")
    poisson: float = Field(gt=-1.0, lt=0.5, description="Poisson's ratio")
    density: float = Field(gt=0, description="mass density [kg/m^3]")


class VelocitySine(_Section):
    """``[bodies.velocity_sine]``: adds ``amplitude * sin(k . (x - origin))`` to the velocity."""

    amplitude: list[float] = Field(description="velocity amplitude per axis [m/s]")
    wavenumber: list[float] = Field(description="wave vector k [rad/m]")
    origin: list[float] = Field(default_factory=_zero_vector, description="phase origin [m]")


class Body(_Section):
    """``[[bodies]]``: one explicit body; only the geometry keys of its ``shape`` are set."""

    name: str = Field("", description='unique name; empty -> "body<index>"')
    shape: Literal["disk", "rectangle", "polygon"]
    center: list[float] | None = Field(None, description="disk centre [m]")
    radius: float | None = Field(None, gt=0, description="disk radius [m]")
    lower: list[float] | None = Field(None, description="rectangle lower corner [m]")
    upper: list[float] | None = Field(None, description="rectangle upper corner [m]")
    vertices: list[list[float]] | None = Field(None, min_length=3, description="polygon [m]")
    material: str = Field(description="name of a [materials] entry")
    kind: Literal["deformable", "kinematic"] = Field("deformable", description="body kind")
    velocity: list[float] = Field(
        default_factory=_zero_vector,
        description="initial velocity [m/s] (the prescribed rigid velocity if kinematic)",
    )
    velocity_gradient: list[list[float]] | None = Field(
        None, description="initial velocity gradient L [1/s]: adds L (x - centroid)"
    )
    velocity_sine: VelocitySine | None = Field(None, description="initial sine velocity field")
    seeding: Literal["lattice", "rings"] = Field(
        "lattice", description="material points on the grid-aligned sub-lattice, or on "
        "concentric rings (disks only: a round boundary instead of a staircase)")
    outer_ring_density: int = Field(
        1, ge=1, le=2, description="seeding = 'rings': points on the outermost ring per "
        "point spacing along it (each of 1/density the volume); the outer points are the "
        "disk's contact sites against other grains (experimental: redundant sites, more "
        "than the nodal velocities can tell apart, can leave a dense frictional packing's "
        "contact problem without a solution; 3 did, and 2 on one sample in six)")
    _generated: bool = PrivateAttr(False)  # made by [sample], not written back

    @property
    def generated(self) -> bool:
        return self._generated

    def area(self) -> float:
        """Area of the shape [m^2]."""
        if self.shape == "disk":
            return math.pi * self.radius * self.radius
        if self.shape == "rectangle":
            return math.prod(u - lo for lo, u in zip(self.lower, self.upper, strict=True))
        return abs(_signed_area(self.vertices))

    def centroid(self) -> list[float]:
        """Centroid of the shape [m] (a disk's centre): the reference of ``velocity_gradient``."""
        if self.shape == "disk":
            return list(self.center)
        if self.shape == "rectangle":
            return [(lo + u) / 2 for lo, u in zip(self.lower, self.upper, strict=True)]
        vertices = self.vertices
        area = _signed_area(vertices)
        cx = cy = 0.0
        for (x0, y0), (x1, y1) in zip(vertices, vertices[1:] + vertices[:1], strict=True):
            cross = x0 * y1 - x1 * y0
            cx += (x0 + x1) * cross
            cy += (y0 + y1) * cross
        return [cx / (6 * area), cy / (6 * area)]

    def bounds(self) -> tuple[list[float], list[float]]:
        """Lower and upper corners of the shape's bounding box [m]."""
        if self.shape == "disk":
            return [c - self.radius for c in self.center], [c + self.radius for c in self.center]
        if self.shape == "rectangle":
            return list(self.lower), list(self.upper)
        columns = list(zip(*self.vertices, strict=True))
        return [min(column) for column in columns], [max(column) for column in columns]

    @model_validator(mode="after")
    def _check_keys(self) -> Body:
        problems = []
        for shape, keys in SHAPE_KEYS.items():
            for key in keys:
                value = getattr(self, key)
                if shape == self.shape and value is None:
                    problems.append(Problem((key,), MISSING, f"required for shape = '{shape}'"))
                elif shape != self.shape and value is not None:
                    message = f"only for shape = '{shape}', not '{self.shape}': remove it"
                    problems.append(Problem((key,), value, message))
        if self.seeding == "rings" and self.shape != "disk":
            message = f"'rings' is only for shape = 'disk', not '{self.shape}': use 'lattice'"
            problems.append(Problem(("seeding",), self.seeding, message))
        problems += _outer_ring_problems(self.seeding, self.outer_ring_density)
        if self.kind == "kinematic":
            for key in ("velocity_gradient", "velocity_sine"):
                value = getattr(self, key)
                if value is not None:
                    message = "only for kind = 'deformable' (a kinematic body moves rigidly)"
                    problems.append(Problem((key,), value, message))
        if problems:
            raise Problems(problems)
        return self


class Boundary(_Section):
    """``[[boundary]]``: prescribed velocity components on the grid nodes inside a box."""

    lower: list[float] = Field(description="lower corner of the box [m] (inclusive)")
    upper: list[float] = Field(description="upper corner of the box [m] (inclusive)")
    components: list[Literal["x", "y", "z"]] = Field(min_length=1, description="components")
    velocity: list[float] = Field(default_factory=_zero_vector, description="velocity [m/s]")
    bodies: list[str] = Field(
        default_factory=list, description="bodies it applies to (empty: all deformable bodies)"
    )


class Gravity(_Section):
    """``[gravity]``: a uniform body acceleration."""

    acceleration: list[float] = Field(default_factory=_zero_vector, description="[m/s^2]")


class FrictionPair(_Section):
    """``[[contact.pairs]]``: the Coulomb coefficient between two named bodies."""

    bodies: list[str] = Field(min_length=2, max_length=2, description="two body names")
    friction: float = Field(ge=0.0, le=10.0, description="Coulomb coefficient")


class ContactSettings(_Section):
    """``[contact]``: frictional contact between bodies (Contact Dynamics)."""

    enabled: bool = Field(True, description="contact between bodies on or off")
    friction: float = Field(0.0, ge=0.0, le=10.0, description="Coulomb coefficient (global)")
    wall_friction: float | None = Field(
        None, ge=0.0, le=10.0, description="between a grain and a kinematic body (default: "
        "friction)")
    pairs: list[FrictionPair] = Field(default_factory=list,
                                      description="friction of named body pairs")
    gap: bool = Field(True, description="act only when the boundaries meet (ALGORITHM.md §4)")
    keep_closed: bool = Field(
        False, description="a contact that carried an impulse at the previous step starts "
        "the step closed (gap 0: the integrator's end-of-step prediction) unless the fresh "
        "estimate says the bodies overlap, so that the estimate's scatter cannot ratchet "
        "loaded bodies into each other (opt-in while it is measured: docs/dev-notes.md)")
    end_gap_check: bool = Field(
        True, description="after each converged step, the point contacts' gaps evaluated "
        "at the end of the step (points and surfaces moved): where the linearised gap "
        "missed an overlap below min(start gap, -0.025 h) (by 0.002 h; past 0.04 h by any "
        "amount, so that small errors of one sign do not creep on), the constraint is "
        "corrected and "
        "the step solved again (at most 3 times; a step whose gaps have not settled then "
        "is retried shorter). Keeps the linearisation's errors from adding up; the "
        "energy the corrections put in is series.csv's gap_correction_work")
    adaptive_reach: bool = Field(
        True, description="look for a step's point contacts only as far as the grains can "
        "move in it: within 2 x the relative motion the last step's fastest point predicts "
        "(at least 0.5 h; at most the kernel's reach, ~2 h); a step whose points then "
        "moved farther than that allowed is redone with the full reach (logged, "
        "summary.json contact_reach_retries). false: always the full reach")
    overlap_removal: float = Field(
        0.0, ge=0.0, le=1.0, description="fraction of an estimated overlap between two "
        "bodies removed per step (0: overlaps are only kept from growing)")
    overlap_tolerance: float = Field(
        0.0, ge=0.0, le=10.0, description="estimated overlap, in cells h, that the removal "
        "leaves alone (only the excess is removed)")
    normal: Literal["difference", "alpha", "beta"] = Field(
        "difference", description="contact normal from the mass gradients of both bodies, "
        "or of α or β alone (exact face normals against kinematic rectangles and disks)")
    grain_sites: Literal["surface", "nodes"] = Field(
        "surface", description="where two grains' contacts act: at the grains' outer "
        "points against the other's kernel-smoothed surface (see grain_passes), or at the "
        "nodes they share (the contact of sessions 1-10, which lets loaded grains into each "
        "other)")
    grain_passes: Literal["auto", "two", "one"] = Field(
        "auto", description="with grain_sites = \"surface\": \"auto\": one pass for a "
        "pair with friction, two for a frictionless pair; \"two\": the outer points of both "
        "grains of a pair against the other's surface; \"one\": those of one grain only (a "
        "ring-seeded grain's against another seeding, else the grain with fewer points): "
        "half the sites, a 1.5-1.6x cheaper dense frictional step, and C9's h halving within 1%; "
        "the other grain's points are not constraints (summary.json reports how deep they "
        "go: up to ~0.1 h at 300 sigma0). Without friction one pass holds loaded grains "
        "(the surface sides' levers, since 2026-12-06), but on the frictionless example its "
        "loaded contacts reach the gap limit (0.040 h against 0.027 h with two "
        "passes): \"one\" on frictionless pairs is experimental (docs/dev-notes.md, #11 "
        "next step 000)")
    wall_sites: Literal["nodes", "surface", "points"] = Field(
        "points", description="where a grain's contacts with a kinematic rectangle or disk "
        "act: at each of the grain's points within reach against the wall's exact face, the "
        "force at the edge of the point's cell (\"points\"); at the nodes they share (exact "
        "face normals, but loaded grains creep into the wall); or the points grouped in "
        "patches of about h "
        "(\"surface\", cheaper, but the patch's mean constrains the patch, not each "
        "point); docs/dev-notes.md")
    local_relation: Literal["delassus", "lumped"] = Field(
        "delassus", description="local compliance: Delassus (bodies' Newton matrices) or "
        "lumped nodal masses")
    tolerance: float = Field(1e-4, gt=0.0, lt=1.0, description="relative complementarity "
                             "(natural-map) residual of the contacts, and the bodies' residual "
                             "relative to the largest impulse")
    max_iterations: int = Field(200, ge=1, le=100000,
                                description="coupling iterations (a Newton update of the bodies "
                                "and a complete contact solve each); a step whose loop makes no "
                                "progress in 40 iterations in a row stops earlier, unconverged "
                                "(a cycle: retried with a smaller dt)")
    solver: Literal["newton", "nsgs"] = Field(
        "newton", description="contact problem solver: semismooth Newton (Alart-Curnier) or "
        "nonlinear Gauss-Seidel")
    solver_iterations: int = Field(50, ge=1, le=100000, description="per contact solve: "
                                   "Newton iterations or Gauss-Seidel sweeps")
    on_failure: Literal["stop", "warn"] = Field(
        "stop", description="when the loop does not converge: stop the run, or warn, flag "
        "the step in series.csv and go on")

    @model_validator(mode="after")
    def _check_passes(self) -> ContactSettings:
        if self.grain_passes == "one" and self.grain_sites != "surface":
            message = ('one pass is a choice of the point-to-surface contact; with '
                       'grain_sites = "nodes" the grains meet at shared nodes: set '
                       'grain_sites = "surface" or leave grain_passes out')
            raise Problems([Problem(("grain_passes",), self.grain_passes, message)])
        return self


class SampleSettings(_Section):
    """``[sample]``: grains deposited at random (seeded) in a box of four kinematic walls."""

    count: int = Field(ge=1, le=100000, description="number of disks")
    mean_diameter: float = Field(gt=0, description="mean diameter d [m]")
    polydispersity: float = Field(
        0.2, ge=0.0, lt=1.0, description="diameters uniform in [d(1-p), d(1+p)]")
    box_width: float = Field(gt=0, description="inner width of the box [m]")
    material: str = Field(description="material of the grains")
    wall_material: str | None = Field(None, description="material of the walls (default: "
                                      "the grains')")
    wall_thickness: float | None = Field(None, gt=0, description="[m] (default: 3 cells)")
    clearance: float | None = Field(
        None, ge=0, description="gap left between grains and walls at the deposit [m] "
        "(default: DEPOSIT_CLEARANCE × mean_diameter, the same deposit at every cell size)")
    seeding: Literal["lattice", "rings"] = Field(
        "rings", description="material points of the grains: concentric rings (a round "
        "grain of exactly its volume) or the grid-aligned lattice (a staircase whose "
        "corners make the grains rough at the scale of the cell: the packing fraction "
        "then moves with h; see [[bodies]] seeding)")
    outer_ring_density: int = Field(
        1, ge=1, le=2, description="seeding = 'rings': points on each grain's outermost "
        "ring per point spacing along it (see [[bodies]] outer_ring_density)")

    @model_validator(mode="after")
    def _check_outer_ring(self) -> SampleSettings:
        problems = _outer_ring_problems(self.seeding, self.outer_ring_density)
        if problems:
            raise Problems(problems)
        return self


class ProtocolSettings(_Section):
    """``[protocol]``: a loading programme driving the walls of a ``[sample]``."""

    kind: Literal["uniaxial-compaction"] = Field(description="the protocol")
    sigma0: float = Field(gt=0, description="pre-compaction stress σ0 on the top wall [Pa]")
    wall_speed: float = Field(5.0, gt=0, description="top-wall speed in compaction [m/s]")
    precompaction_speed: float = Field(
        0.05, gt=0, description="largest top-wall speed of the stress control [m/s]")
    precompaction_dt: float | None = Field(
        None, gt=0, description="time step of the pre-compaction [s] (default: dt)")
    precompaction_friction: float | None = Field(
        None, ge=0.0, le=10.0, description="Coulomb coefficient of every body pair during the "
        "pre-compaction (default: the [contact] ones); 0 prepares the sample without friction "
        "and the [contact] friction acts from σ0 on")
    stress_tolerance: float = Field(
        0.01, gt=0, lt=1, description="equilibrium: |σ − σ0| ≤ tolerance σ0")
    kinetic_ratio: float = Field(
        1e-3, gt=0, lt=1, description="equilibrium: kinetic ≤ ratio × strain energy")
    wall_speed_ramp: float = Field(
        0.0, ge=0.0, description="time for the top wall to reach wall_speed from rest [s] "
        "(0: at once)")
    precompaction_max_steps: int | None = Field(
        None, ge=1, description="start the compaction after this many pre-compaction steps "
        "even out of equilibrium (logged)")
    stop_stress_ratio: float | None = Field(
        1000.0, gt=1, description="stop when σ_yy/σ0 reaches this")
    stop_packing_fraction: float | None = Field(
        None, gt=0, lt=1, description="stop when φ reaches this")
    label: str = Field("", description="name of the run in figures (default: from friction)")


class OutputSettings(_Section):
    """``[output]``: what is written, and how often."""

    interval: int = Field(10, ge=1, description="steps between rows of series.csv / bodies.csv")
    snapshot_interval: int = Field(100, ge=0, description="steps between snapshots (0 = none)")
    progress: bool = Field(True, description="progress bar on a terminal")
    checkpoint_interval: int = Field(
        0, ge=0, description="steps between checkpoints (0 = by wall-clock time only)")
    checkpoint_minutes: float = Field(
        10.0, ge=0.0, description="wall-clock minutes between checkpoints (0 = by steps "
        "only); a checkpoint is also written at the end and when the run is interrupted")


class Case(_Section):
    """A whole case file."""

    simulation: SimulationSettings
    grid: GridSettings
    materials: dict[str, Material] = Field(min_length=1)
    bodies: list[Body] = Field(default_factory=list)
    sample: SampleSettings | None = None
    protocol: ProtocolSettings | None = None
    boundary: list[Boundary] = Field(default_factory=list)
    gravity: Gravity = Field(default_factory=Gravity)
    contact: ContactSettings = Field(default_factory=ContactSettings)
    output: OutputSettings = Field(default_factory=OutputSettings)

    _layout: object = PrivateAttr(None)

    @property
    def user_bodies(self) -> list[Body]:
        """The bodies written in the case file (not those generated by ``[sample]``)."""
        return [b for b in self.bodies if not b.generated]

    @model_validator(mode="after")
    def _check_consistency(self) -> Case:
        for index, body in enumerate(self.bodies):
            body.name = body.name or f"body{index}"
        problems = self._sample_problems()
        if problems:
            raise Problems(problems)
        problems = self._length_problems()
        if not problems:  # the other checks rely on vectors of the right length
            problems = self._reference_problems() + self._geometry_problems()
            problems += self._size_problems()
        if self.simulation.mass_matrix == "consistent" and self.grid.points_per_cell < 2:
            message = ('needs grid.points_per_cell >= 2: with one point per cell the '
                       'consistent mass matrix is singular; use "lumped"')
            problems.append(Problem(("simulation", "mass_matrix"), "consistent", message))
        if problems:
            raise Problems(problems)
        return self

    def _sample_problems(self) -> list[Problem]:
        """Generate the ``[sample]`` grains and walls (and the grid extent when not given);
        a protocol needs a sample; there must be a body."""
        sample, grid = self.sample, self.grid
        if self.protocol is not None and sample is None:
            return [Problem(("protocol", "kind"), self.protocol.kind,
                            "needs a [sample] (its walls are what the protocol drives)")]
        if sample is None:
            if grid.size is None:
                return [Problem(("grid", "size"), MISSING,
                                "required (it has a default only with a [sample])")]
            if not self.bodies:
                return [Problem(("bodies",), MISSING, "required: give [[bodies]] or a [sample]")]
            return []
        from softgrains.sample import box_layout  # light: NumPy only

        problems = []
        for key in ("material", "wall_material"):
            name = getattr(sample, key)
            if name is not None and name not in self.materials:
                problems.append(Problem(("sample", key), name, "no such material"
                                        + suggest(name, list(self.materials))))
        if problems:
            return problems
        spacing = grid.cell_size / grid.points_per_cell
        ratio = sample.mean_diameter / spacing  # (a float ** 2 raises OverflowError)
        points = sample.count * math.pi / 4 * ratio * ratio
        if points > MAX_POINTS:
            message = (f"gives about {points:.3g} material points in the grains, at most "
                       f"{MAX_POINTS:.0e} allowed: fewer or smaller grains, or a larger "
                       "grid.cell_size")
            return [Problem(("sample", "count"), sample.count, message)]
        try:
            layout = box_layout(
                sample.count, sample.mean_diameter, sample.polydispersity, sample.box_width,
                self.simulation.seed,
                DEPOSIT_CLEARANCE * sample.mean_diameter if sample.clearance is None
                else sample.clearance,
                sample.wall_thickness or 3.0 * grid.cell_size)
        except ValueError as error:
            return [Problem(("sample",), f"count = {sample.count}", str(error))]
        self.bodies = [b for b in self.bodies if not b.generated]
        names = {b.name for b in self.bodies}
        for table in layout.body_tables(sample.material, sample.wall_material or
                                        sample.material):
            if table["name"] in names:
                return [Problem(("bodies",), table["name"],
                                "this name is taken by a generated [sample] body; rename it")]
            if table["shape"] == "disk":
                table["seeding"] = sample.seeding
                table["outer_ring_density"] = sample.outer_ring_density
            body = Body(**table)
            body._generated = True
            self.bodies.append(body)
        if grid.size is None:
            grid.origin, grid.size = layout.domain(grid.cell_size)
        self._layout = layout
        return []

    @property
    def layout(self):
        """The generated box (``sample.box.BoxLayout``), or None without a [sample]."""
        return self._layout

    def _length_problems(self) -> list[Problem]:
        """Every vector must have one entry per axis (every matrix one row per axis)."""
        vectors: dict[tuple[str | int, ...], list | None] = {
            ("grid", "origin"): self.grid.origin,
            ("grid", "size"): self.grid.size,
            ("gravity", "acceleration"): self.gravity.acceleration,
        }
        for i, body in enumerate(self.bodies):
            for key in ("center", "lower", "upper", "velocity", "velocity_gradient"):
                vectors["bodies", i, key] = getattr(body, key)
            for key in ("vertices", "velocity_gradient"):
                for j, row in enumerate(getattr(body, key) or []):
                    vectors["bodies", i, key, j] = row
            if body.velocity_sine is not None:
                for key in ("amplitude", "wavenumber", "origin"):
                    vectors["bodies", i, "velocity_sine", key] = getattr(body.velocity_sine, key)
        for i, condition in enumerate(self.boundary):
            for key in ("lower", "upper", "velocity"):
                vectors["boundary", i, key] = getattr(condition, key)
        dim = self.simulation.dimension
        return [
            Problem(loc, vector, f"must have {dim} entries (one per axis), not {len(vector)}")
            for loc, vector in vectors.items()
            if vector is not None and len(vector) != dim
        ]

    def _reference_problems(self) -> list[Problem]:
        """Materials and bodies named elsewhere must exist; names and components be unique."""
        problems = []
        names = [body.name for body in self.bodies]
        for i, body in enumerate(self.bodies):
            if body.material not in self.materials:
                message = "no such material" + suggest(body.material, list(self.materials))
                problems.append(Problem(("bodies", i, "material"), body.material, message))
            if body.name in names[:i]:
                problems.append(Problem(("bodies", i, "name"), body.name, "duplicate body name"))
        axes = AXES[: self.simulation.dimension]
        for i, condition in enumerate(self.boundary):
            components = condition.components
            if not set(components) <= set(axes) or len(set(components)) != len(components):
                message = f"must be distinct entries of {list(axes)}"
                problems.append(Problem(("boundary", i, "components"), components, message))
            for j, name in enumerate(condition.bodies):
                if name not in names:
                    message = "no such body" + suggest(name, names)
                    problems.append(Problem(("boundary", i, "bodies", j), name, message))
        return problems

    def _geometry_problems(self) -> list[Problem]:
        """Shapes must be proper and lie inside the grid domain; boundary boxes not be inverted."""
        problems = []
        for i, body in enumerate(self.bodies):
            problems += [
                Problem(("bodies", i, *loc), value, message)
                for loc, value, message in self._shape_problems(body)
            ]
        for i, condition in enumerate(self.boundary):
            if any(u < lo for lo, u in zip(condition.lower, condition.upper, strict=True)):
                message = f"each entry must be >= lower = [{_vector(condition.lower)}]"
                problems.append(Problem(("boundary", i, "upper"), condition.upper, message))
        return problems

    def _shape_problems(self, body: Body) -> list[Problem]:
        """A rectangle must not be inverted, a polygon not be flat, no shape leave the domain."""
        if body.shape == "rectangle" and any(
            u <= lo for lo, u in zip(body.lower, body.upper, strict=True)
        ):
            message = f"each entry must be > lower = [{_vector(body.lower)}]"
            return [Problem(("upper",), body.upper, message)]
        if body.shape == "polygon" and _signed_area(body.vertices) == 0:
            message = "the polygon has zero area: give at least 3 non-collinear vertices"
            return [Problem(("vertices",), body.vertices, message)]
        lower, upper = body.bounds()
        below = any(b < d for b, d in zip(lower, self.grid.origin, strict=True))
        above = any(b > d for b, d in zip(upper, self.grid.upper, strict=True))
        if not (below or above):
            return []
        rectangle_key = "lower" if below else "upper"
        key = {"disk": "center", "rectangle": rectangle_key, "polygon": "vertices"}[body.shape]
        message = (
            f"the {body.shape} reaches from [{_vector(lower)}] to [{_vector(upper)}], outside the "
            f"grid domain from [{_vector(self.grid.origin)}] to [{_vector(self.grid.upper)}]: "
            "move it or change grid.origin / grid.size"
        )
        return [Problem((key,), getattr(body, key), message)]

    def _size_problems(self) -> list[Problem]:
        """The run must fit: bounded numbers of grid nodes and material points."""
        problems = []
        grid = self.grid
        nodes = math.prod(s / grid.cell_size + 1 for s in grid.size)
        if nodes > MAX_NODES:
            message = (
                f"too many grid nodes: about {nodes:.3g}, at most {MAX_NODES:.0e} allowed: "
                "use a larger cell_size or a smaller grid.size"
            )
            problems.append(Problem(("grid", "cell_size"), grid.cell_size, message))
        points = sum(estimate_points(body, grid) for body in self.bodies)
        if points > MAX_POINTS:
            message = (
                f"too many points: about {points:.3g} material points estimated, at most "
                f"{MAX_POINTS:.0e} allowed: use a larger cell_size or fewer points_per_cell"
            )
            problems.append(Problem(("grid", "cell_size"), grid.cell_size, message))
        return problems


def estimate_points(body: Body, grid: GridSettings) -> float:
    """Estimated number of material points of ``body``: its area / (h / points_per_cell)^2."""
    points_per_length = grid.points_per_cell / grid.cell_size
    return body.area() * math.prod(points_per_length for _ in grid.size)


def _signed_area(vertices: list[list[float]]) -> float:
    """Signed area of a polygon (shoelace formula), positive when counter-clockwise."""
    pairs = zip(vertices, vertices[1:] + vertices[:1], strict=True)
    return 0.5 * sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in pairs)


def _vector(values: list[float]) -> str:
    """``1, 0.5`` for ``[1.0, 0.5]``: compact coordinates for messages."""
    return ", ".join(f"{v:g}" for v in values)


def suggest(name: str, choices: list[str]) -> str:
    """``"; did you mean 'x'?"`` for a close choice, else ``"; expected one of 'a', 'b'"``."""
    close = difflib.get_close_matches(name, choices, n=1)
    if not choices:
        return ""
    if close:
        return f"; did you mean '{close[0]}'?"
    return "; expected one of " + ", ".join(f"'{choice}'" for choice in choices)

"""Model (what a run does not change) and State (what evolves), built from a validated Case.

Points of all bodies live in flat arrays, sorted by body: body b owns the slice
``model.bodies[b].points``. Per-point constants (mass, reference volume, law code, Lamé
parameters) sit in the Model; positions, velocities, accelerations, F, σ and V in the State.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from softgrains.errors import CaseError
from softgrains.geometry import (
    Disk,
    PointCells,
    Polygon,
    Rectangle,
    Shape,
    disk_ring_cells,
    lattice_cells,
    seed_disk_rings,
    seed_points,
)
from softgrains.grid.lattice import Lattice
from softgrains.grid.shape_functions import SHAPE_FUNCTIONS
from softgrains.integrator.implicit import DirichletBox, IntegratorSettings
from softgrains.materials import lame_parameters, law_code

AXES = "xyz"


@dataclass(frozen=True)
class BodySpec:
    """One body: name, kind, material and its slice of the point arrays."""

    index: int
    name: str
    kind: str  # "deformable" | "kinematic"
    material: str
    points: slice
    shape: Shape
    seeding: str = "lattice"  # "rings": disk points on concentric rings (geometry/shapes.py)
    outer_ring_density: int = 1  # rings: the outer ring's points per point spacing

    @property
    def deformable(self) -> bool:
        return self.kind == "deformable"


@dataclass
class Model:
    dim: int
    lattice: Lattice
    shape_kind: int
    points_per_cell: int
    bodies: list[BodySpec]
    mass: np.ndarray
    vol0: np.ndarray
    body_id: np.ndarray
    law: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    gravity: np.ndarray
    integrator: IntegratorSettings
    constraints: dict[int, list[DirichletBox]] = field(default_factory=dict)
    contact: object = None  # the case's [contact] settings
    friction: np.ndarray | None = None  # (B, B) Coulomb coefficient per body pair

    @property
    def n_points(self) -> int:
        return self.mass.size

    @cached_property
    def deformable_points(self) -> np.ndarray:
        """Indices of the points of deformable bodies (kinematic walls are driven)."""
        return np.concatenate([np.arange(b.points.start, b.points.stop)
                               for b in self.bodies if b.deformable] or [np.arange(0)])

    @cached_property
    def reference_cells(self) -> PointCells:
        """Each point's reference cell (2D): the lattice square, or the ring sector of a
        ring-seeded disk (geometry.PointCells)."""
        spacing = self.lattice.h / self.points_per_cell
        return PointCells.concatenate([
            disk_ring_cells(body.shape, spacing, body.outer_ring_density)
            if body.seeding == "rings"
            else lattice_cells(self.vol0[body.points], self.dim) for body in self.bodies])


@dataclass
class State:
    time: float
    step: int
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    F: np.ndarray
    sigma: np.ndarray
    vol: np.ndarray
    body_velocity: np.ndarray  # (B, d): prescribed velocity of kinematic bodies
    body_offset: np.ndarray  # (B, d): rigid displacement of kinematic bodies since the start
    contacts: object = None  # the last step's ContactState (warm start of the next step)


def make_shape(body) -> Shape:
    """The geometric shape of a case body."""
    if body.shape == "disk":
        return Disk(np.asarray(body.center, dtype=float), float(body.radius))
    if body.shape == "rectangle":
        return Rectangle(np.asarray(body.lower, dtype=float), np.asarray(body.upper, dtype=float))
    return Polygon(np.asarray(body.vertices, dtype=float))


def _initial_velocity(body, shape: Shape, x: np.ndarray) -> np.ndarray:
    v = np.tile(np.asarray(body.velocity, dtype=float), (len(x), 1))
    if body.kind != "deformable":
        return v
    if getattr(body, "velocity_gradient", None) is not None:
        L = np.asarray(body.velocity_gradient, dtype=float)
        v += (x - shape.centroid) @ L.T
    sine = getattr(body, "velocity_sine", None)
    if sine is not None:
        k = np.asarray(sine.wavenumber, dtype=float)
        phase = (x - np.asarray(sine.origin, dtype=float)) @ k
        v += np.sin(phase)[:, None] * np.asarray(sine.amplitude, dtype=float)
    return v


def build(case) -> tuple[Model, State]:
    """Seed the bodies' points and set up Model and State from a validated Case."""
    sim, grid = case.simulation, case.grid
    dim = sim.dimension
    lattice = Lattice.covering(grid.origin, grid.size, grid.cell_size)
    xs, vs, masses, vols, laws, lams, mus, ids, bodies = [], [], [], [], [], [], [], [], []
    start = 0
    for b, body in enumerate(case.bodies):
        shape = make_shape(body)
        name = body.name or f"body{b}"
        if body.seeding == "rings":
            spacing = grid.cell_size / grid.points_per_cell
            if body.radius < spacing:
                raise CaseError(f"[bodies.{b}] ('{name}'): radius {body.radius:g} is below one "
                                f"point spacing ({spacing:g}) for seeding = 'rings'; make it "
                                "larger or the grid finer.")
            x, v0 = seed_disk_rings(shape, spacing, body.outer_ring_density)
        else:
            x, v0 = seed_points(shape, lattice.domain_lower, grid.cell_size,
                                grid.points_per_cell)
        if len(x) == 0:
            raise CaseError(f"[bodies.{b}] ('{name}'): the shape holds no material point at "
                            f"cell_size {grid.cell_size} and points_per_cell "
                            f"{grid.points_per_cell}; make it larger or the grid finer.")
        mat = case.materials[body.material]
        lam, mu = lame_parameters(mat.young, mat.poisson)
        n = len(x)
        xs.append(x)
        vs.append(_initial_velocity(body, shape, x))
        masses.append(mat.density * np.broadcast_to(v0, n))
        vols.append(np.broadcast_to(v0, n).astype(float))
        laws.append(np.full(n, law_code(mat.law), dtype=np.int64))
        lams.append(np.full(n, lam))
        mus.append(np.full(n, mu))
        ids.append(np.full(n, b, dtype=np.int64))
        bodies.append(BodySpec(b, name, body.kind, body.material, slice(start, start + n), shape,
                               body.seeding, body.outer_ring_density))
        start += n
    x = np.concatenate(xs)
    n = len(x)
    gravity = np.zeros(dim)
    if getattr(case, "gravity", None) is not None:
        gravity = np.asarray(case.gravity.acceleration, dtype=float)
    settings = IntegratorSettings(
        kind=sim.integrator, theta=sim.theta, beta=sim.newmark_beta, gamma=sim.newmark_gamma,
        flip=sim.flip, mass_matrix=sim.mass_matrix, tolerance=sim.newton_tolerance,
        max_iterations=sim.newton_max_iterations,
        linear_solver=sim.linear_solver, tangent=sim.tangent,
        stress_form=sim.stress_form)
    model = Model(
        dim=dim, lattice=lattice, shape_kind=SHAPE_FUNCTIONS[grid.shape_function],
        points_per_cell=grid.points_per_cell, bodies=bodies, mass=np.concatenate(masses),
        vol0=np.concatenate(vols), body_id=np.concatenate(ids), law=np.concatenate(laws),
        lam=np.concatenate(lams), mu=np.concatenate(mus), gravity=gravity, integrator=settings,
        constraints=_constraints(case, bodies, dim), contact=case.contact,
        friction=friction_matrix(case.contact, bodies))
    state = State(
        time=0.0, step=0, x=x, v=np.concatenate(vs), a=np.zeros((n, dim)),
        F=np.tile(np.eye(dim), (n, 1, 1)), sigma=np.zeros((n, 3, 3)),
        vol=model.vol0.copy(),
        body_velocity=np.array([np.asarray(cb.velocity, dtype=float) for cb in case.bodies]),
        body_offset=np.zeros((len(case.bodies), dim)))
    return model, state


def _constraints(case, bodies: list[BodySpec], dim: int) -> dict[int, list[DirichletBox]]:
    by_name = {b.name: b.index for b in bodies}
    out: dict[int, list[DirichletBox]] = {b.index: [] for b in bodies if b.deformable}
    for bc in getattr(case, "boundary", None) or []:
        comps = np.array([AXES[j] in bc.components for j in range(dim)])
        box = DirichletBox(np.asarray(bc.lower, dtype=float), np.asarray(bc.upper, dtype=float),
                           comps, np.asarray(bc.velocity, dtype=float))
        unknown = [nm for nm in bc.bodies if nm not in by_name]
        if unknown:
            raise CaseError(f"[boundary].bodies = {unknown}: no body of that name; "
                            f"known bodies: {sorted(by_name)}")
        targets = [by_name[nm] for nm in bc.bodies] if bc.bodies else list(out)
        for t in targets:
            if t in out:
                out[t].append(box)
    return out


def friction_matrix(contact, bodies: list[BodySpec]) -> np.ndarray:
    """μ per body pair: ``friction`` between grains, ``wall_friction`` (default: friction)
    between a grain and a kinematic body, and ``[[contact.pairs]]`` for named pairs."""
    n = len(bodies)
    mu = np.full((n, n), contact.friction)
    wall = np.array([not b.deformable for b in bodies])
    if contact.wall_friction is not None:
        mu[wall, :] = contact.wall_friction
        mu[:, wall] = contact.wall_friction
    by_name = {b.name: b.index for b in bodies}
    for i, pair in enumerate(contact.pairs):
        unknown = [nm for nm in pair.bodies if nm not in by_name]
        if unknown:
            raise CaseError(f"[contact.pairs.{i}].bodies = {pair.bodies}: no body named "
                            f"{unknown}; known bodies: {sorted(by_name)[:10]}")
        a, b = (by_name[nm] for nm in pair.bodies)
        mu[a, b] = mu[b, a] = pair.friction
    return mu

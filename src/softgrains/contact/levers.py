"""Where a grain's surface takes another grain's impulse: the lever of a kernel surface.

In a point-to-surface contact between grains (surfaces.py) the impulse acts on the grain
whose kernel surface the point meets (the *surface side*) through that grain's stencil at
the point's start position x_s, fixed in space. The θ-step balances the bodies' momentum
about the start nodes, while its internal forces f_int(u) are torque-free only about the
moved nodes: each body gains the angular impulse −Σ_I u_I × s_f f_int,I a step (u the
step's displacement; for a pre-stressed grain turning at ω, +θΔt²ω Σ P R, the sign of ω).
An impulse taken at a material point (the point's own side, a wall contact) is applied at
that point's start position and its moment carries the same error with the opposite
sign: for a body in balance the two cancel. On the surface side nothing cancels it, and a
loaded round grain that only kernel surfaces hold from turning spins up
(docs/dev-notes.md, #11 next step 000).

The lever puts the surface side's impulse where that grain's material that meets the site
at the end of the step started: x_s + δ, δ = u_point(x_s) − u_surface(x_s), the relative
displacement of the step at the site. The change of moment, δ × P, is added to the
surface grain as a rigid-rotation impulse (g_I = m_I ω × r_I, J ω = Σ δ × P, r about the
grain's nodal mass centre: zero net impulse). It is taken at the bodies' current iterates
and the last contact solve's impulses, outside the contact problem: a δ inside the
problem's rows, fixed at the start of the step, made the contact solve reverse a grain's
spin to open its gaps (tried in session 46).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from softgrains.integrator.rotations import mass_centred


@dataclass(frozen=True)
class SurfaceSides:
    """The grain-to-grain point contacts whose surface side is a deformable grain: the
    contact's index in the coupled problem, both sides' bodies and stencils (active rows,
    −1: none, and weights) and the sign of the impulse on the surface side (+1 where it
    is α)."""

    contact: np.ndarray
    surface: np.ndarray
    owner: np.ndarray
    surface_rows: np.ndarray
    surface_weights: np.ndarray
    owner_rows: np.ndarray
    owner_weights: np.ndarray
    sign: np.ndarray

    def __len__(self) -> int:
        return self.contact.size


def surface_sides(points, point_contact: np.ndarray, steps: dict,
                  one_pass: Callable[[int, int], bool]) -> SurfaceSides | None:
    """The surface sides of the point contacts ``points`` (surfaces.SurfaceContacts) that
    are contacts of their own (``point_contact`` ≥ 0: their index) between two grains of
    ``steps`` taken in one pass (``one_pass(α, β)``); None if there are none.

    Not with two passes: a pair's impulse is then split between its two passes' sites as
    the redundant (singular) W leaves it, the split moves from solve to solve and the
    levers' moments with it. On the frictionless example (two passes) that took the
    coupling loop from 2.6 to 6.2 iterations a compaction step and the run 1.7× the time
    (session 46); there each grain's own points carry a share of the impulses, and their
    moments held the grains (session 45)."""
    surface = np.where(points.owner_is_alpha, points.beta, points.alpha)
    pairs = np.stack([points.alpha, points.beta], axis=1)
    distinct, which = np.unique(pairs, axis=0, return_inverse=True)
    single = np.array([one_pass(int(a), int(b)) for a, b in distinct], bool)
    # a body whose internal forces have the momentum form keeps its angular momentum by
    # itself: its lever would add the moment δ × P the pair's impulses do not have
    balanced = [b for b, step in steps.items() if not step.momentum_form]
    keep = np.flatnonzero((point_contact >= 0) & single[which.ravel()]
                          & np.isin(surface, balanced)
                          & np.isin(np.where(points.owner_is_alpha, points.alpha,
                                             points.beta), list(steps)))
    if keep.size == 0:
        return None
    alpha_owns = points.owner_is_alpha[keep][:, None]
    return SurfaceSides(
        contact=point_contact[keep], surface=surface[keep],
        owner=np.where(points.owner_is_alpha, points.alpha, points.beta)[keep],
        surface_rows=np.where(alpha_owns, points.rows_beta[keep], points.rows_alpha[keep]),
        surface_weights=np.where(alpha_owns, points.weights_beta[keep],
                                 points.weights_alpha[keep]),
        owner_rows=np.where(alpha_owns, points.rows_alpha[keep], points.rows_beta[keep]),
        owner_weights=np.where(alpha_owns, points.weights_alpha[keep],
                               points.weights_beta[keep]),
        sign=np.where(points.owner_is_alpha[keep], -1.0, 1.0))


def _at_sites(u: np.ndarray, rows: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Σ_k w_k u_{rows_k} per site (rows −1: none)."""
    return (u[np.maximum(rows, 0)] * (weights * (rows >= 0))[:, :, None]).sum(axis=1)


def moment(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b per row: a scalar per row in 2D, a vector in 3D."""
    if a.shape[1] == 2:
        return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return np.cross(a, b)


def _site_map(sides: SurfaceSides, steps: dict) -> tuple:
    """The bodies of ``sides`` (all their iterates stacked in this order), both sides'
    stencil rows into that stack (−1: none), and each site's surface grain as an index
    into the distinct surface grains (returned too)."""
    bodies = np.unique(np.r_[sides.surface, sides.owner])
    sizes = np.array([steps[int(b)].u.shape[0] for b in bodies])
    offset = np.r_[0, np.cumsum(sizes)[:-1]]
    at = np.searchsorted(bodies, sides.owner)
    owner_rows = np.where(sides.owner_rows >= 0, sides.owner_rows + offset[at][:, None], -1)
    at = np.searchsorted(bodies, sides.surface)
    surface_rows = np.where(sides.surface_rows >= 0,
                            sides.surface_rows + offset[at][:, None], -1)
    surfaces, which = np.unique(sides.surface, return_inverse=True)
    return bodies, owner_rows, surface_rows, surfaces, which


def lever_moments(sides: SurfaceSides, steps: dict, P: np.ndarray,
                  site_map: tuple | None = None) -> dict:
    """Per surface grain the moment Σ δ × P_surface of its sites' impulses ``P`` (on α,
    per contact) moved by the step's relative displacement δ = u_owner − u_surface at
    each site, the bodies' displacements their current iterates (``site_map``:
    :func:`_site_map`'s, if built)."""
    bodies, owner_rows, surface_rows, surfaces, which = (
        site_map if site_map is not None else _site_map(sides, steps))
    u = np.concatenate([steps[int(b)].u for b in bodies])
    delta = (_at_sites(u, owner_rows, sides.owner_weights)
             - _at_sites(u, surface_rows, sides.surface_weights))
    moments = moment(delta, sides.sign[:, None] * P[sides.contact])
    if moments.ndim == 1:
        total = np.bincount(which, moments, minlength=surfaces.size)
    else:
        total = np.stack([np.bincount(which, moments[:, k], minlength=surfaces.size)
                          for k in range(moments.shape[1])], axis=1)
    return dict(zip(surfaces.tolist(), total, strict=True))


def rotation_basis(step) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(m_I, r_I, J⁻¹): the active nodes' lumped masses, positions about their mass centre
    and the inverse of their polar (2D, 1 × 1) or inertia (3D) moment."""
    positions = step.stepper.lattice.node_positions(step.box, step.active)
    m = step.m[:, 0]
    r = mass_centred(positions, m)
    polar = float((m * (r * r).sum(axis=1)).sum())
    if r.shape[1] == 2:
        return m, r, np.array([[1.0 / polar]])
    inertia = polar * np.eye(3) - np.einsum("i,ij,ik->jk", m, r, r)
    return m, r, np.linalg.inv(inertia)


def rotation_impulses(basis: tuple, torque) -> np.ndarray:
    """Nodal impulses g_I = m_I ω × r_I, J ω = ``torque`` (``basis``: :func:`rotation_basis`):
    a rigid rotation's momentum carrying the angular impulse ``torque`` and no net
    impulse."""
    m, r, inverse = basis
    if r.shape[1] == 2:
        omega = inverse[0, 0] * float(torque)
        return m[:, None] * omega * np.stack([-r[:, 1], r[:, 0]], axis=1)
    return m[:, None] * np.cross(inverse @ np.asarray(torque, float), r)


class Levers:
    """The levers of one step's coupled loop: the surface sides, each surface grain's
    rotation basis (built once) and the impulses applied so far."""

    def __init__(self, sides: SurfaceSides, steps: dict) -> None:
        self.sides, self.steps = sides, steps
        self.applied: dict[int, np.ndarray] = {}
        self._bases: dict[int, tuple] = {}
        self._site_map = _site_map(sides, steps)

    def apply(self, P: np.ndarray) -> None:
        """Bring each surface grain's lever impulses to the moments of the impulses P at
        the bodies' current iterates. A body held by Dirichlet rows gets none (its supports
        take the moment)."""
        for body, torque in lever_moments(self.sides, self.steps, P,
                                          self._site_map).items():
            step = self.steps[body]
            if step.fixed.any():
                continue
            if body not in self._bases:
                self._bases[body] = rotation_basis(step)
            g = rotation_impulses(self._bases[body], torque)
            step.add_impulses(slice(None), g - self.applied.get(body, 0.0))
            self.applied[body] = g

    def work(self) -> float:
        """Σ_b g_b·u_b: the applied impulses' work (× Δt) over the step's displacements."""
        return sum(float(np.sum(g * self.steps[body].u)) for body, g in self.applied.items())

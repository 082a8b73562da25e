"""Contact and bulk together: the nonlinear Gauss–Seidel loop of ALGORITHM.md §6 (lumped
local relation).

    set up every deformable body's step; find the contact nodes and normals
    repeat:
        one Newton update of every body not yet converged (with the current impulses)
        Gauss–Seidel over the contacts: w^free = w − (1/m^α + 1/m^β) P with the latest
            end-of-step velocities, local Signorini–Coulomb solution (local_law.py),
            the impulse change moves both bodies' velocities by ±ΔP/m at the node
    until ‖P^k − P^{k−1}‖ ≤ tol ‖P^k‖ + floor and every body's residual has converged

Kinematic bodies take no impulse response (1/m = 0): their nodal velocity is their
prescribed velocity. With the gap treatment (gap.py, on by default) a contact acts only when
the bodies' boundaries would meet within the step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softgrains.contact.detection import ContactNodes, NodalField, find_contact_nodes
from softgrains.contact.gap import boundary_gaps
from softgrains.contact.local_law import OPEN, SLIP, STICK, local_impulse
from softgrains.errors import SimulationError
from softgrains.grid.lattice import Lattice

IMPULSE_FLOOR = 1e-14  # relative to the largest momentum of a contact node


@dataclass
class ContactDiagnostics:
    iterations: int = 0
    residual: float = 0.0
    n_contacts: int = 0
    active: int = 0
    sticking: int = 0
    sliding: int = 0


@dataclass
class ContactState:
    """The contacts of a step and their impulses (on α; −P on β)."""

    nodes: ContactNodes
    impulse: np.ndarray  # (n_contacts, d)
    status: np.ndarray  # OPEN / STICK / SLIP


def solve_coupled(lattice: Lattice, steps: dict, fields: list[NodalField],
                  wall_velocity: dict, wall_shape: dict, friction: float, tolerance: float,
                  max_iterations: int, step: int, dt: float,
                  gap_points: dict | None = None, spacing: float = 0.0,
                  reach: float = 0.0) -> tuple[ContactState, ContactDiagnostics]:
    """Run the coupled loop; ``steps`` maps deformable body index → BodyStep (not finished).

    ``wall_velocity`` and ``wall_shape`` map a kinematic body's index to its prescribed
    velocity and its current shape (exact face normals against walls). With ``gap_points``
    (body index → start-of-step point positions) the boundary gap of gap.py is used.
    """
    contacts = find_contact_nodes(lattice, fields, wall_shape)
    n = len(contacts)
    d = lattice.dim
    gaps = (boundary_gaps(lattice, contacts, gap_points, spacing, reach)
            if gap_points is not None else np.zeros(n))
    P = np.zeros((n, d))
    status = np.zeros(n, dtype=np.int64)
    diag = ContactDiagnostics(n_contacts=n)
    if n == 0:
        for s in steps.values():
            s.solve()
        return ContactState(contacts, P, status), diag

    def side(body, local):
        s = steps.get(body)
        if s is None:
            return None, -1
        return s, int(s.active_row[local])

    sides = [(side(a, la), side(b, lb)) for a, b, la, lb in zip(
        contacts.alpha, contacts.beta, contacts.local_alpha, contacts.local_beta, strict=True)]
    scale = 0.0
    for (sa, ra), (sb, rb) in sides:
        for s, r in ((sa, ra), (sb, rb)):
            if s is not None and r >= 0:
                scale = max(scale, float(s.m[r, 0] * np.abs(s.node_velocity(np.array([r]))).max()))
    floor = IMPULSE_FLOOR * max(scale, 1e-300)
    w_free = np.empty(d)
    P_new = np.empty(d)
    done = {i: b.converged(limit=False) for i, b in steps.items()}
    for k in range(1, max_iterations + 1):
        for i, b in steps.items():
            if not done[i]:
                b.newton_update()
        change = 0.0
        for c in range(n):
            (sa, ra), (sb, rb) = sides[c]
            if (sa is not None and ra < 0) or (sb is not None and rb < 0):
                continue  # the node carries no unknown in one body
            va = sa.node_velocity(np.array([ra]))[0] if sa else wall_velocity[contacts.alpha[c]]
            vb = sb.node_velocity(np.array([rb]))[0] if sb else wall_velocity[contacts.beta[c]]
            inv_m = (1.0 / sa.m[ra, 0] if sa else 0.0) + (1.0 / sb.m[rb, 0] if sb else 0.0)
            if inv_m == 0.0:
                continue
            w_free[:] = va - vb - inv_m * P[c]
            status[c] = local_impulse(w_free, contacts.normal[c], 1.0 / inv_m, 1.0 / inv_m,
                                      gaps[c] / dt, friction, P_new)
            dP = P_new - P[c]
            if np.any(dP != 0.0):
                if sa:
                    sa.apply_impulse(ra, dP)
                if sb:
                    sb.apply_impulse(rb, -dP)
                P[c] = P_new
                change = max(change, float(np.abs(dP).max()))
        for s in steps.values():
            s.refresh()
        diag.iterations = k
        diag.residual = change / max(float(np.abs(P).max()), floor)
        # a body's residual need not be finer than the impulses it carries (same units)
        p_scale = tolerance * float(np.abs(P).max())
        done = {i: b.converged(limit=False, floor=p_scale * b.impulse_weight)
                for i, b in steps.items()}
        if change <= p_scale + floor and all(done.values()):
            break
    else:
        raise SimulationError(
            f"step {step}: the contact loop did not converge in {max_iterations} iterations "
            f"(impulse change {diag.residual:.2e} of the largest impulse); try a smaller dt, "
            "more contact max_iterations or a looser contact tolerance.", step=step)
    diag.active = int(np.sum(status != OPEN))
    diag.sticking = int(np.sum(status == STICK))
    diag.sliding = int(np.sum(status == SLIP))
    return ContactState(contacts, P, status), diag

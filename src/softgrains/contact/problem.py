"""The frictional contact problem of one outer iteration, as plain data (ALGORITHM.md §5–6).

Contacts c = 1..n between bodies α (impulse +P) and β (−P). Every deformable body s in
contact carries k_s contact rows with velocities V_s (k_s, d) and a compliance W_s
(k_s d × k_s d): the change of those velocities per unit impulse at one of them (Delassus:
κ w [A⁻¹]_cc from the body's Newton matrix; lumped: diag(1/m)). A kinematic body (slot −1)
has W = 0 and a prescribed velocity. With Q_s(P) the impulses summed per row of s,

    V_s(P) = V_s^free + W_s Q_s(P),      w_c(P) = v^α_c(P) − v^β_c(P) = q_c + Σ_c' W_cc' P_c'

and the problem is: find P with, in each contact's frame (n, t), on w̃_n = w_n + b_c
(b_c: the gap bias of gap.py),

    Signorini  P_n ≥ 0, w̃_n ≥ 0, P_n w̃_n = 0;   Coulomb  ‖P_t‖ ≤ μ P_n, stick (w_t = 0)
    while ‖P_t‖ < μ P_n, else P_t = −μ P_n w_t/‖w_t‖.

The solvers (solvers.py) see only this object. :func:`natural_map_residual` is the error
measure all of them share: Φ = P − proj_K(P − ρ ŵ) with K the Coulomb cone and
ŵ = (w̃_n + μ‖w_t‖, w_t) (De Saxcé's modified velocity), zero exactly at a solution.
``save``/``load`` write a problem to an .npz file so that a hard step can be replayed.
Dimension-generic (2D, and 3D with its circular cone).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from numba import njit

from softgrains.contact.delassus import BlockRows, assemble, block_rows

FORMAT_VERSION = 1
VELOCITY_RESOLUTION = 1e-10  # relative: velocity differences below it are round-off
# the largest relative asymmetry of a body's compliance a problem may have (W is symmetric,
# BodyStep.contact_response; saved problems of sessions before 32 carry the LU's ~1e-10)
SYMMETRY_TOLERANCE = 1e-8


@dataclass
class ContactProblem:
    """One frictional contact problem (see the module docstring for the equations).

    Per contact: ``normal`` (n, d) from β into α, ``bias`` (n,) added to w_n, ``mu`` (n,),
    the slot of α's and β's body (−1: kinematic, with velocity ``wall_va``/``wall_vb``) and
    the column of the contact's row in that body's block. Per body slot: its rows' offset
    ``k_off`` and count ``k_size`` in ``V_free`` (k_total, d), and the offset ``w_off`` of its
    block (k d × k d, row-major, (row, component) order) in the flat array ``W``.
    """

    normal: np.ndarray
    bias: np.ndarray
    mu: np.ndarray
    a_slot: np.ndarray
    a_col: np.ndarray
    b_slot: np.ndarray
    b_col: np.ndarray
    wall_va: np.ndarray
    wall_vb: np.ndarray
    k_off: np.ndarray
    k_size: np.ndarray
    w_off: np.ndarray
    W: np.ndarray
    V_free: np.ndarray
    # per row (k_total, d, m): the body's rigid modes of inertia alone, scaled so that
    # G_c G_c'ᵀ is their share of W_s's block (c, c') (BodyStep.rigid_modes; empty: none)
    rigid: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 0)))
    # quantities derived from the data above, computed once (treat a problem as immutable)
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # every reader of W relies on its symmetry: the compliance products and the
        # Gauss–Seidel spreads read rows for columns, the Delassus product the rows of the
        # loaded contacts for their columns
        if self.asymmetry() > SYMMETRY_TOLERANCE:
            raise ValueError(f"the bodies' compliances W_s of a contact problem must be "
                             f"symmetric (relative asymmetry {self.asymmetry():.1e} > "
                             f"{SYMMETRY_TOLERANCE:.0e}): the solvers read W's columns as "
                             f"its rows")

    def _cached(self, name: str, compute):
        if name not in self._cache:
            self._cache[name] = compute()
        return self._cache[name]

    @property
    def n_contacts(self) -> int:
        return self.normal.shape[0]

    @property
    def dim(self) -> int:
        return self.normal.shape[1]

    # -- velocities ------------------------------------------------------------------
    def row_impulses(self, P: np.ndarray) -> np.ndarray:
        """Q: the impulses summed per body contact row (+P on α, −P on β)."""
        return row_impulses(self.a_slot, self.a_col, self.b_slot, self.b_col, self.k_off,
                            P, self.V_free.shape[0])

    def compliance_times(self, Q: np.ndarray) -> np.ndarray:
        """W_s Q_s for every body: the row velocity changes the row impulses Q give."""
        return _compliance_times(self.W, self.w_off, self.k_off, self.k_size,
                                 np.ascontiguousarray(Q, float))

    def asymmetry(self) -> float:
        """max_s max |W_s − W_sᵀ| / max |W_s| over the bodies' compliances."""
        return self._cached("asymmetry", lambda: _asymmetry(self.W, self.w_off, self.k_size,
                                                            self.dim))

    def row_velocities(self, P: np.ndarray) -> np.ndarray:
        """V(P) = V^free + W Q(P) at every body contact row."""
        return self.V_free + self.compliance_times(self.row_impulses(P))

    def relative_velocities(self, V: np.ndarray) -> np.ndarray:
        """w_c = v^α − v^β from the row velocities V (walls: their prescribed velocity)."""
        return relative_velocities(self.a_slot, self.a_col, self.b_slot, self.b_col,
                                   self.k_off, self.wall_va, self.wall_vb, V)

    def velocities(self, P: np.ndarray) -> np.ndarray:
        """w(P) (n, d), the relative velocities the impulses P give."""
        return self.relative_velocities(self.row_velocities(P))

    # -- the assembled operator -------------------------------------------------------
    def touches(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every (contact, body slot, column, sign) where a contact touches a deformable
        body (sign +1 on the α side, −1 on β), grouped by slot."""
        return self._cached("touches", self._touches)

    def _touches(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        a, b = self.a_slot >= 0, self.b_slot >= 0
        contact = np.r_[np.flatnonzero(a), np.flatnonzero(b)]
        slot = np.r_[self.a_slot[a], self.b_slot[b]]
        col = np.r_[self.a_col[a], self.b_col[b]]
        sign = np.r_[np.ones(a.sum()), -np.ones(b.sum())]
        order = np.argsort(slot, kind="stable")
        return contact[order], slot[order], col[order], sign[order]

    def delassus(self, frames: np.ndarray | None = None) -> sp.bsr_matrix:
        """W (n d × n d, (contact, component) order, d × d blocks): w = q + W P, in global
        axes or, with ``frames`` (n, d, d), in those contact frames (delassus.py).

        W_cc' = Σ_s σ_c σ_c' W_s[col_c, col_c'] over the bodies s that both contacts touch
        (σ = +1 on the α side, −1 on the β side).
        """
        if frames is None:
            frames = np.broadcast_to(np.eye(self.dim), (self.n_contacts, self.dim, self.dim))
        contact, slot, col, sign = self.touches()
        return assemble(contact, slot, col, sign, self.W, self.w_off, self.k_size, frames)

    def block_rows(self, frames: np.ndarray) -> BlockRows:
        """W in the contact ``frames`` by block rows assembled when first asked for
        (delassus.BlockRows: the solvers read only the rows of loaded contacts)."""
        contact, slot, col, sign = self.touches()
        return block_rows(contact, slot, col, sign, self.W, self.w_off, self.k_size, frames)

    def diagonal_blocks(self) -> np.ndarray:
        """W_cc (n, d, d): each contact's own compliance, Σ of its bodies' diagonal blocks."""
        return self._cached("Wcc", self._diagonal_blocks)

    def _diagonal_blocks(self) -> np.ndarray:
        d = self.dim
        contact, slot, col, _ = self.touches()
        kd = self.k_size[slot] * d
        p, q = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
        flat = (self.w_off[slot][:, None, None] + (col[:, None, None] * d + p) * kd[:, None, None]
                + col[:, None, None] * d + q)
        Wcc = np.zeros((self.n_contacts, d, d))
        np.add.at(Wcc, contact, self.W[flat])
        return Wcc

    def free_velocity(self) -> np.ndarray:
        """q = w(0) (n, d): the relative velocities without any impulse of this problem."""
        return self._cached("q", lambda: self.relative_velocities(self.V_free))

    def frames(self) -> np.ndarray:
        """(n, d, d): each contact's orthonormal frame, rows n, t1 (, t2)."""
        return self._cached("frames", lambda: contact_frames(self.normal))

    # -- files ------------------------------------------------------------------------
    def save(self, path: str | Path, **extra) -> None:
        """Write the problem to an .npz file (replay it with :meth:`load`); ``extra``
        arrays are stored beside it (e.g. a warm start, read by
        benchmarks/contact_solve_replay.py; :meth:`load` ignores them)."""
        names = {f.name for f in fields(self) if f.init} | {"format_version"}
        if clash := names & set(extra):
            raise ValueError(f"extra arrays may not be named like the problem's: {clash}")
        np.savez_compressed(path, format_version=FORMAT_VERSION, **extra,
                            **{f.name: getattr(self, f.name) for f in fields(self) if f.init})

    @classmethod
    def load(cls, path: str | Path) -> ContactProblem:
        with np.load(path) as data:
            if int(data["format_version"]) != FORMAT_VERSION:
                raise ValueError(f"{path}: contact problem format {int(data['format_version'])}"
                                 f", this version reads {FORMAT_VERSION}")
            # (problems saved before the field ``rigid`` existed load without it)
            return cls(**{f.name: data[f.name] for f in fields(cls)
                          if f.init and f.name in data})


@njit(cache=True, nogil=True)
def _compliance_times(W, w_off, k_off, k_size, Q):
    """W_s Q_s for every body slot s (its block W_s, k d × k d row-major at w_off[s] in W;
    its rows k_off[s] … + k_size[s] of Q (k_total, d)): W_s symmetric, Σ_i W_s[i, :] Q_i
    over the nonzero Q_i alone (its contiguous rows; most rows of a large problem carry
    no impulse)."""
    d = Q.shape[1]
    out = np.zeros_like(Q)
    flat_q, flat_out = Q.reshape(Q.size), out.reshape(out.size)
    for s in range(k_size.size):
        kd, base, first = k_size[s] * d, w_off[s], k_off[s] * d
        for i in range(kd):
            value = flat_q[first + i]
            if value == 0.0:
                continue
            row = base + i * kd
            for j in range(kd):
                flat_out[first + j] += W[row + j] * value
    return out


@njit(cache=True, nogil=True)
def _asymmetry(W, w_off, k_size, d):
    worst = 0.0
    for s in range(k_size.size):
        kd, at = k_size[s] * d, w_off[s]
        largest = difference = 0.0
        for i in range(kd):
            for j in range(kd):
                largest = max(largest, abs(W[at + i * kd + j]))
                if j > i:
                    difference = max(difference, abs(W[at + i * kd + j] - W[at + j * kd + i]))
        if largest > 0.0:
            worst = max(worst, difference / largest)
    return worst


@njit(cache=True, nogil=True)
def _row_impulses(a_slot, a_col, b_slot, b_col, k_off, P, k_total):
    Q = np.zeros((k_total, P.shape[1]))
    for c in range(a_slot.size):  # (all α sides first, then all β: the summation order
        if a_slot[c] >= 0:  # of the array version this replaced)
            Q[k_off[a_slot[c]] + a_col[c]] += P[c]
    for c in range(b_slot.size):
        if b_slot[c] >= 0:
            Q[k_off[b_slot[c]] + b_col[c]] += -P[c]
    return Q


def row_impulses(a_slot: np.ndarray, a_col: np.ndarray, b_slot: np.ndarray, b_col: np.ndarray,
                 k_off: np.ndarray, P: np.ndarray, k_total: int) -> np.ndarray:
    """Q (k_total, d): the impulses P summed per body contact row (+P on α, −P on β)."""
    return _row_impulses(a_slot, a_col, b_slot, b_col, k_off, np.ascontiguousarray(P, float),
                         int(k_total))


def relative_velocities(a_slot: np.ndarray, a_col: np.ndarray, b_slot: np.ndarray,
                        b_col: np.ndarray, k_off: np.ndarray, wall_va: np.ndarray,
                        wall_vb: np.ndarray, V: np.ndarray) -> np.ndarray:
    """w_c = v^α − v^β (n, d) from the body row velocities V; a kinematic side (slot −1)
    moves at its wall velocity."""
    va = np.where((a_slot >= 0)[:, None], V[k_off[np.maximum(a_slot, 0)] + a_col], wall_va)
    vb = np.where((b_slot >= 0)[:, None], V[k_off[np.maximum(b_slot, 0)] + b_col], wall_vb)
    return va - vb


def contact_frames(normal: np.ndarray) -> np.ndarray:
    """Orthonormal frames (n, d, d) with the normal first: 2D t = (−n_y, n_x); 3D two
    tangents from the axis least aligned with n."""
    n, d = normal.shape
    frames = np.zeros((n, d, d))
    frames[:, 0] = normal
    if d == 2:
        frames[:, 1, 0] = -normal[:, 1]
        frames[:, 1, 1] = normal[:, 0]
    elif d == 3:
        axis = np.zeros_like(normal)
        axis[np.arange(n), np.argmin(np.abs(normal), axis=1)] = 1.0
        t1 = np.cross(normal, axis)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        frames[:, 1] = t1
        frames[:, 2] = np.cross(normal, t1)
    return frames


def to_local(frames: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Components (n, d) of global vectors x in each contact's frame: R_c x_c."""
    return _rotate(frames, np.asarray(x, float), False)


def to_global(frames: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Global vectors (n, d) of components x in each contact's frame: R_cᵀ x_c."""
    return _rotate(frames, np.asarray(x, float), True)


@njit(cache=True)
def _rotate(frames, x, transpose):
    """y_c = R_c x_c (or R_cᵀ x_c) per contact (einsum's "cij,cj->ci" / "cji,cj->ci",
    whose strided loop over 43 000 contacts took 1.7% of a 1000-grain front step)."""
    n, d = x.shape
    y = np.empty((n, d))
    for c in range(n):
        for i in range(d):
            s = 0.0
            for j in range(d):
                s += (frames[c, j, i] if transpose else frames[c, i, j]) * x[c, j]
            y[c, i] = s
    return y


def project_to_cone(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Projection of local vectors r = (r_n, r_t) (n, d) onto the Coulomb cones
    K = {‖r_t‖ ≤ μ r_n} (the Euclidean projection onto a second-order cone)."""
    rn, rt = r[:, 0], r[:, 1:]
    norm_t = row_norms(rt)
    out = r.copy()
    polar = mu * norm_t <= -rn  # in the polar cone: projects to the apex
    inside = norm_t <= mu * rn
    edge = ~(polar | inside)
    scale = (rn[edge] + mu[edge] * norm_t[edge]) / (1.0 + mu[edge] ** 2)
    out[polar] = 0.0
    out[edge, 0] = scale
    safe = np.where(norm_t[edge] > 0.0, norm_t[edge], 1.0)
    out[edge, 1:] = (mu[edge] * scale / safe)[:, None] * rt[edge]
    return out


def natural_map_residual(problem: ContactProblem, P: np.ndarray, w: np.ndarray | None = None,
                         rho: np.ndarray | None = None) -> np.ndarray:
    """Φ_c = P_c − proj_K(P_c − ρ_c ŵ_c) in each contact's frame (n, d), impulse units.

    ŵ = (w_n + b + μ‖w_t‖, w_t); ρ_c defaults to 1/(n·W_cc n) (the contact's own normal
    stiffness), which makes Φ the impulse change a local solve would make. ``w``: the
    relative velocities (default: those of the problem at P).
    """
    frames = problem.frames()
    if w is None:
        w = problem.velocities(P)
    if rho is None:
        rho = normal_masses(problem)
    r = to_local(frames, P)
    u = to_local(frames, w)
    u[:, 0] += problem.bias + problem.mu * row_norms(u[:, 1:])
    return r - project_to_cone(r - rho[:, None] * u, problem.mu)


def normal_masses(problem: ContactProblem) -> np.ndarray:
    """1/(n·W_cc n) per contact (where no body can move there, the largest finite one)."""
    return problem._cached("rho", lambda: _normal_masses(problem))


def _normal_masses(problem: ContactProblem) -> np.ndarray:
    Wcc = problem.diagonal_blocks()
    wnn = np.einsum("ci,cij,cj->c", problem.normal, Wcc, problem.normal)
    positive = wnn > 0.0
    scale = wnn[positive].max() if positive.any() else 1.0
    return 1.0 / np.where(positive, wnn, scale)


def deformation_masses(problem: ContactProblem) -> np.ndarray:
    """A normal mass per contact that leaves out what its bodies' rigid modes of inertia
    alone carry (``rigid``): 1/Σ_s Σ_c' |n_c·(W_s − G Gᵀ)_cc'·n_c'|, over each body s the
    contact touches and the contacts c' touching s too (a bound on how fast the bodies'
    deformation alone moves the contact under the loads of its neighbours), never below
    :func:`normal_masses`. At a quasi-static step the rigid modes carry nearly all of W_cc
    (Δt c/h 3000: all but 2e-5 of a free disk's), and 1/W_cc,nn is then the bodies'
    inertia, not the contact's stiffness (solvers.py tries this scale where the first
    Newton stalls)."""
    return problem._cached("deformation_masses", lambda: _deformation_masses(problem))


def _deformation_masses(problem: ContactProblem) -> np.ndarray:
    rho = normal_masses(problem)
    if problem.rigid.size == 0:
        return rho
    contact, slot, col, _ = problem.touches()
    G = np.einsum("ci,cim->cm", problem.normal[contact],
                  problem.rigid[problem.k_off[slot] + col])
    spread = np.zeros(problem.n_contacts)
    _deformation_spread(contact, slot, col, problem.normal, problem.W, problem.w_off,
                        problem.k_size, G, spread)
    with np.errstate(divide="ignore"):
        return np.maximum(rho, np.where(spread > 0.0, 1.0 / spread, 0.0))


@njit(cache=True, nogil=True)
def _deformation_spread(contact, slot, col, normal, W, w_off, k_size, G, spread):
    """spread_c += Σ_c' |n_c·(W_s[col_c, col_c'] − G_c G_c'ᵀ)·n_c'| over the touches of each
    body slot s (``contact``, ``slot``, ``col`` grouped by slot; G: n·G per touch)."""
    t, d = contact.shape[0], normal.shape[1]
    start = 0
    while start < t:
        s = slot[start]
        end = start
        while end < t and slot[end] == s:
            end += 1
        kd = k_size[s] * d
        for a in range(start, end):
            row_sum = 0.0
            for b in range(start, end):
                w = 0.0
                for i in range(d):
                    base = w_off[s] + (col[a] * d + i) * kd + col[b] * d
                    for j in range(d):
                        w += normal[contact[a], i] * W[base + j] * normal[contact[b], j]
                for m in range(G.shape[1]):
                    w -= G[a, m] * G[b, m]
                row_sum += abs(w)
            spread[contact[a]] += row_sum
        start = end


def impulse_scale(problem: ContactProblem) -> float:
    """The impulse scale of the problem's velocities: the largest impulse the free
    velocities call for, max_c ρ_c max(0, −(q_n + b)), and at least the impulse a relative
    error of VELOCITY_RESOLUTION in the contact's velocities would give (w̃_n = w_n + b is
    a difference of two terms that nearly cancel at a resting contact)."""
    return problem._cached("impulse_scale", lambda: _impulse_scale(problem))


def _impulse_scale(problem: ContactProblem) -> float:
    q = problem.free_velocity()
    q_n = np.einsum("ci,ci->c", q, problem.normal) + problem.bias
    rho = normal_masses(problem)
    resolution = VELOCITY_RESOLUTION * (np.linalg.norm(q, axis=1) + np.abs(problem.bias))
    return float(np.max(rho * np.maximum(-q_n, resolution), initial=0.0))


def residual_norm(problem: ContactProblem, P: np.ndarray, w: np.ndarray | None = None,
                  floor: float = 0.0) -> float:
    """The relative complementarity error, the larger of
        max_c ‖Φ_c‖ / max(max_c ‖P_c‖, impulse_scale, floor)      (impulses) and
        max_c ‖Φ_c‖/ρ_c / max_c (‖w_c‖, ‖q_c‖ + |b_c|)          (velocities).
    The first alone misses a violated constraint where the contact's own compliance W_cc is
    huge (ρ_c tiny): a body whose rigid mode carries only its mass term M/(θΔt)² at
    Δt c/h ~ 10⁴ let a plate pass into it by its full travel each step with Φ/P ~ 1e-6.
    Φ_c/ρ_c is the contact's velocity error (w̃_n where it presses and should not move
    closer, W_cc r where it carries an impulse it should not). The impulse scale keeps the
    first meaningful where all impulses are nearly zero (e.g. a contact about to open)."""
    if problem.n_contacts == 0:
        return 0.0
    if w is None:
        w = problem.velocities(P)
    return relative_error(problem, natural_map_residual(problem, P, w), P, w, floor)


def relative_error(problem: ContactProblem, phi: np.ndarray, P: np.ndarray, w: np.ndarray,
                   floor: float = 0.0) -> float:
    """:func:`residual_norm` of a natural-map residual ``phi`` (n, d) at impulses P and
    relative velocities w (also for a related law, e.g. Tresca's fixed friction bound)."""
    phi = row_norms(phi)
    largest = float(row_norms(P).max())
    scale = max(largest, impulse_scale(problem), floor, 1e-300)
    speed = max(float(row_norms(w).max()), velocity_scale(problem))
    velocity = float(np.max(phi / normal_masses(problem))) / speed if speed > 0.0 else 0.0
    return max(float(phi.max()) / scale, velocity)


def velocity_scale(problem: ContactProblem) -> float:
    """max_c ‖q_c‖ + |b_c|: the free relative velocities with the gap bias."""
    return problem._cached("velocity_scale", lambda: float(np.max(
        np.linalg.norm(problem.free_velocity(), axis=1) + np.abs(problem.bias))))


@njit(cache=True)
def _row_norms(x):
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        s = 0.0
        for j in range(x.shape[1]):
            s += x[i, j] * x[i, j]
        out[i] = np.sqrt(s)
    return out


def row_norms(x: np.ndarray) -> np.ndarray:
    """‖x_i‖ per row of a real (n, k) array: np.linalg.norm(x, axis=1) to the bit (the same
    sum in the same order), without NumPy's slow reduction over a short axis (0.9 ms on
    43 000 contacts, several times a Newton iteration; this kernel 0.07 ms)."""
    return _row_norms(np.asarray(x, float))

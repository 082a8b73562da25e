"""A free body's rigid rotations in the Newton matrix of the momentum form (θ = 1).

With the momentum form of the internal forces (assembly.momentum_form) their moment about
the start nodes vanishes for every iterate u, so ρᵀK = 0 for each rigid rotation ρ of the
body: the rotation's row of the step equations is the body's angular-momentum balance
ρᵀ(c_m M u − b) = 0, linear in u, its stiffness the inertia c_m ρᵀMρ alone (tiny at
quasi-static steps). The exact tangent K is not symmetric (its non-symmetric part is
O(E |ΔF − I|)); its symmetric part would couple the rotation to the strain by ½ Kρ,
which against that tiny stiffness sends the iteration far off (the body's Newton
stalled on falling grains, measured in session 48). The Newton matrix used for the
factorization and the contacts' compliance is therefore

    A_s = PᵀĀP + Q (c_m RᵀMR) Qᵀ,   Ā = ½(A + Aᵀ),  P = I − R Qᵀ,  Q = M R (RᵀMR)⁻¹,

(R: the rotations as columns) — symmetric, the rotations decoupled from the strain and
their equation exact — and the exact direction A⁻¹b is reached from it by defect
correction (:func:`corrected_solve`), except once the rotation is stiffened
(:func:`rotation_stiffness`; BodyStep._momentum_direction). (The exact A factorised by
LU, with the contacts' compliance symmetrised, sent the quasi-static squeeze's disk
spinning: the asymmetry lives in the rotations' huge compliance. docs/theory.md has the
derivation.)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from softgrains.integrator.banded import BandedDecoupled
from softgrains.integrator.linear_solvers import DenseCholesky, DenseLU

# defect corrections x ← x + A_s⁻¹(b − A x) of a direction at most, and their stopping test
CORRECTIONS = 6
CORRECTION_TOLERANCE = 1e-6


def mass_centred(positions: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The positions about their mass centre (masses m, one per position)."""
    return positions - (m[:, None] * positions).sum(axis=0) / m.sum()


@dataclass(frozen=True)
class RigidRotations:
    """A body's rigid rotations about its nodal mass centre: R (unknowns × k, k = 1 in 2D,
    3 in 3D), M R, Q = M R (RᵀMR)⁻¹ and the inertia RᵀMR."""

    fields: np.ndarray
    mass_fields: np.ndarray
    dual: np.ndarray
    inertia: np.ndarray

    @classmethod
    def of(cls, positions: np.ndarray, m: np.ndarray,
           mass_times: Callable[[np.ndarray], np.ndarray]) -> RigidRotations:
        """From the active nodes' positions, their lumped masses m (one per node) and the
        product by the step's mass matrix (lumped or consistent) on (nodes, d) arrays."""
        r = mass_centred(positions, m)
        n, d = r.shape
        if d == 2:
            columns = [np.stack([-r[:, 1], r[:, 0]], axis=1)]
        else:
            columns = [np.cross(axis, r) for axis in np.eye(3)]
        R = np.stack([c.ravel() for c in columns], axis=1)
        MR = np.stack([np.array(mass_times(c), float).ravel() for c in columns], axis=1)
        inertia = R.T @ MR
        return cls(R, MR, MR @ np.linalg.inv(inertia), inertia)


def decoupled_dense(A: sp.bsr_matrix, rotations: RigidRotations, block: np.ndarray
                    ) -> np.ndarray:
    """A_s of the module docstring as a new dense array (symmetric: C and Fortran order
    alike) from the BSR Newton matrix A, with the rotations' block ``block`` (k × k: c_m RᵀMR,
    or stiffer: :func:`rotation_stiffness`)."""
    n = A.shape[0]
    full = np.empty((n, n))
    _decoupled(A.indptr, A.indices, A.data, rotations.fields, rotations.dual, block, full)
    return full


@njit(cache=True, nogil=True)
def _decoupled(indptr, indices, data, R, Q, inertia, out):
    """out = PᵀĀP + Q B Qᵀ from BSR (indptr, indices, data) (``inertia``: the rotations'
    block B): Ā = ½(A + Aᵀ) and ĀR scattered from the blocks, then one pass of rank
    updates over out's rows (the rotation vectors stored by rotation, contiguous)."""
    n, k = R.shape
    d = data.shape[1]
    out[:, :] = 0.0
    RT = np.ascontiguousarray(R.T)
    QT = np.ascontiguousarray(Q.T)
    ART = np.zeros((k, n))
    for r in range(indptr.shape[0] - 1):
        for q in range(indptr[r], indptr[r + 1]):
            c = indices[q]
            for i in range(d):
                for j in range(d):
                    half = 0.5 * data[q, i, j]
                    out[r * d + i, c * d + j] += half
                    out[c * d + j, r * d + i] += half
                    for a in range(k):
                        ART[a, r * d + i] += half * RT[a, c * d + j]
                        ART[a, c * d + j] += half * RT[a, r * d + i]
    C = inertia.copy()
    for a in range(k):
        for b in range(k):
            acc = 0.0
            for i in range(n):
                acc += RT[a, i] * ART[b, i]
            C[a, b] += acc
    QCT = np.zeros((k, n))
    for b in range(k):
        for a in range(k):
            for i in range(n):
                QCT[b, i] += QT[a, i] * C[a, b]
    for i in range(n):
        row = out[i]
        for a in range(k):
            qc, qi, ai = QCT[a, i], QT[a, i], ART[a, i]
            qa, ara = QT[a], ART[a]
            for j in range(n):
                row[j] += qc * qa[j] - qi * ara[j] - ai * qa[j]


class DecoupledSparse:
    """A_s⁻¹ for a sparse A by Woodbury around SuperLU of Ā:
    A_s = Ā + U C Uᵀ with U = [Q, ĀR], C = [[RᵀĀR + B, −I], [−I, 0]] (B: the rotations'
    block, as in :func:`decoupled_dense`), so A_s⁻¹ = Ā⁻¹ − Ā⁻¹U (C⁻¹ + UᵀĀ⁻¹U)⁻¹ UᵀĀ⁻¹,
    C⁻¹ = [[0, −I], [−I, −(RᵀĀR + B)]]. ``solve(b)`` as SuperLU's (b a vector or a matrix)."""

    def __init__(self, A: sp.spmatrix, rotations: RigidRotations, block: np.ndarray) -> None:
        sym = (0.5 * (A + A.T)).tocsc()
        self.base = spla.splu(sym, permc_spec="MMD_AT_PLUS_A")
        R, Q = rotations.fields, rotations.dual
        AR = sym @ R
        k = R.shape[1]
        block = R.T @ AR + block
        self.U = np.hstack([Q, AR])
        inverse_mid = np.block([[np.zeros((k, k)), -np.eye(k)], [-np.eye(k), -block]])
        self.BU = self.base.solve(self.U)
        self.capacitance = np.linalg.inv(inverse_mid + self.U.T @ self.BU)

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = self.base.solve(np.asarray(b, float))
        return x - self.BU @ (self.capacitance @ (self.U.T @ x))


def rotation_stiffness(rotations: RigidRotations, stresses: np.ndarray, c_m: float,
                       s: float) -> np.ndarray:
    """The rotations' block c_m RᵀMR + s |V|, V = Σ_p S_aᵀ S_b : Ŝ_p the virial of the
    points' stresses Ŝ_p (V⁰ Fⁿ S Fⁿᵀ; S_a the rotations' skew gradients): the magnitude of
    the curvature the consistent form's tangent gives a loaded body's rigid rotation (its
    negative mode under compression, which the mirror reflects). A stiffer rotation makes
    the contacts' compliance well conditioned at quasi-static steps, where the inertia
    alone leaves it ~(Δt c/h)² times the strain's; the residual is unchanged, so the step's
    solution is too."""
    d = stresses.shape[1]
    total = stresses.sum(axis=0)
    if d == 2:
        skews = [np.array([[0.0, -1.0], [1.0, 0.0]])]
    else:
        skews = [np.cross(np.eye(3), axis) for axis in np.eye(3)]
    virial = np.array([[float(np.sum((Sa.T @ Sb) * total)) for Sb in skews] for Sa in skews])
    w, V = np.linalg.eigh(0.5 * (virial + virial.T))
    return c_m * rotations.inertia + s * (V * np.abs(w)) @ V.T


def symmetric_factorization(A_s):
    """Cholesky of the dense symmetric A_s (a copy), or its LU where it is not positive
    definite (its negative modes are then a material's own: the rotations are not); a
    :class:`DecoupledSparse` or a banded.BandedDecoupled is its own factorization."""
    if isinstance(A_s, (DecoupledSparse, BandedDecoupled)):
        return A_s
    cholesky = DenseCholesky.attempt(np.array(A_s, order="F"))
    return cholesky if cholesky is not None else DenseLU(A_s)


def corrected_solve(A, factorization, b: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, int]:
    """x → A⁻¹b by defect correction x ← x + A_s⁻¹(b − A x) (A_s⁻¹: ``factorization``),
    from x = A_s⁻¹ b: at most CORRECTIONS, until a correction is below
    CORRECTION_TOLERANCE ‖x‖; one that grows is not taken (A_s⁻¹(A_s − A) is
    O(|ΔF − I|): on the frictionless example the first correction is 7.6e-3 of x in the
    median, 0.11 at the 99th percentile, each next one 1e-2–1e-3 of the last, session 48).
    Returns (x, corrections taken)."""
    last = np.inf
    for taken in range(CORRECTIONS):
        step = factorization.solve(b - A @ x)
        size = float(np.linalg.norm(step))
        if size > last:
            return x, taken
        x = x + step
        if size <= CORRECTION_TOLERANCE * float(np.linalg.norm(x)):
            return x, taken + 1
        last = size
    return x, CORRECTIONS

"""The momentum form's Newton direction of a dense body in one call that releases the GIL
(issue 14: the second thread's share of a coupling iteration).

Per body and coupling iteration the direction is a chain of small kernels: the points'
stresses and tangents, the tangent's gather into the BSR Newton matrix
A = c_m M + s K (assembly.py), its symmetric form with the rigid rotations decoupled, A_s
(rotations.py), A_s = L Lᵀ (LAPACK potrf), du = −A_s⁻¹ R, and the defect corrections
du ← du + A_s⁻¹(−R − A du) towards the exact direction (rotations.corrected_solve). Called
from Python one kernel at a time, a grain of the dense compaction (262 unknowns) spent a
fifth of its ~1 ms in the interpreter between them, holding the GIL: the bodies'
directions on two threads (threads.over_bodies) ran ×1.27 faster than on one. Here the
chain is one Numba function of the same kernels in the same order (the same arithmetic as
:meth:`BodyStep._momentum_direction`'s path, tested to round-off), so the threads overlap
it whole.

``banded_momentum_direction`` is the same chain with A_s factorised as Ā's band and a
rank-2k update (banded.py), the path BodyStep takes first.

It covers the common case: the momentum form, a body up to DENSE_LIMIT unknowns, the
rotations' block given (not stiffened from this iterate's stresses). Where A_s is not
positive definite, or the iterate inverts a point, it says so and the caller takes the
general path.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from softgrains.integrator import banded, lapack
from softgrains.integrator.assembly import (
    add_block_mass,
    add_diagonal,
    constrain,
    gather_tangent,
    point_stresses,
)
from softgrains.integrator.rotations import CORRECTION_TOLERANCE, CORRECTIONS, _decoupled

# the parallel kernels' serial twins (threads.ParallelKernel), called from the kernel below
_point_stresses = point_stresses.serial
_gather_tangent = gather_tangent.serial

# the outcomes of :func:`momentum_direction`
DONE = 0
INVERTED = 1  # the iterate inverts a point (J ≤ 0): no tangent
INDEFINITE = 2  # A_s is not positive definite: the caller's LU path


class PointTangents(NamedTuple):
    """A body's points and what their stresses and tangents need (assembly.point_stresses'
    arguments; Pv and Av are written). The flags are fields, not constants in the kernels
    that call point_stresses: a literal argument would make Numba compile a second
    point_stresses for them (~5 s from a fresh clone, each)."""

    nodes: np.ndarray
    dN: np.ndarray
    u_box: np.ndarray
    F_n: np.ndarray
    vol_n: np.ndarray
    law: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    Pv: np.ndarray
    Av: np.ndarray
    n_chunks: int
    projected: bool
    tangent: bool
    momentum: bool
    dims: tuple  # assembly.dimension(d)


class NewtonPattern(NamedTuple):
    """The Newton matrix's BSR pattern and values (``data``, written) and how points
    reach it (assembly.block_pattern, node_point_map)."""

    ptr: np.ndarray
    entries: np.ndarray
    slot: np.ndarray
    codes: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    diag_slot: np.ndarray
    data: np.ndarray


class StepTerms(NamedTuple):
    """The step's scalars and the mass term: A = c_m M + s_f K; M lumped (``lumped``, per
    dof, already × c_m) or consistent (``m_blocks``, one scalar a block); ``fixed`` per
    dof."""

    s_f: float
    c_m: float
    consistent: bool
    lumped: np.ndarray
    m_blocks: np.ndarray
    fixed: np.ndarray


class Rotations(NamedTuple):
    """The body's rigid rotations (rotations.RigidRotations' fields and dual) and their
    block B in A_s."""

    fields: np.ndarray
    dual: np.ndarray
    block: np.ndarray


@njit(cache=True, nogil=True)
def _bsr_times(indptr, indices, data, x, out):
    """out = A x for the BSR matrix (indptr, indices, data) (x, out per dof), summed block
    by block and column by column as SciPy's bsr_matvec."""
    d = data.shape[1]
    out[:] = 0.0
    for r in range(indptr.shape[0] - 1):
        for q in range(indptr[r], indptr[r + 1]):
            c = indices[q]
            for i in range(d):
                acc = out[r * d + i]
                for j in range(d):
                    acc += data[q, i, j] * x[c * d + j]
                out[r * d + i] = acc


@njit(cache=True, nogil=True)
def _assemble(points, pattern, terms):
    """A = c_m M + s_f K in ``pattern.data`` at the iterate in ``points.u_box`` (fixed dofs
    constrained). Returns False where the iterate inverts a point (no tangent)."""
    jmin, _ = _point_stresses(
        points.nodes, points.dN, points.u_box, points.F_n, points.vol_n, points.law,
        points.lam, points.mu, points.Pv, points.Av, points.tangent, points.n_chunks,
        points.projected, points.momentum, points.dims)
    if not jmin > 0.0:
        return False
    data = pattern.data
    _gather_tangent(pattern.ptr, pattern.entries, points.dN, points.Av, pattern.slot,
                          pattern.codes, data)
    if terms.s_f != 1.0:
        for q in range(data.shape[0]):
            for i in range(data.shape[1]):
                for k in range(data.shape[2]):
                    data[q, i, k] *= terms.s_f
    if terms.consistent:
        add_block_mass(data, terms.m_blocks, terms.c_m)
    else:
        add_diagonal(data, pattern.diag_slot, terms.lumped)
    constrain(data, pattern.indptr, pattern.indices, terms.fixed)
    return True


@njit(cache=True, nogil=True)
def momentum_direction(potrf, potrs, points, pattern, terms, rotations, rhs, scratch, lower,
                       du):
    """du = A⁻¹ rhs for the momentum form's Newton matrix A at the iterate in
    ``points.u_box`` (``points.tangent`` and ``points.momentum`` true): A assembled in
    ``pattern.data``, A_s (its symmetric form with the
    rotations decoupled) = L Lᵀ in ``lower`` (n × n, Fortran order; ``scratch`` n × n),
    then the defect corrections du ← du + A_s⁻¹(rhs − A du) (at most CORRECTIONS, while
    they shrink, until one is below CORRECTION_TOLERANCE ‖du‖). Returns (outcome,
    corrections taken): DONE, INVERTED or INDEFINITE (du then unset; ``lower``, the
    pattern's data and the points' Pv and Av overwritten). f^int is not gathered (the
    general path's Newton matrix wrote f^int(u) into the body's buffer; the residual at u
    is known)."""
    if not _assemble(points, pattern, terms):
        return INVERTED, 0
    data = pattern.data
    _decoupled(pattern.indptr, pattern.indices, data, rotations.fields, rotations.dual,
               rotations.block, scratch)
    n = rhs.shape[0]
    for j in range(n):
        for i in range(n):
            lower[i, j] = scratch[i, j]
    if lapack.cholesky(potrf, lower) != 0:
        return INDEFINITE, 0
    # (element loops, not slice assignments or in-place array operators: those took
    # seconds to compile from a fresh clone)
    for i in range(n):
        du[i] = rhs[i]
    lapack.cholesky_solve(potrs, lower, du)
    residual = np.empty(n)
    last = np.inf
    for taken in range(CORRECTIONS):
        _bsr_times(pattern.indptr, pattern.indices, data, du, residual)
        for i in range(n):
            residual[i] = rhs[i] - residual[i]
        lapack.cholesky_solve(potrs, lower, residual)
        size = np.sqrt(np.sum(residual * residual))
        if size > last:
            return DONE, taken
        for i in range(n):
            du[i] += residual[i]
        if size <= CORRECTION_TOLERANCE * np.sqrt(np.sum(du * du)):
            return DONE, taken + 1
        last = size
    return DONE, CORRECTIONS


@njit(cache=True, nogil=True)
def banded_momentum_direction(pbtrf, pbtrs, points, pattern, terms, rotations, rhs,
                              factors, du):
    """:func:`momentum_direction` with A_s factorised as a band matrix and a rank-2k update
    (banded.py; ``factors``: banded.BandedDecoupled.workspace's arrays, written): the same
    assembly and defect corrections. Returns INDEFINITE where Ā is not positive definite
    (the caller then takes the dense A_s)."""
    if not _assemble(points, pattern, terms):
        return INVERTED, 0
    data = pattern.data
    ab, U, BU, capacitance = factors
    if banded.factorize(pbtrf, pbtrs, pattern.indptr, pattern.indices, data,
                        rotations.fields, rotations.dual, rotations.block, ab, U, BU,
                        capacitance) != 0:
        return INDEFINITE, 0
    n = rhs.shape[0]
    for i in range(n):
        du[i] = rhs[i]
    banded.solve(pbtrs, ab, U, BU, capacitance, du)
    residual = np.empty(n)
    last = np.inf
    for taken in range(CORRECTIONS):
        _bsr_times(pattern.indptr, pattern.indices, data, du, residual)
        for i in range(n):
            residual[i] = rhs[i] - residual[i]
        banded.solve(pbtrs, ab, U, BU, capacitance, residual)
        size = np.sqrt(np.sum(residual * residual))
        if size > last:
            return DONE, taken
        for i in range(n):
            du[i] += residual[i]
        if size <= CORRECTION_TOLERANCE * np.sqrt(np.sum(du * du)):
            return DONE, taken + 1
        last = size
    return DONE, CORRECTIONS

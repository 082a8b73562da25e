"""The momentum form's line search in one call that releases the GIL (issue 14: the
bodies' share of a coupling iteration on the threads, as dense_direction.py's direction).

With the momentum form the step equations are no potential's gradient, so the line search
of implicit.line_search tests the residual alone: the first α = 1, ½, ¼, … (at most
MAX_LINE_SEARCH halvings) whose trial u + α du inverts no point and has
‖R‖ ≤ max((1 − 10⁻⁴ α)‖R(u)‖, enough) is taken, else the admissible trial of least ‖R‖,
else (every trial inverts a point) the last one. Each trial is the points' stresses, their
gather into f^int and R(u) = c_m M u − b − s_f f^int (zero at fixed dofs): the same
kernels and arithmetic as BodyStep.internal_force and BodyStep.residual, tested against
implicit.line_search.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from softgrains.integrator.assembly import block_scalar_matvec, gather_forces, point_stresses

_point_stresses = point_stresses.serial
_gather_forces = gather_forces.serial
_block_scalar_matvec = block_scalar_matvec.serial


class ResidualTerms(NamedTuple):
    """R(u) = c_m M u − b − s_f f^int(u), zero at ``fixed`` (per node and component):
    M lumped (``m``, per node and component) or consistent (``m_blocks`` on the BSR
    pattern ``indptr``, ``indices``); ``active`` the box nodes that are unknowns, f^int
    gathered by (``ptr``, ``entries``) (assembly.node_point_map)."""

    c_m: float
    s_f: float
    b: np.ndarray
    fixed: np.ndarray
    consistent: bool
    m: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    m_blocks: np.ndarray
    active: np.ndarray
    ptr: np.ndarray
    entries: np.ndarray


@njit(cache=True, nogil=True, inline="always")
def _copy(source, target):
    """target ← source (2-d; an element loop: a slice assignment took seconds to compile)."""
    for a in range(source.shape[0]):
        for i in range(source.shape[1]):
            target[a, i] = source[a, i]


@njit(cache=True, nogil=True)
def _norm(r):
    """‖r‖ as np.linalg.norm forms it: √(r·r) by BLAS dot, so the tests' decisions are
    those of implicit.line_search to the last bit."""
    flat = r.ravel()
    return np.sqrt(np.dot(flat, flat))


@njit(cache=True, nogil=True, inline="always")
def _trial(points, terms, u, f, r, mass_u):
    """(Inlined: compiled on its own it linked point_stresses into a second library,
    +2.5 s of compilation from a fresh clone. ``points``: dense_direction.PointTangents
    without the tangent, of the momentum form.) f^int(u) into f (left as it was where u
    inverts a point) and R(u) into r; returns the smallest J and the strain energy W(u)."""
    for a in range(terms.active.shape[0]):
        for i in range(u.shape[1]):
            points.u_box[terms.active[a], i] = u[a, i]
    jmin, energy = _point_stresses(points.nodes, points.dN, points.u_box, points.F_n,
                              points.vol_n, points.law, points.lam, points.mu, points.Pv,
                              points.Av, points.tangent, points.n_chunks, points.projected,
                              points.momentum, points.dims)
    if jmin > 0.0:
        _gather_forces(terms.ptr, terms.entries, points.dN, points.Pv, f)
    if terms.consistent:
        _block_scalar_matvec(terms.indptr, terms.indices, terms.m_blocks, u, mass_u)
    else:
        for a in range(u.shape[0]):
            for i in range(u.shape[1]):
                mass_u[a, i] = terms.m[a, i] * u[a, i]
    for a in range(u.shape[0]):
        for i in range(u.shape[1]):
            r[a, i] = 0.0 if terms.fixed[a, i] else (
                terms.c_m * mass_u[a, i] - terms.b[a, i] - terms.s_f * f[a, i])
    return jmin, energy


@njit(cache=True, nogil=True)
def residual_line_search(points, terms, u, du, r, enough, max_halvings, f, out_u, out_r,
                         out_f):
    """The line search of the module docstring from the iterate u (residual r) along du:
    the taken trial's u, R and f^int in out_u, out_r and out_f (f: f^int's buffer).
    Returns (‖R‖ of the trial, or NaN where no trial is admissible; its smallest J; its
    strain energy W). Where every trial inverts a point, R is formed with f as it came in
    or as the last trial that did not left it, as implicit.line_search does (the caller
    refuses that iterate; nothing reads R, f^int or W)."""
    rnorm = _norm(r)
    shape = u.shape
    u_try, r_try, mass_u = np.empty(shape), np.empty(shape), np.empty(shape)
    have_best, best_norm, best_j, best_w = False, np.inf, 0.0, np.nan
    alpha, j_try, w_try = 1.0, 0.0, np.nan
    for _ in range(max_halvings + 1):
        for a in range(shape[0]):
            for i in range(shape[1]):
                u_try[a, i] = u[a, i] + alpha * du[a, i]
        j_try, w_try = _trial(points, terms, u_try, f, r_try, mass_u)
        if j_try > 0.0:
            n_try = _norm(r_try)
            if np.isfinite(n_try) and n_try <= max((1.0 - 1e-4 * alpha) * rnorm, enough):
                _copy(u_try, out_u)
                _copy(r_try, out_r)
                _copy(f, out_f)
                return n_try, j_try, w_try
            if np.isfinite(n_try) and (not have_best or n_try < best_norm):
                have_best, best_norm, best_j, best_w = True, n_try, j_try, w_try
                _copy(u_try, out_u)
                _copy(r_try, out_r)
                _copy(f, out_f)
        alpha *= 0.5
    if have_best:
        return best_norm, best_j, best_w
    _copy(u_try, out_u)
    _copy(r_try, out_r)
    _copy(f, out_f)
    return np.nan, j_try, np.nan

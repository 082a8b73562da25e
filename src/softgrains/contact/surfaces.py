"""Point-to-surface contact between two deformable grains (issue #11, ``grain_sites =
"surface"``).

Each deformable body T gets a smooth boundary from its points: the ½ level of its
kernel-smoothed volume fraction
    c(x) = Σ_{q∈T} V_q W(x − x_q)       (W: Wendland C², radius R = 1.5 h, ∫W = 1),
which depends only on where T's points are (not on the grid: a rigid motion moves it
rigidly) and has no lattice staircase. Its outward normal is n_T = −∇c/‖∇c‖ and the signed
distance to it (> 0 outside) is read through the profile of a flat boundary, c = F(s/R):
    d_T(x) = −R F⁻¹(c(x))        (exact across a flat boundary, within 0.04 h over ±0.5 h
                                  for lattice points; −(c − ½)/‖∇c‖ errs by 0.4 h at 0.5 h).

A contact is taken at every point p of the outer layer of a grain O (d_O(x_p) > −δ, δ the
point spacing) that lies within T's kernel reach, for both orders of a pair (two passes;
``grain_passes``: for one order, :func:`sampling_side`); against a kinematic wall
at every point within reach (``wall_contacts``).
Its gap is the distance from T's surface to the edge of p's deformed round cell, per unit
of its rate,
    g_p = (d_T(x_p) − e_p)/λ,   e_p = −n_T·r_p = ½δ‖F_pᵀn_T‖,   r_p = −½δ F_p F_pᵀn_T/‖F_pᵀn_T‖,
    λ = ‖∇d_T‖ = R ‖∇c‖/F'(F⁻¹(c))   (1 across a flat boundary),
and its normal rate is taken from both bodies' nodal velocities:
    ġ_p λ⁻¹ ≈ n_T·v_O(x_p + r_p) − (1/‖∇c‖) ∂c/∂t(x_p),     ∂c/∂t(x) = Σ_J a_J·v_J,
    v_O(x_p + r_p) = Σ_I v_I [N_I(x_p) + ∇N_I(x_p)·r_p],
    a_J = Σ_q V_q [−∇W(x − x_q) N_J(x_q) + W(x − x_q) ∇N_J(x_q)]
(p moving with Σ_I N_I v_I and its cell with Ḟ = ∇v F; T's points moving with ẋ_q =
Σ_J N_J(x_q) v_J, their volumes with V̇_q = V_q ∇·v; Σ_J a_J = −∇c, so momentum is
exchanged exactly). The own side's velocity is that of p's cell edge, v_O(x_p + r_p), so
the cell's stretching and shearing are in the rate (session 16: at p's own velocity they
were not, and a point carrying a disk's weight on a soft block saw its edge move 0.014 h
a step beyond the linearised gap; session 13: at walls the force then acted h/4 inside the
grain, and the small compaction's volume-averaged stress came out 7.9% below the wall's,
2.8% with the edge). The cell is the round one for every grain, lattice squares included:
the square's extent ½δ Σ_j |(Fᵀn)_j| has a kink where a cell edge is parallel to the
surface (an axis-aligned wall, the bottom of a disk), across which the edge's linear rate
points the wrong way (session 14); with the round cell the edge stencil between grains
holds the sliding disk of the tests within 0.03 h (with the square one it sank 0.063 h).
The surface side's velocity, along n_T, is the motion of T's smoothed surface above and,
across n_T (friction), T's velocity field at x_p. Taking the surface's normal velocity from
where T's points are — not T's velocity field at x_p, a point outside T — is what keeps the
constraint tight while T deforms: with the sampled velocity the gap fell up to 0.13 h a
step below its prediction at an impact (session 11, docs/dev-notes.md).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numba import njit

from softgrains.contact.neighbours import PointCells, cell_around, cell_base, distance2
from softgrains.geometry import Disk, Rectangle
from softgrains.grid.shape_functions import compute_stencils, stencil_width
from softgrains.threads import threads_for

_trapezoid = getattr(np, "trapezoid", None) or np.trapz  # NumPy ≥ 2 / 1.26
FIELD_FLOOR = 1e-9  # a smoothed volume fraction below this does not reach the point
PSEUDO_INVERSE_RCOND = 1e-8  # the first-moment correction's C⁺ drops eigenvalues below this


@dataclass(frozen=True)
class SurfaceContacts:
    """Point contacts of one step: per contact the body pair, the point's body and index,
    its position, gap and normal (from β into α), each side's sampled stencil (active rows,
    −1: none, and weights) and the surface side's exact normal velocity Σ_J b_J·v_J (rows,
    vectors b_J = a_J/‖∇c‖) along its outward normal n_T."""

    alpha: np.ndarray
    beta: np.ndarray
    owner_is_alpha: np.ndarray  # the point belongs to α (first pass) or to β (second)
    point: np.ndarray  # the point's index within its own body
    position: np.ndarray  # (n, d)
    gap: np.ndarray
    normal: np.ndarray
    rows_alpha: np.ndarray  # (n, s^d)
    weights_alpha: np.ndarray
    rows_beta: np.ndarray
    weights_beta: np.ndarray
    rate_rows: np.ndarray  # (n, r)
    rate_vec: np.ndarray  # (n, r, d)
    rate_normal: np.ndarray  # (n, d)

    def __len__(self) -> int:
        return self.gap.size


KERNEL_RADIUS = 1.5  # support radius of the smoothing kernel, in cells h


@njit(cache=True, inline="always")
def _wendland(r, radius, d):
    """Wendland C² kernel W(r) with support ``radius`` (∫W = 1 in d = 2 or 3) and
    W'(r)/r (for ∇W = W'(r)/r · (x − x_q))."""
    q = r / radius
    if q >= 1.0:
        return 0.0, 0.0
    norm = 7.0 / (np.pi * radius**2) if d == 2 else 21.0 / (2.0 * np.pi * radius**3)
    w = norm * (1.0 - q) ** 4 * (1.0 + 4.0 * q)
    dw_over_r = norm * (-20.0) * (1.0 - q) ** 3 / radius**2
    return w, dw_over_r


@njit(cache=True, inline="always")
def _kernel_between(x, p, xq, q, radius):
    """W and W'(r)/r between query point x[p] and body point xq[q]."""
    return _wendland(np.sqrt(distance2(x, p, xq, q)), radius, x.shape[1])


@njit(cache=True)
def _kernel_field_in_cells(x, xq, origin, side, dims, start, order, vol, radius, value, grad):
    """c(x) = Σ_q V_q W(x − x_q) and ∇c at each query point, over the body points within
    ``radius`` (‖x − x_q‖ ≤ radius) found in the 3^d cells about x of neighbours.PointCells'
    cell list (cells of side ≥ radius), in the order of its neighbour lists, without writing
    the lists (half the cost of summing over PointCells.ball's lists)."""
    m, d = x.shape
    r2 = radius * radius
    base = np.empty(d, np.int64)
    for p in range(m):
        value[p] = 0.0
        for j in range(d):
            grad[p, j] = 0.0
        cell_base(x, p, origin, side, base)
        for code in range(3**d):
            index = cell_around(base, code, dims)
            if index < 0:
                continue
            for e in range(start[index], start[index + 1]):
                q = order[e]
                dist2 = distance2(x, p, xq, q)
                if dist2 <= r2:  # (the kernel from the same distance, not recomputed)
                    w, dw = _wendland(np.sqrt(dist2), radius, d)
                    value[p] += vol[q] * w
                    for j in range(d):
                        grad[p, j] += vol[q] * dw * (x[p, j] - xq[q, j])


@njit(cache=True)
def _kernel_rate(x, ptr, neighbours, xq, vol, radius, nodes, N, dN, active_row, out_rows,
                 out_vec):
    """a_J with ∂c(x)/∂t = Σ_J a_J·v_J for c = Σ_q V_q W(x − x_q), points moving with
    ẋ_q = Σ_J N_J(x_q) v_J and volumes with V̇_q = V_q ∇·v:
        a_J = Σ_q V_q [−∇W(x − x_q) N_J(x_q) + W(x − x_q) ∇N_J(x_q)]
    (Σ_J a_J = −∇c: a rigid translation moves c rigidly)."""
    m, d = x.shape
    ns = N.shape[1]
    n_rows = 0
    for i in range(active_row.size):
        n_rows = max(n_rows, active_row[i] + 1)
    acc = np.zeros((n_rows, d))
    mark = -np.ones(n_rows, np.int64)
    width = out_rows.shape[1]
    touched = np.empty(width, np.int64)
    for p in range(m):
        count = 0
        for e in range(ptr[p], ptr[p + 1]):
            q = neighbours[e]
            w, dw = _kernel_between(x, p, xq, q, radius)
            if w == 0.0:
                continue
            for kk in range(ns):
                J = active_row[nodes[q, kk]]
                if J < 0:
                    continue
                if mark[J] != p:
                    if count == width:
                        continue  # (never: width bounds the nodes a kernel can reach)
                    mark[J] = p
                    for j in range(d):
                        acc[J, j] = 0.0
                    touched[count] = J
                    count += 1
                for j in range(d):
                    acc[J, j] += vol[q] * (-dw * (x[p, j] - xq[q, j]) * N[q, kk]
                                           + w * dN[q, kk, j])
        for t in range(width):
            if t < count:
                out_rows[p, t] = touched[t]
                for j in range(d):
                    out_vec[p, t, j] = acc[touched[t], j]
            else:
                out_rows[p, t] = -1
                for j in range(d):
                    out_vec[p, t, j] = 0.0


def _wendland_profile(d: int, samples: int = 801) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The volume fraction across a flat boundary smoothed by the unit-radius kernel:
    ξ (signed distance into the body, in kernel radii), F(ξ) = ∫_{−1}^{ξ} W₁ and its
    derivative W₁, the kernel's marginal along the normal (numerical quadrature)."""
    xi = np.linspace(-1.0, 1.0, samples)
    t = np.linspace(0.0, 1.0, 2001)
    r = np.sqrt(xi[:, None] ** 2 + t[None, :] ** 2)
    q = np.minimum(r, 1.0)
    w = (1.0 - q) ** 4 * (1.0 + 4.0 * q) * (r < 1.0)
    if d == 2:
        marginal = 2.0 * _trapezoid(w, t, axis=1) * 7.0 / np.pi
    else:
        marginal = _trapezoid(w * 2.0 * np.pi * t, t, axis=1) * 21.0 / (2.0 * np.pi)
    F = np.concatenate([[0.0], np.cumsum(0.5 * (marginal[1:] + marginal[:-1])
                                         * np.diff(xi))])
    F /= F[-1]
    return xi, F, marginal / _trapezoid(marginal, xi)


PROFILES = {d: _wendland_profile(d) for d in (2, 3)}


def calibrated_distance(value: np.ndarray, grad: np.ndarray, radius: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance to the ½ level (> 0 outside) from the smoothed volume fraction c,
    exact for a flat boundary: d = −R F⁻¹(c), F the profile of :func:`_wendland_profile`;
    and λ = ‖∇d‖ = R‖∇c‖/F'(F⁻¹(c)) (1 across a flat boundary), so that ḋ = λ (n·ẋ − ∂c/∂t
    /‖∇c‖). Where c is 0 (beyond the kernel's reach) d is +inf."""
    xi, profile, slope = PROFILES[grad.shape[1]]
    length, distance, lam = np.empty(len(grad)), np.empty(len(grad)), np.empty(len(grad))
    _calibrated_distances(np.ascontiguousarray(value, float),
                          np.ascontiguousarray(grad, float), float(radius), xi, profile,
                          slope, length, distance, lam)
    return distance, lam


@njit(cache=True, inline="always", error_model="numpy")
def _norm(a, p):
    """‖a[p]‖ (the squares summed in order)."""
    total = 0.0
    for i in range(a.shape[1]):
        total += a[p, i] * a[p, i]
    return np.sqrt(total)


@njit(cache=True, error_model="numpy")
def _calibrated_distances(value, grad, radius, xi, profile, slope, length, distance, lam):
    """:func:`calibrated_distance` of the field's value c and gradient at each point, into
    ``length`` (‖∇c‖), ``distance`` and ``lam`` (NumPy's error model: 0/0 is NaN where ∇c
    vanishes). The profile is interpolated over all points at once: a point at a time,
    each search started afresh, took 2.5× as long."""
    n = value.shape[0]
    clipped = np.empty(n)
    for p in range(n):
        length[p] = _norm(grad, p)
        clipped[p] = min(max(value[p], profile[1]), profile[-2])
    inside = np.interp(clipped, profile, xi)
    at = np.interp(inside, xi, slope)
    for p in range(n):
        distance[p] = -radius * inside[p] if value[p] > 0.0 else np.inf
        lam[p] = radius * length[p] / at[p]


class KernelSurface:
    """A deformable body's smoothed volume fraction c(x) = Σ_q V_q W(x − x_q) from its
    points at the start of the step (its BodyStep), and c's rate in its nodal velocities."""

    def __init__(self, step) -> None:
        self.step = step
        self.radius = KERNEL_RADIUS * step.stepper.lattice.h
        self.cells = PointCells(step.pts.x, self.radius)
        self._own_distance = None
        self._bounds = None

    def own_distance(self) -> np.ndarray:
        """The calibrated distance of each of the body's own points to its surface (< 0
        inside), computed once a step for all its passes."""
        if self._own_distance is None:
            value, grad = self.field(self.step.pts.x)
            self._own_distance, _ = calibrated_distance(value, grad, self.radius)
        return self._own_distance

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The least and greatest coordinates of the body's points (once a step)."""
        if self._bounds is None:
            x = self.step.pts.x
            self._bounds = (x.min(axis=0), x.max(axis=0))
        return self._bounds

    def field(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """c and ∇c at x."""
        x = np.ascontiguousarray(x, float)
        value, grad = np.empty(len(x)), np.empty(x.shape)
        cells = self.cells
        _kernel_field_in_cells(x, cells.points, cells.origin, cells.side, cells.dims,
                               cells.start, cells.order, self.step.pts.vol, self.radius,
                               value, grad)
        return value, grad

    def rate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, a): ∂c/∂t(x) = Σ_k a_k·v_{rows_k} (rows −1: unused)."""
        x = np.ascontiguousarray(x, float)
        near = self.cells.ball(x)
        step = self.step
        d = x.shape[1]
        s = int(round(step.N.shape[1] ** (1.0 / d)))
        width = (int(np.ceil(2 * KERNEL_RADIUS)) + s + 1) ** d
        out_rows = np.empty((len(x), width), np.int64)
        out_vec = np.empty((len(x), width, d))
        _kernel_rate(x, near[0], near[1], step.pts.x, step.pts.vol, self.radius, step.nodes,
                     step.N, step.dN, step.active_row, out_rows, out_vec)
        return out_rows, out_vec

    def velocity_stencil(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The body's velocity field at x: active rows and weights N_I(x) renormalised over
        them (all zero where no active node is reached)."""
        step = self.step
        lattice, kind = step.stepper.lattice, step.stepper.shape_kind
        n, d = x.shape
        s = stencil_width(kind)
        base = np.empty((n, d), np.int64)
        N = np.empty((n, s**d))
        with threads_for(n):
            compute_stencils(x, lattice.node_origin, lattice.h, kind, base, N,
                             np.empty((n, s**d, d)))
        rows, weights = np.empty((n, s**d), np.int64), np.empty((n, s**d))
        _stencil_rows(base, N, step.box.lower, step.box.shape, step.active_row, rows, weights)
        _first_moment_correction(x, base, lattice.node_origin, lattice.h, weights)
        return rows, weights


@njit(cache=True)
def _stencil_rows(base, N, lower, shape, active_row, rows, weights):
    """Each stencil entry's active row in the body's box (−1: outside or inactive) and the
    weights renormalised over the active entries."""
    n, ns = N.shape
    d = base.shape[1]
    s = int(round(ns ** (1.0 / d)))
    for p in range(n):
        total = 0.0
        for k in range(ns):
            rem, local, stride, inside = k, 0, 1, True
            for j in range(d):
                i = base[p, j] + rem % s - lower[j]
                rem //= s
                inside = inside and 0 <= i < shape[j]
                local += i * stride
                stride *= shape[j]
            rows[p, k] = active_row[local] if inside else -1
            weights[p, k] = N[p, k] if rows[p, k] >= 0 else 0.0
            total += weights[p, k]
        for k in range(ns):
            weights[p, k] = weights[p, k] / total if total > 0.0 else 0.0


@njit(cache=True)
def _first_moment_correction(x, base, origin, h, weights):
    """Make weights w_k (Σ w = 1, some nodes dropped) reproduce linear fields at x:
    w_k ← w_k (1 − (X_k − x̄)ᵀ C⁺ (x̄ − x)), x̄ − x = Σ w_k (X_k − x), C = Σ w_k (X_k − x̄)
    (X_k − x̄)ᵀ, so that Σ w_k = 1 and Σ w_k X_k = x (a rigid motion's velocity at x; an
    impulse through them acts at x, with its moment). Where the remaining nodes lie on a
    line (C singular: linear hats) only the component along it is corrected (C⁺ the
    pseudo-inverse, eigenvalues below 1e-8 of the largest dropped). Stencil node k in
    compute_stencils' order (first axis fastest)."""
    n, ns = weights.shape
    d = x.shape[1]
    s = int(round(ns ** (1.0 / d)))
    offsets = np.empty((ns, d))
    mean = np.empty(d)
    coef = np.empty(d)
    C = np.empty((d, d))
    for p in range(n):
        for k in range(ns):
            rem = k
            for j in range(d):
                offsets[k, j] = origin[j] + (base[p, j] + rem % s) * h - x[p, j]
                rem //= s
        for j in range(d):
            mean[j] = 0.0
            for k in range(ns):
                mean[j] += weights[p, k] * offsets[k, j]
        for i in range(d):
            for j in range(d):
                C[i, j] = 0.0
                for k in range(ns):
                    C[i, j] += (weights[p, k] * (offsets[k, i] - mean[i])
                                * (offsets[k, j] - mean[j]))
        lam, vec = np.linalg.eigh(C)
        largest = 0.0
        for i in range(d):
            largest = max(largest, abs(lam[i]))
        for j in range(d):
            coef[j] = 0.0
        for i in range(d):
            if abs(lam[i]) > PSEUDO_INVERSE_RCOND * largest:
                along = 0.0
                for j in range(d):
                    along += vec[j, i] * mean[j]
                for j in range(d):
                    coef[j] -= vec[j, i] * along / lam[i]
        for k in range(ns):
            moment = 0.0
            for j in range(d):
                moment += (offsets[k, j] - mean[j]) * coef[j]
            weights[p, k] *= 1.0 + moment


def cell_support(F: np.ndarray, n: np.ndarray, spacing: float, round_body: bool
                 ) -> np.ndarray:
    """Offset r from each point to the point of its deformed cell furthest along −n (where
    the cell meets a surface with outward normal n in front of it): lattice squares, edges
    F δ e_j: r = −½δ F sign(Fᵀn); ring cells (one edge along the radius, taken along n):
    r = −½δ F Fᵀn/‖Fᵀn‖. The cell's half-extent along n is e = −n·r."""
    r = np.empty(n.shape)
    _cell_supports(np.ascontiguousarray(F, float), np.ascontiguousarray(n, float),
                   float(spacing), bool(round_body), r)
    return r


@njit(cache=True, inline="always", error_model="numpy")
def _cell_support_point(F, n, p, spacing, round_body, r, FTn):
    """:func:`cell_support` of point p: r[p] (n[p] NaN counts as 0; ``FTn``: d scratch)."""
    d = n.shape[1]
    size = 0.0
    for i in range(d):
        acc = 0.0
        for j in range(d):
            nj = n[p, j]
            acc += F[p, j, i] * (0.0 if np.isnan(nj) else nj)
        FTn[i] = acc
        size += acc * acc
    size = max(np.sqrt(size), 1e-300)
    for i in range(d):
        acc = 0.0
        for j in range(d):
            acc += F[p, i, j] * (FTn[j] / size if round_body else np.sign(FTn[j]))
        r[p, i] = -0.5 * spacing * acc


@njit(cache=True, error_model="numpy")
def _cell_supports(F, n, spacing, round_body, r):
    """:func:`cell_support`, point by point."""
    FTn = np.empty(n.shape[1])
    for p in range(n.shape[0]):
        _cell_support_point(F, n, p, spacing, round_body, r, FTn)


def edge_gap(distance: np.ndarray, n: np.ndarray, F: np.ndarray, spacing: float,
             round_body: bool) -> tuple[np.ndarray, np.ndarray]:
    """The gap from a surface (``distance`` to it, outward normal n) to the edge of each
    point's deformed cell, d − e with e = −n·r (r: :func:`cell_support`), and r."""
    r = cell_support(F, n, spacing, round_body)
    return distance + np.einsum("pi,pi->p", n, r), r


def edge_stencil(step, points: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The velocity of the material at x_p + r_p as the point's cell carries it (x_p and F_p
    moving with the nodal velocities): v = Σ_I v_I [N_I(x_p) + ∇N_I(x_p)·r_p] (rows, weights).
    It is the exact rate of the gap's cell edge (ė = −n·Ḟ s with Ḟ = ∇v F), and an impulse
    through it acts at the edge (Σ_I w_I X_I = x_p + r_p), so that the wall's force has its
    lever arm to the boundary in Σ_p V_p σ_p = Σ x ⊗ f."""
    weights = step.N[points] + np.einsum("pkj,pj->pk", step.dN[points], r)
    return step.active_row[step.nodes[points]], weights


def _outer_candidates(own: int, other: int, surfaces: dict, spacing: float,
                      reach: float) -> np.ndarray:
    """Body ``own``'s outer points (d_O > −δ) within ``other``'s box widened by the reach and
    its kernel radius: the points that may meet its surface."""
    O, T = surfaces[own], surfaces[other]
    lo, hi = T.bounds()
    margin = reach + T.radius
    return _points_in_box_outside(O.step.pts.x, lo - margin, hi + margin, O.own_distance(),
                                  -spacing)


@njit(cache=True)
def _points_in_box_outside(x, lo, hi, distance, threshold):
    """The indices of the points strictly inside the box (lo, hi) whose ``distance`` is
    above ``threshold``, in order."""
    n, d = x.shape
    out = np.empty(n, np.int64)
    m = 0
    for p in range(n):
        inside = True
        for j in range(d):
            if not (x[p, j] > lo[j] and x[p, j] < hi[j]):
                inside = False
                break
        if inside and distance[p] > threshold:
            out[m] = p
            m += 1
    return out[:m]


def _kernel_surfaces(pairs, steps: dict, surfaces: dict | None) -> dict:
    """``surfaces`` (body → KernelSurface of the step; a new dict if None) with those of
    the bodies of ``pairs`` that it lacks built: one per body and step, shared by the
    passes and the report of :func:`least_unsampled_gap`."""
    surfaces = surfaces if surfaces is not None else {}
    for body in {b for pair in pairs for b in pair} - set(surfaces):
        surfaces[body] = KernelSurface(steps[body])
    return surfaces


def _outer_points(owners: list[int], other: int, surfaces: dict, spacing: float,
                  reach: float) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The outer points of each body in ``owners`` that may meet ``other``'s surface
    (:func:`_outer_candidates`): their indices per owner, and their positions and
    deformation gradients, owner after owner."""
    candidates = [_outer_candidates(own, other, surfaces, spacing, reach) for own in owners]
    pts = [surfaces[own].step.pts for own in owners]
    x = np.concatenate([p.x[c] for p, c in zip(pts, candidates, strict=True)])
    F = np.concatenate([p.F[c] for p, c in zip(pts, candidates, strict=True)])
    return candidates, x, F


def _gaps_against(T: KernelSurface, x: np.ndarray, F: np.ndarray, spacing: float) -> tuple:
    """Points at x (deformation gradients F) against T's surface: T's field c, ‖∇c‖, T's
    outward normal n_T, the gap g = (d_T(x) − e)/λ (the distance to T's surface less the
    point's half cell, per unit of its rate n·(v_O − v_T)) and the cell's support r."""
    c, grad = T.field(x)
    return (c, *surface_gaps(c, grad, F, T.radius, spacing))


def surface_gaps(c: np.ndarray, grad: np.ndarray, F: np.ndarray, radius: float,
                 spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """From a kernel surface's field c and ∇c at points of deformation gradients F: ‖∇c‖,
    the outward normal n = −∇c/‖∇c‖, the gap (d − e)/λ of :func:`calibrated_distance` and
    :func:`edge_gap` (round cells) and the cells' support r, in one kernel (NaN gap and
    normal where ∇c = 0; +inf where c = 0)."""
    xi, profile, slope = PROFILES[grad.shape[1]]
    n, d = grad.shape
    length, n_out = np.empty(n), np.empty((n, d))
    gap, support = np.empty(n), np.empty((n, d))
    _gaps_from_field(np.ascontiguousarray(c, float), np.ascontiguousarray(grad, float),
                     np.ascontiguousarray(F, float), float(radius), xi, profile, slope,
                     float(spacing), length, n_out, gap, support)
    return length, n_out, gap, support


@njit(cache=True, error_model="numpy")
def _gaps_from_field(c, grad, F, radius, xi, profile, slope, spacing, length, n_out, gap,
                     support):
    """:func:`surface_gaps`: calibrated_distance's arithmetic, the normals, cell_support's
    per-point arithmetic, then edge_gap's sum (NumPy's error model: 0/0 is NaN)."""
    n, d = grad.shape
    distance, lam = np.empty(n), np.empty(n)
    _calibrated_distances(c, grad, radius, xi, profile, slope, length, distance, lam)
    FTn = np.empty(d)
    for p in range(n):
        for i in range(d):
            n_out[p, i] = -grad[p, i] / length[p]
        _cell_support_point(F, n_out, p, spacing, True, support, FTn)
        along = 0.0
        for i in range(d):
            along += n_out[p, i] * support[p, i]
        gap[p] = (distance[p] + along) / lam[p]


def least_unsampled_gap(one_pass: frozenset, steps: dict, spacing: float, reach: float,
                        round_bodies: frozenset = frozenset(),
                        surfaces: dict | None = None) -> float:
    """The least gap of the points that one pass leaves out: for each pair in ``one_pass``,
    the other grain's outer points against the sampling grain's surface (the reverse of
    :func:`sampling_side`'s order), as a second pass would read them (NaN: no such point
    within reach), one field evaluation per sampling surface. Not a constraint: how far
    one pass lets the other grain in. ``surfaces``: the step's KernelSurfaces, if built."""
    left_out: dict[int, list[int]] = {}  # sampling grain → the grains it leaves out
    for a, b in sorted(one_pass):
        own, other = sampling_side(a, b, steps, round_bodies)
        left_out.setdefault(own, []).append(other)
    surfaces = _kernel_surfaces(one_pass, steps, surfaces)
    least = np.nan
    for sampling, bodies in left_out.items():
        _, x, F = _outer_points(bodies, sampling, surfaces, spacing, reach)
        c, length, _, gap, _ = _gaps_against(surfaces[sampling], x, F, spacing)
        seen = gap[(c > FIELD_FLOOR) & (length > 0.0) & np.isfinite(gap)]
        if seen.size:
            least = np.fmin(least, seen.min())
    return float(least)


def _passes_against(other: int, owners: list[int], surfaces: dict, spacing: float,
                    reach: float) -> list[tuple]:
    """The outer points of each body in ``owners`` against ``other``'s surface T, in one
    evaluation of T's field, stencils and rates over all of them. Per owner O: the points'
    indices, gaps, T's outward normals, the own stencils (the velocity of each point's cell
    edge), T's sampled stencils and T's exact normal velocity (rows, vectors, normal). A
    point is seen only within T's kernel reach (c > 0: about 1.25 h outside T's surface)
    and where T has an active node in its stencil: two grains closing faster than ~1 h a
    step meet one step late."""
    T = surfaces[other]
    candidates, xc, Fc = _outer_points(owners, other, surfaces, spacing, reach)
    sizes = [c.size for c in candidates]
    c, length, n_out, gap, support = _gaps_against(T, xc, Fc, spacing)
    rows, weights = T.velocity_stencil(xc)
    reached = ((c > FIELD_FLOOR) & (length > 0.0) & np.isfinite(gap) & (gap < reach)
               & (weights.sum(axis=1) > 0.5))
    rate_rows, rate_vec = T.rate(xc[reached])
    rate_vec /= length[reached][:, None, None]
    out, start, at = [], 0, 0
    for own, candidate, size in zip(owners, candidates, sizes, strict=True):
        mine = reached[start:start + size]
        kept = int(mine.sum())
        span, kept_span = slice(start, start + size), slice(at, at + kept)
        keep = candidate[mine]
        normal = n_out[span][mine]
        out.append((keep, gap[span][mine], normal,
                    edge_stencil(surfaces[own].step, keep, support[span][mine]),
                    (rows[span][mine], weights[span][mine]),
                    (rate_rows[kept_span], rate_vec[kept_span], normal)))
        start, at = start + size, at + kept
    return out


def shape_distance(shape, x: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Exact signed distance (> 0 outside) and outward unit normal of a kinematic body's
    rectangle or disk at x (None for other shapes)."""
    if isinstance(shape, Rectangle):
        lo, hi = np.asarray(shape.lower, float), np.asarray(shape.upper, float)
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        r = x - centre
        q = np.abs(r) - half  # per axis: distance out of the slab (< 0 inside)
        out = np.maximum(q, 0.0)
        outside = np.linalg.norm(out, axis=1)
        axis = np.argmax(q, axis=1)
        inside = np.minimum(q[np.arange(len(x)), axis], 0.0)
        normal = np.where(outside[:, None] > 0.0,
                          np.sign(r) * out / np.maximum(outside, 1e-300)[:, None],
                          np.sign(r) * (np.arange(x.shape[1]) == axis[:, None]))
        return outside + inside, normal
    if isinstance(shape, Disk):
        r = x - np.asarray(shape.center, float)
        length = np.linalg.norm(r, axis=1)
        return length - shape.radius, r / np.maximum(length, 1e-300)[:, None]
    return None


def wall_contacts(pairs: list[tuple[int, int]], steps: dict, shapes: dict, spacing: float,
                  reach: float) -> SurfaceContacts:
    """Every (grain, wall) pair: the grain's points within reach against the kinematic
    wall's exact surface (gap d_wall(x_p) − e_p, normal the wall's outward normal, the
    wall's velocity prescribed). The grain is α, the wall β.

    Every point within reach is a contact, not only the outer layer of the grain (interior
    points are open contacts): with the outer-point threshold of the grain pairs, compressed
    corner points read 0.50–0.57 h inside their grain's kernel surface, left the contact
    set and entered the wall unconstrained (session 15). The cell support is the round one,
    e = ½δ‖Fᵀn‖, for every grain: the lattice square's e = ½δ Σ_j |(Fᵀn)_j| has its kink
    exactly against an axis-aligned wall, where the edge stencil's linear rate let the solve
    meet the constraint by shearing the point's cell (|ΔF| up to 0.74 a step) while the
    real e grew (session 14, ``benchmarks/wall_gap_audit.py``)."""
    parts = []
    for grain, wall in pairs:
        step = steps[grain]
        x = step.pts.x
        distance, n_out = shape_distance(shapes[wall], x)
        keep = np.flatnonzero(distance < reach + spacing)
        gap, support = edge_gap(distance[keep], n_out[keep], step.pts.F[keep], spacing, True)
        keep, gap, support = keep[gap < reach], gap[gap < reach], support[gap < reach]
        n, d = keep.size, x.shape[1]
        width = step.N.shape[1]
        none = -np.ones((n, width), np.int64)
        parts.append((np.full(n, grain), np.full(n, wall), np.ones(n, bool), keep, x[keep],
                      gap, n_out[keep], *edge_stencil(step, keep, support), none,
                      np.zeros((n, width)),
                      -np.ones((n, 0), np.int64), np.zeros((n, 0, d)), n_out[keep]))
    return _concatenate(parts)


def select(sc: SurfaceContacts, which: np.ndarray) -> SurfaceContacts:
    """The contacts of ``sc`` picked by ``which`` (a mask or indices)."""
    return SurfaceContacts(*(getattr(sc, f.name)[which] for f in fields(sc)))


def merge(found: list[SurfaceContacts]) -> SurfaceContacts:
    """Several SurfaceContacts in one."""
    return _concatenate([tuple(getattr(sc, f.name) for f in fields(sc)) for sc in found])


def _concatenate(parts: list[tuple]) -> SurfaceContacts:
    """The contacts of several passes in one SurfaceContacts (rate arrays padded to the
    widest)."""
    width = max(part[11].shape[1] for part in parts)
    return SurfaceContacts(*(
        stack_padded([p[i] for p in parts], width, -1 if i == 11 else 0.0) if i in (11, 12)
        else np.concatenate([p[i] for p in parts]) for i in range(14)))


def stack_padded(arrays: list[np.ndarray], width: int, fill) -> np.ndarray:
    """The arrays (n_i, w_i, ...) stacked along their first axis, their second axis padded
    with ``fill`` to ``width`` (np.pad array by array costs ~20 µs each in Python)."""
    first = arrays[0]
    out = np.full((sum(a.shape[0] for a in arrays), width, *first.shape[2:]), fill,
                  first.dtype)
    start = 0
    for a in arrays:
        out[start:start + a.shape[0], :a.shape[1]] = a
        start += a.shape[0]
    return out


def sampling_side(a: int, b: int, steps: dict, round_bodies: frozenset = frozenset()
                  ) -> tuple[int, int]:
    """(own, other): the order of a pair's one pass (``grain_passes``): the points
    of a round (ring-seeded) grain against a body of another seeding, else those of the
    body with fewer points (the smaller one; α on a tie). A deformable slab's flat row of
    points against a sliding disk's surface let the disk slide 3% fast (its lowest points
    alone carry it); the disk's points against the slab's surface slide it at the Coulomb
    rate (session 44). Fixed by seeding and point count: a pair keeps its order."""
    def rank(body: int) -> tuple[bool, int]:
        return body not in round_bodies, steps[body].pts.x.shape[0]

    return (a, b) if rank(a) <= rank(b) else (b, a)


def surface_contacts(pairs: list[tuple[int, int]], steps: dict, spacing: float,
                     reach: float, one_pass: frozenset = frozenset(),
                     round_bodies: frozenset = frozenset(),
                     surfaces: dict | None = None) -> SurfaceContacts:
    """Both passes for every pair (α, β) of deformable bodies, α < β (evaluated surface by
    surface, :func:`_passes_against`; listed pair by pair, α's points first); for the
    pairs in ``one_pass`` only :func:`sampling_side`'s. Both passes put ~4 sites a cell
    along an interface against ~1 velocity mode of each grain: W is singular, and the
    redundancy slows the frictional contact solve (docs/dev-notes.md, session 44).
    ``surfaces``: the step's KernelSurfaces (body → surface), filled in where missing."""
    surfaces = _kernel_surfaces(pairs, steps, surfaces)
    orders = {(a, b): (sampling_side(a, b, steps, round_bodies),) if (a, b) in one_pass
              else ((a, b), (b, a)) for a, b in pairs}
    owners: dict[int, list[int]] = {}
    for pair in pairs:
        for own, other in orders[pair]:
            owners.setdefault(other, []).append(own)
    found = {}
    for other, own_bodies in owners.items():
        for own, result in zip(own_bodies, _passes_against(other, own_bodies, surfaces,
                                                           spacing, reach), strict=True):
            found[own, other] = result
    parts = []
    for a, b in pairs:
        for own, other in orders[a, b]:
            idx, gap, n_out, own_st, other_st, rate = found[own, other]
            own_alpha = own == a
            # normal from β into α: out of β's surface in the first pass, into α's in the
            # second
            normal = n_out if own_alpha else -n_out
            st_a, st_b = (own_st, other_st) if own_alpha else (other_st, own_st)
            parts.append((np.full(idx.size, a), np.full(idx.size, b),
                          np.full(idx.size, own_alpha), idx, steps[own].pts.x[idx], gap,
                          normal, st_a[0], st_a[1], st_b[0], st_b[1], *rate))
    return _concatenate(parts)

"""Area covered by the grains and area where two grains overlap (2D), on a pixel raster.

Each material point stands for its reference cell (geometry.PointCells: the lattice square
δ × δ, or the ring sector of a ring-seeded disk) mapped by F_p about x_p, so that its area
is J_p V0_p = V_p and a body's cells tile it while F is uniform: a pixel centre y belongs to
point p when the local coordinates (a, b) = E_pᵀ F_p⁻¹ (y − x_p) (E_p: the cell's frame) lie
in the cell. Over the inner box A_box:
    φ_covered = (pixels covered by at least one grain) / pixels,
    overlap   = Σ_pixels max(0, grains covering it − 1) / pixels,
i.e. the packing fraction an image of the sample gives (an overlap counted once), and the
area where two grains occupy the same place (interpenetration), as fractions of A_box.
φ = Σ V_p / A_box (ALGORITHM.md §9) counts an overlap twice; it also counts the cells of one
grain that cover each other when the points' positions and F drift apart (large
deformation), which the raster counts once: φ − φ_covered ≥ overlap.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from softgrains.geometry import PointCells

PIXELS_PER_SPACING = 4  # raster pixel = δ/4 (δ: the median cell side)


@njit(cache=True, inline="always")
def _in_cell(a, b, shape, cos_alpha, sin_alpha):
    """Whether local coordinates (a, b) lie in a cell of ``shape``: the rectangle
    |a| ≤ s₀/2, |b| ≤ s₁/2 (s₂ = 0), or the ring sector of radius r ± ½Δr and half angle α
    about the point at (r, 0) from the ring's centre (shape (r, Δr, α); cos α and sin α
    given)."""
    if shape[2] == 0.0:
        return abs(a) <= 0.5 * shape[0] and abs(b) <= 0.5 * shape[1]
    X = shape[0] + a
    rho2 = X * X + b * b
    lo, hi = shape[0] - 0.5 * shape[1], shape[0] + 0.5 * shape[1]
    return lo * lo <= rho2 <= hi * hi and abs(b) * cos_alpha <= X * sin_alpha


@njit(cache=True, inline="always")
def _cell_reach(shape):
    """Radius about the point of a ball holding its cell (local coordinates)."""
    if shape[2] == 0.0:
        return 0.5 * np.sqrt(shape[0] ** 2 + shape[1] ** 2)
    r, alpha = shape[0], shape[2]
    reach = 0.5 * shape[1]
    for rho in (r - 0.5 * shape[1], r + 0.5 * shape[1]):
        dx, dy = rho * np.cos(alpha) - r, rho * np.sin(alpha)
        reach = max(reach, np.sqrt(dx * dx + dy * dy))
    return reach


@njit(cache=True)
def _raster(x, F, frame, shape, grain, lower, px, py, nx, ny, covered, last):
    """Mark every pixel inside each point's cell (local coordinates A⁻¹(y − x), A = F E, E
    the cell's ``frame``);
    ``covered`` counts distinct grains per pixel (points must come grouped by grain;
    ``last`` holds the last grain that marked a pixel). Returns the number of pixels covered
    and Σ_pixels max(0, covered − 1), counted as the marks are made."""
    n_covered, n_overlap = 0, 0
    for p in range(x.shape[0]):
        a = F[p, 0, 0] * frame[p, 0, 0] + F[p, 0, 1] * frame[p, 1, 0]
        b = F[p, 0, 0] * frame[p, 0, 1] + F[p, 0, 1] * frame[p, 1, 1]
        c = F[p, 1, 0] * frame[p, 0, 0] + F[p, 1, 1] * frame[p, 1, 0]
        d = F[p, 1, 0] * frame[p, 0, 1] + F[p, 1, 1] * frame[p, 1, 1]
        det = a * d - b * c
        if det <= 0.0:
            continue
        # bounding box of the mapped ball holding the cell
        q = _cell_reach(shape[p])
        ex = q * np.sqrt(a * a + b * b)
        ey = q * np.sqrt(c * c + d * d)
        i0 = max(int(np.floor((x[p, 0] - ex - lower[0]) / px)), 0)
        i1 = min(int(np.floor((x[p, 0] + ex - lower[0]) / px)), nx - 1)
        j0 = max(int(np.floor((x[p, 1] - ey - lower[1]) / py)), 0)
        j1 = min(int(np.floor((x[p, 1] + ey - lower[1]) / py)), ny - 1)
        g = grain[p]
        cos_alpha, sin_alpha = np.cos(shape[p, 2]), np.sin(shape[p, 2])
        for i in range(i0, i1 + 1):
            rx = lower[0] + (i + 0.5) * px - x[p, 0]
            for j in range(j0, j1 + 1):
                ry = lower[1] + (j + 0.5) * py - x[p, 1]
                s = (d * rx - b * ry) / det
                t = (-c * rx + a * ry) / det
                if _in_cell(s, t, shape[p], cos_alpha, sin_alpha):
                    k = i * ny + j
                    if last[k] != g:
                        last[k] = g
                        if covered[k] == 0:
                            n_covered += 1
                        else:
                            n_overlap += 1
                        covered[k] += 1
    return n_covered, n_overlap


def coverage(x: np.ndarray, F: np.ndarray, cells: PointCells, grain: np.ndarray,
             lower: np.ndarray, upper: np.ndarray) -> tuple[float, float]:
    """(φ_covered, overlap) of the points (x, F, reference cells, grain index; grouped by
    grain) in the box [lower, upper] (2D); pixels of a quarter of the median cell side
    (√ of its area)."""
    if x.shape[1] != 2:
        raise NotImplementedError("the coverage raster is written for 2D")
    grain = np.asarray(grain).astype(np.int64)
    if np.count_nonzero(np.diff(grain)) + 1 > np.unique(grain).size:
        raise ValueError("coverage: the points must come grouped by grain")
    shape = np.ascontiguousarray(cells.shape, dtype=float)
    target = float(np.median(np.sqrt(cells.area()))) / PIXELS_PER_SPACING
    size = np.asarray(upper, float) - np.asarray(lower, float)
    # pixels that tile the box exactly (about δ/4 on each axis)
    nx, ny = (max(int(np.ceil(s / target)), 1) for s in size)
    covered = np.zeros(nx * ny, np.int32)
    last = np.full(nx * ny, -1, np.int32)
    n_covered, n_overlap = _raster(x, np.ascontiguousarray(F, float),
                                   np.ascontiguousarray(cells.frame, float), shape,
                                   grain.astype(np.int32),
                                   np.asarray(lower, float), size[0] / nx, size[1] / ny, nx,
                                   ny, covered, last)
    return float(n_covered) / covered.size, float(n_overlap) / covered.size

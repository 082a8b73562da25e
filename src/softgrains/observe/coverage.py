"""Area covered by the grains and area where two grains overlap (2D), on a pixel raster.

Each material point stands for the deformed cell F_p·[−s_p/2, s_p/2]² around x_p, with
s_p = √V0_p (δ for lattice points), so that its area is J_p V0_p = V_p. (Ring cells are
taken as axis-aligned squares of the same area: they leave holes, and a ring-seeded disk at
rest covers only 92% of its area; the raster is meant for lattice-seeded grains.) A pixel
centre y belongs to point p when ‖F_p⁻¹ (y − x_p)‖_∞ ≤ s_p/2. Over the inner box A_box:
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

PIXELS_PER_SPACING = 4  # raster pixel = δ/4 (δ: the median cell side)


@njit(cache=True)
def _raster(x, F, side, grain, lower, res, nx, ny, covered, last):
    """Mark every pixel inside each point's cell; ``covered`` counts distinct grains per
    pixel (points must come grouped by grain; ``last`` holds the last grain that marked a
    pixel)."""
    for p in range(x.shape[0]):
        half = 0.5 * side[p]
        a, b, c, d = F[p, 0, 0], F[p, 0, 1], F[p, 1, 0], F[p, 1, 1]
        det = a * d - b * c
        if det <= 0.0:
            continue
        # bounding box of the parallelogram: half-extents |F| (s/2, s/2)
        ex = half * (abs(a) + abs(b))
        ey = half * (abs(c) + abs(d))
        i0 = max(int(np.floor((x[p, 0] - ex - lower[0]) / res)), 0)
        i1 = min(int(np.floor((x[p, 0] + ex - lower[0]) / res)), nx - 1)
        j0 = max(int(np.floor((x[p, 1] - ey - lower[1]) / res)), 0)
        j1 = min(int(np.floor((x[p, 1] + ey - lower[1]) / res)), ny - 1)
        g = grain[p]
        for i in range(i0, i1 + 1):
            rx = lower[0] + (i + 0.5) * res - x[p, 0]
            for j in range(j0, j1 + 1):
                ry = lower[1] + (j + 0.5) * res - x[p, 1]
                s = (d * rx - b * ry) / det
                t = (-c * rx + a * ry) / det
                if abs(s) <= half and abs(t) <= half:
                    k = i * ny + j
                    if last[k] != g:
                        last[k] = g
                        covered[k] += 1


def coverage(x: np.ndarray, F: np.ndarray, vol0: np.ndarray, grain: np.ndarray,
             lower: np.ndarray, upper: np.ndarray) -> tuple[float, float]:
    """(φ_covered, overlap) of the points (x, F, initial volume, grain index; grouped by
    grain) in the box [lower, upper] (2D); pixels of a quarter of the median cell side."""
    if x.shape[1] != 2:
        raise NotImplementedError("the coverage raster is written for 2D")
    side = np.sqrt(np.asarray(vol0, float))
    res = float(np.median(side)) / PIXELS_PER_SPACING
    size = np.asarray(upper, float) - np.asarray(lower, float)
    nx, ny = (max(int(np.ceil(s / res)), 1) for s in size)
    covered = np.zeros(nx * ny, np.int32)
    last = np.full(nx * ny, -1, np.int64)
    _raster(x, F, side, grain.astype(np.int64), np.asarray(lower, float), res, nx, ny,
            covered, last)
    # pixels sticking out of the box count by the part inside
    pixel = res * res
    area = float(size[0] * size[1])
    inside = _inside_fraction(nx, ny, res, size)
    phi = float(np.sum((covered >= 1) * inside)) * pixel / area
    overlap = float(np.sum(np.maximum(covered - 1, 0) * inside)) * pixel / area
    return phi, overlap


def _inside_fraction(nx: int, ny: int, res: float, size: np.ndarray) -> np.ndarray:
    """Fraction of each pixel inside the box (the last row and column may stick out)."""
    fx = np.ones(nx)
    fy = np.ones(ny)
    fx[-1] = (size[0] - (nx - 1) * res) / res
    fy[-1] = (size[1] - (ny - 1) * res) / res
    return np.outer(fx, fy).ravel()

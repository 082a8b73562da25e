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
def _raster(x, F, side, grain, lower, px, py, nx, ny, covered, last):
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
        i0 = max(int(np.floor((x[p, 0] - ex - lower[0]) / px)), 0)
        i1 = min(int(np.floor((x[p, 0] + ex - lower[0]) / px)), nx - 1)
        j0 = max(int(np.floor((x[p, 1] - ey - lower[1]) / py)), 0)
        j1 = min(int(np.floor((x[p, 1] + ey - lower[1]) / py)), ny - 1)
        g = grain[p]
        for i in range(i0, i1 + 1):
            rx = lower[0] + (i + 0.5) * px - x[p, 0]
            for j in range(j0, j1 + 1):
                ry = lower[1] + (j + 0.5) * py - x[p, 1]
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
    grain = np.asarray(grain).astype(np.int64)
    if np.count_nonzero(np.diff(grain)) + 1 > np.unique(grain).size:
        raise ValueError("coverage: the points must come grouped by grain")
    target = float(np.median(side)) / PIXELS_PER_SPACING
    size = np.asarray(upper, float) - np.asarray(lower, float)
    # pixels that tile the box exactly (about δ/4 on each axis)
    nx, ny = (max(int(np.ceil(s / target)), 1) for s in size)
    covered = np.zeros(nx * ny, np.int32)
    last = np.full(nx * ny, -1, np.int64)
    _raster(x, F, side, grain, np.asarray(lower, float), size[0] / nx, size[1] / ny, nx, ny,
            covered, last)
    phi = float(np.count_nonzero(covered)) / covered.size
    overlap = float(np.sum(np.maximum(covered - 1, 0))) / covered.size
    return phi, overlap

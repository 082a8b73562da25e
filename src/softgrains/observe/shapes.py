"""Grain shape descriptors (issue #13, item 4), 2D.

Each grain is drawn as the union of its points' deformed cells F_p·[−s_p/2, s_p/2]² on a
pixel raster of δ/8 (observe/coverage.py), averaged over 2 × 2 pixels (an image of δ/4:
the descriptors within 0.07% of the δ/8 image's at 2.5× less time, session 35; a raster of
δ/3 itself aliases the cells' edges, +1.4% on a disk's area), blurred by a Gaussian of σ =
δ so that the lattice's staircase does not count as boundary (σ = δ/4 left the perimeter
of a disk 12% long), and its outline is the longest closed line of that image at half the
grain's median level (½ where the cells tile; ring cells leave holes) (marching squares,
contourpy: a matplotlib dependency). The blur also rounds corners: a regular hexagon's
asphericity comes out 3% low (tests/observe/test_grain_shapes.py). Per grain:
    area A = Σ_p V_p (its points' volumes),
    perimeter P = length of the outline,
    asphericity α = P² / (4π A_outline)   (1 for a disk, 1.103 for a regular hexagon),
    aspect ratio = √(λ₁/λ₂) of the area tensor Σ_p V_p (x_p − x̄)⊗(x_p − x̄),
with A_outline the area the outline encloses (so that α does not mix two area measures).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from contourpy import contour_generator
from scipy.ndimage import gaussian_filter

from softgrains.geometry import lattice_cells
from softgrains.observe.compaction import bearing_pairs
from softgrains.observe.coverage import _raster

PIXELS_PER_SPACING = 4  # of the image that is blurred and contoured
SUBPIXELS = 2  # raster pixels per image pixel, in each direction
BLUR_SPACINGS = 1.0  # Gaussian σ of the blur, in point spacings


@dataclass(frozen=True)
class GrainShape:
    """One grain's shape descriptors (SI units)."""

    area: float
    perimeter: float
    outline_area: float
    asphericity: float
    aspect_ratio: float


def grain_outline(x: np.ndarray, F: np.ndarray, side: np.ndarray,
                  pixels_per_spacing: int = PIXELS_PER_SPACING,
                  subpixels: int = SUBPIXELS) -> np.ndarray:
    """The outline (m, 2) of one grain: the longest closed line at half the grain's median
    coverage (½ where the cells tile) of its points' deformed cells F_p·[−s_p/2, s_p/2]²
    (s_p = ``side``) rastered at δ/8, averaged to an image of δ/4
    (δ/``pixels_per_spacing``; the raster ``subpixels`` times finer) and blurred over
    σ = δ (δ the median side). The enclosed area is within 1% of Σ V_p for disks of
    radius ≥ 5δ (lattice or rings seeding); below that the blur dominates (radius 3δ: 12%
    large for lattice cells, 21% for rings)."""
    if x.shape[1] != 2:
        raise NotImplementedError("grain outlines are written for 2D")
    side = np.asarray(side, float)
    spacing = float(np.median(side))
    pixel = spacing / pixels_per_spacing
    reach = float(np.max(np.abs(F).sum(axis=2).max(axis=1) * side))  # a cell's extent
    pad = reach + 4.0 * BLUR_SPACINGS * spacing
    lower = x.min(axis=0) - pad
    nx, ny = (int(np.ceil(s / pixel)) + 1 for s in (x.max(axis=0) + pad - lower))
    fine, k = pixel / subpixels, subpixels
    covered = np.zeros(nx * k * ny * k, np.int32)
    last = np.full(covered.size, -1, np.int64)
    squares = lattice_cells(side**2).shape  # (the cells as squares of side s_p)
    _raster(np.ascontiguousarray(x, float), np.ascontiguousarray(F, float),
            np.tile(np.eye(2), (len(x), 1, 1)), squares, np.zeros(len(x), np.int64), lower,
            fine, fine, nx * k, ny * k, covered, last)
    coverage = covered.reshape(nx, k, ny, k).mean(axis=(1, 3))
    image = gaussian_filter(coverage, BLUR_SPACINGS * pixels_per_spacing)
    centres = lower[:, None] + pixel * (np.arange(max(nx, ny)) + 0.5)[None, :]
    # half of the grain's own coverage: 0.5 for lattice cells that tile; ring cells, taken
    # as squares, leave holes (about 8% of a disk) that would pull a level-½ line inwards
    at = np.clip(((x - lower) / pixel).astype(np.int64), 0, [nx - 1, ny - 1])
    level = 0.5 * float(np.median(image[at[:, 0], at[:, 1]]))
    lines = contour_generator(centres[0, :nx], centres[1, :ny], image.T).lines(level)
    closed = [line for line in lines if len(line) > 3]
    return max(closed, key=_length)


def grain_shape(x: np.ndarray, F: np.ndarray, vol0: np.ndarray, vol: np.ndarray
                ) -> GrainShape:
    """The shape descriptors of one grain from its points (positions, F, V0, V)."""
    outline = grain_outline(x, F, np.sqrt(np.asarray(vol0, float)))
    area = float(np.sum(vol))
    enclosed = abs(polygon_area(outline))
    perimeter = _length(outline)
    mean = np.average(x, axis=0, weights=vol)
    r = x - mean
    tensor = np.einsum("p,pi,pj->ij", vol, r, r)
    small, large = np.linalg.eigvalsh(tensor)
    return GrainShape(area, perimeter, enclosed, perimeter**2 / (4.0 * np.pi * enclosed),
                      float(np.sqrt(large / small)))


def _length(line: np.ndarray) -> float:
    closed = np.vstack([line, line[:1]]) if not np.allclose(line[0], line[-1]) else line
    return float(np.sum(np.linalg.norm(np.diff(closed, axis=0), axis=1)))


def polygon_area(line: np.ndarray) -> float:
    """Signed area of a closed polygon (shoelace formula; > 0 counter-clockwise)."""
    x, y = line[:, 0], line[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


GRAIN_COLUMNS = ["step", "time", "grain", "area", "perimeter", "asphericity", "aspect_ratio",
                 "contacts_grains", "contacts_walls"]


def grain_rows(model, state, contacts) -> list[dict[str, object]]:
    """Rows of grains/grains_<step>.csv: every deformable body's shape descriptors and how
    many grains and walls press on it (distinct bodies with a contact of P_n > 0)."""
    if model.dim != 2:
        return []
    partners: dict[int, set[int]] = {}
    for a, b in bearing_pairs(contacts):
        partners.setdefault(a, set()).add(b)
        partners.setdefault(b, set()).add(a)
    rows = []
    for body in model.bodies:
        if not body.deformable:
            continue
        sl = body.points
        shape = grain_shape(state.x[sl], state.F[sl], model.vol0[sl], state.vol[sl])
        others = partners.get(body.index, set())
        walls = sum(1 for o in others if not model.bodies[o].deformable)
        rows.append({"step": state.step, "time": state.time, "grain": body.name,
                     "area": shape.area, "perimeter": shape.perimeter,
                     "asphericity": shape.asphericity, "aspect_ratio": shape.aspect_ratio,
                     "contacts_grains": len(others) - walls, "contacts_walls": walls})
    return rows

"""Shapes of bodies and the seeding of their material points (ALGORITHM.md §1).

Lattice seeding (any shape): points sit at the centres of a sub-lattice of spacing
δ = h/n_pc aligned with the grid (x = origin + (i + ½) δ); each point inside the shape gets
the reference volume δ^d and mass ρ δ^d. In 2D volumes are per unit thickness.

Ring seeding (disks): concentric rings of cells of nearly square side δ that fill the disk
exactly, so that the outermost points lie δ/2 inside the circle all around. A lattice-seeded
disk is a staircase: its lowest row is flat over a half-width up to √(2Rδ) (0.14 R at
D/h = 100, n_pc = 2), wider than a Hertz contact at P/(E*R) = 0.01 (0.11 R).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class Shape:
    """A closed region of the plane that can say which points lie inside it."""

    def contains(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    @property
    def area(self) -> float:
        raise NotImplementedError

    @property
    def centroid(self) -> np.ndarray:
        raise NotImplementedError


@dataclass(frozen=True)
class Disk(Shape):
    center: np.ndarray
    radius: float

    def contains(self, x):
        return np.sum((x - np.asarray(self.center)) ** 2, axis=1) <= self.radius**2

    def bounds(self):
        c = np.asarray(self.center, dtype=float)
        return c - self.radius, c + self.radius

    @property
    def area(self):
        return float(np.pi * self.radius**2)

    @property
    def centroid(self):
        return np.asarray(self.center, dtype=float)


@dataclass(frozen=True)
class Rectangle(Shape):
    lower: np.ndarray
    upper: np.ndarray

    def contains(self, x):
        return np.all((x >= np.asarray(self.lower)) & (x <= np.asarray(self.upper)), axis=1)

    def bounds(self):
        return np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float)

    @property
    def area(self):
        return float(np.prod(np.asarray(self.upper) - np.asarray(self.lower)))

    @property
    def centroid(self):
        return 0.5 * (np.asarray(self.lower, dtype=float) + np.asarray(self.upper, dtype=float))


@dataclass(frozen=True)
class Polygon(Shape):
    vertices: np.ndarray  # (n, 2), either orientation

    def contains(self, x):
        """Even–odd ray casting along +x."""
        v = np.asarray(self.vertices, dtype=float)
        inside = np.zeros(len(x), dtype=bool)
        px, py = x[:, 0], x[:, 1]
        for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
            crosses = (a[1] > py) != (b[1] > py)
            with np.errstate(divide="ignore", invalid="ignore"):
                xc = a[0] + (py - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            inside ^= crosses & (px < xc)
        return inside

    def bounds(self):
        v = np.asarray(self.vertices, dtype=float)
        return v.min(axis=0), v.max(axis=0)

    @property
    def area(self):
        v = np.asarray(self.vertices, dtype=float)
        return float(0.5 * abs(np.sum(v[:, 0] * np.roll(v[:, 1], -1)
                                      - np.roll(v[:, 0], -1) * v[:, 1])))

    @property
    def centroid(self):
        v = np.asarray(self.vertices, dtype=float)
        w = np.roll(v, -1, axis=0)
        cross = v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]
        a = 0.5 * np.sum(cross)
        return np.array([np.sum((v[:, 0] + w[:, 0]) * cross),
                         np.sum((v[:, 1] + w[:, 1]) * cross)]) / (6.0 * a)


def translated(shape: Shape, offset: np.ndarray) -> Shape:
    """The shape moved rigidly by offset (for kinematic bodies)."""
    offset = np.asarray(offset, dtype=float)
    if isinstance(shape, Disk):
        return Disk(np.asarray(shape.center, dtype=float) + offset, shape.radius)
    if isinstance(shape, Rectangle):
        return Rectangle(np.asarray(shape.lower, dtype=float) + offset,
                         np.asarray(shape.upper, dtype=float) + offset)
    return Polygon(np.asarray(shape.vertices, dtype=float) + offset)


def seed_points(shape: Shape, origin: np.ndarray, h: float, n_pc: int) -> tuple[np.ndarray, float]:
    """Points of ``shape`` on the sub-lattice of spacing h/n_pc; returns (x (n, d), volume)."""
    delta = h / n_pc
    lo, hi = shape.bounds()
    origin = np.asarray(origin, dtype=float)
    i0 = np.floor((lo - origin) / delta - 0.5).astype(np.int64)
    i1 = np.ceil((hi - origin) / delta - 0.5).astype(np.int64)
    axes = [origin[j] + (np.arange(i0[j], i1[j] + 1) + 0.5) * delta for j in range(len(origin))]
    mesh = np.meshgrid(*axes, indexing="ij")
    x = np.stack([g.ravel() for g in mesh], axis=1)
    return x[shape.contains(x)], delta ** len(origin)


def _disk_rings(disk: Disk, spacing: float, outer: int = 1):
    """The rings of :func:`seed_disk_rings`: per ring its radius r_k, width Δr and the
    angles of its points."""
    rings = max(1, round(disk.radius / spacing))
    dr = disk.radius / rings
    turn = 0.0
    for k in range(rings):
        r = (k + 0.5) * dr
        n = max(3, round(2.0 * np.pi * r / spacing)) * (outer if k == rings - 1 else 1)
        yield r, dr, turn + 2.0 * np.pi * np.arange(n) / n
        turn += np.pi / n


def seed_disk_rings(disk: Disk, spacing: float, outer: int = 1
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Points of a disk on concentric rings; returns (x (n, 2), volume (n,)).

    N = max(1, round(R/δ)) rings of width Δr = R/N; ring k (radius r_k = (k + ½) Δr) holds
    n_k = max(3, round(2π r_k/δ)) points at equal angles (ring k turned by half a spacing
    against ring k − 1), each of volume 2π r_k Δr / n_k: the volumes add up to πR² exactly.
    The outermost ring holds ``outer`` × n_k points (the disk's contact sites against other
    grains are its outer points).
    """
    xs, vols = [], []
    for r, dr, angle in _disk_rings(disk, spacing, outer):
        xs.append(np.column_stack([r * np.cos(angle), r * np.sin(angle)]))
        vols.append(np.full(angle.size, 2.0 * np.pi * r * dr / angle.size))
    return np.concatenate(xs) + np.asarray(disk.center, dtype=float), np.concatenate(vols)


@dataclass(frozen=True)
class PointCells:
    """Reference cells of 2D material points: per point a frame (n, 2, 2) whose columns
    are the cell's axes e₁, e₂, and ``shape`` (n, 3): (a, b, 0) for a rectangle a × b
    centred on the point along them (lattice points: δ × δ), or (r, Δr, α) for a ring
    sector (radii r ± ½Δr, angles ±α about e₁ from the ring's centre, the point at r e₁
    from it). Both have the point's volume as their area."""

    frame: np.ndarray
    shape: np.ndarray

    def __getitem__(self, index) -> PointCells:
        return PointCells(self.frame[index], self.shape[index])

    def area(self) -> np.ndarray:
        """Each cell's area: a b for a rectangle, 2α r Δr for a ring sector."""
        a, b, alpha = self.shape.T
        return np.where(alpha == 0.0, a * b, 2.0 * alpha * a * b)

    @staticmethod
    def concatenate(parts: list[PointCells]) -> PointCells:
        return PointCells(np.concatenate([p.frame for p in parts]),
                          np.concatenate([p.shape for p in parts]))


def disk_ring_cells(disk: Disk, spacing: float, outer: int = 1) -> PointCells:
    """The ring sectors of :func:`seed_disk_rings`' points, in the same order: frame
    (e_r, e_θ) at each point, shape (r_k, Δr, π/n_k); area 2π r_k Δr/n_k, the point's
    volume, and together they tile the disk."""
    frames, shapes = [], []
    for r, dr, angle in _disk_rings(disk, spacing, outer):
        c, s = np.cos(angle), np.sin(angle)
        frames.append(np.stack([np.column_stack([c, -s]), np.column_stack([s, c])], axis=1))
        shapes.append(np.tile([r, dr, np.pi / angle.size], (angle.size, 1)))
    return PointCells(np.concatenate(frames), np.concatenate(shapes))


def lattice_cells(vol0: np.ndarray, dim: int = 2) -> PointCells:
    """Reference cells of lattice points: squares of side δ = √V0 along the axes."""
    if dim != 2:
        raise NotImplementedError("point cells are written for 2D")
    side = np.sqrt(np.asarray(vol0, float))
    return PointCells(np.tile(np.eye(2), (side.size, 1, 1)),
                      np.column_stack([side, side, np.zeros(side.size)]))

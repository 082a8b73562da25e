"""Fixed-radius neighbour search over one body's points by a cell list (Numba kernels).

The points are binned into cubic cells of side s ≥ ``radius`` (a counting sort; s a hair
above the radius, so that a point at the radius is never two cells away by round-off, and
larger where the cells would outnumber the points many times); the points within
``radius`` of a query point x lie in the 3^d cells around x's cell. The lists come in CSR
form (ptr, flat), each point once, in the order of the cells and, within a cell, of the
points' indices. The kernel surfaces (surfaces.py) use it instead of a k-d tree's ball
query, whose Python lists cost more than the kernel sums over them (session 29: ~5% of a
dense compaction step).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _cell_of(x, p, origin, side, dims):
    """The flat index of the cell holding x[p] (clamped to the grid of cells)."""
    index, stride = 0, 1
    for j in range(x.shape[1]):
        i = int(np.floor((x[p, j] - origin[j]) / side))
        i = min(max(i, 0), dims[j] - 1)
        index += i * stride
        stride *= dims[j]
    return index


@njit(cache=True)
def _bin(points, origin, side, dims, start, order):
    """Counting sort of the points by cell: cell k holds order[start[k]:start[k + 1]]."""
    n_cells = start.size - 1
    cell = np.empty(points.shape[0], np.int64)
    for k in range(n_cells + 1):
        start[k] = 0
    for p in range(points.shape[0]):
        cell[p] = _cell_of(points, p, origin, side, dims)
        start[cell[p] + 1] += 1
    for k in range(n_cells):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    for p in range(points.shape[0]):
        order[fill[cell[p]]] = p
        fill[cell[p]] += 1


SIDE_MARGIN = 1e-9  # the cells' side is at least (1 + this) × the radius
CELLS_PER_POINT = 8  # ... and large enough for at most this many cells a point (and 64)


@njit(cache=True, inline="always")
def distance2(x, i, points, q):
    """‖x[i] − points[q]‖² (summed over the axes in order)."""
    total = 0.0
    for j in range(x.shape[1]):
        total += (x[i, j] - points[q, j]) ** 2
    return total


@njit(cache=True, inline="always")
def cell_base(x, i, origin, side, base):
    """base = the (unclamped) cell coordinates of x[i] in cells of ``side`` from origin."""
    for j in range(x.shape[1]):
        base[j] = int(np.floor((x[i, j] - origin[j]) / side))


@njit(cache=True, inline="always")
def cell_around(base, code, dims):
    """The flat index of the cell at offset ``code`` (0 … 3^d − 1, a base-3 digit per axis:
    −1, 0, +1) from the cell ``base``; −1 where it lies outside the grid of ``dims``."""
    rem, index, stride, inside = code, 0, 1, True
    for j in range(base.size):
        c = base[j] + rem % 3 - 1
        rem //= 3
        if c < 0 or c >= dims[j]:
            inside = False
        index += c * stride
        stride *= dims[j]
    return index if inside else -1


@njit(cache=True)
def _search(x, points, origin, side, dims, start, order, radius, ptr, out, count_only):
    """For each x[i]: the points within ``radius`` (‖x − x_q‖ ≤ radius). With
    ``count_only`` their number goes to ptr[i + 1]; else they are written to out from
    ptr[i]."""
    d = x.shape[1]
    r2 = radius * radius
    around = 3 ** d
    base = np.empty(d, np.int64)
    for i in range(x.shape[0]):
        cell_base(x, i, origin, side, base)
        found = 0
        for code in range(around):
            index = cell_around(base, code, dims)
            if index < 0:
                continue
            for e in range(start[index], start[index + 1]):
                q = order[e]
                if distance2(x, i, points, q) <= r2:
                    if not count_only:
                        out[ptr[i] + found] = q
                    found += 1
        if count_only:
            ptr[i + 1] = found


class PointCells:
    """A body's points binned into cells, for ball queries of ``radius``."""

    def __init__(self, points: np.ndarray, radius: float) -> None:
        self.points = np.ascontiguousarray(points, float)
        self.radius = float(radius)
        d = self.points.shape[1]
        lower = self.points.min(axis=0) if len(self.points) else np.zeros(d)
        upper = self.points.max(axis=0) if len(self.points) else np.zeros(d)
        self.origin = lower
        extent = upper - lower
        side = self.radius * (1.0 + SIDE_MARGIN)
        most = CELLS_PER_POINT * len(self.points) + 64
        cells = np.prod(np.floor(extent / side) + 1.0)
        if cells > most:  # (far-flung points: fewer, larger cells)
            side *= (cells / most) ** (1.0 / d)
            while np.prod(np.floor(extent / side) + 1.0) > most:
                side *= 1.1
        self.side = side
        self.dims = np.floor(extent / side).astype(np.int64) + 1
        self.start = np.empty(int(np.prod(self.dims)) + 1, np.int64)
        self.order = np.empty(len(self.points), np.int64)
        _bin(self.points, self.origin, self.side, self.dims, self.start, self.order)

    def ball(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The points within the radius of each x (‖x − x_q‖ ≤ radius), in CSR form."""
        x = np.ascontiguousarray(x, float)
        ptr = np.zeros(len(x) + 1, np.int64)
        args = (x, self.points, self.origin, self.side, self.dims, self.start, self.order,
                self.radius)
        _search(*args, ptr, ptr, True)
        np.cumsum(ptr, out=ptr)
        flat = np.empty(int(ptr[-1]), np.int64)
        _search(*args, ptr, flat, False)
        return ptr, flat

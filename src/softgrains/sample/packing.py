"""Loose random packings of polydisperse disks in a rectangular box (rain deposit).

Diameters are drawn uniformly in [d(1 − p), d(1 + p)]. The disks are then dropped one after the
other, in the (random) order they were drawn, into the box [0, W] × [0, H]: for each disk a batch
of random x positions is tried, the disk falls vertically at each of them until it touches the
floor or a disk already placed, and the lowest of these resting places is kept. Keeping the best
of a small batch lets the disks find pockets without reaching a dense, crystalline arrangement:
every disk rests on the floor or on another disk, and the pile is loose (φ ≈ 0.6–0.7 for a few
tens of disks with p = 0.2 in a box five diameters wide). All the randomness comes from
``np.random.default_rng(seed)``, so a seed gives a bit-identical sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

#: Random drop positions tried per disk; the lowest resting place wins. Larger batches give
#: denser piles (1: ballistic deposit, φ ≈ 0.35; 32: φ ≈ 0.65; 128: φ ≈ 0.69 for 30 disks).
TRIES_PER_DISK = 32
#: Extra batches a disk gets when its best drop does not fit below a given box height; after
#: that the whole deposit restarts with twice as many tries per disk (a denser pile).
RETRIES = 4


@dataclass(frozen=True, eq=False)
class DiskSample:
    """Disks (centres, radii) placed inside the box [box_lower, box_upper], in metres.

    ``box_lower`` and ``box_upper`` are the inner corners of the box, i.e. the inner faces of
    the walls. The arrays are read-only.
    """

    centers: np.ndarray
    radii: np.ndarray
    box_lower: np.ndarray
    box_upper: np.ndarray

    def __post_init__(self) -> None:
        for name in ("centers", "radii", "box_lower", "box_upper"):
            value = np.array(getattr(self, name), dtype=np.float64)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        n = len(self.radii)
        if self.radii.shape != (n,) or self.centers.shape != (n, 2):
            raise ValueError(
                f"centers must have shape (n, 2) and radii shape (n,); got {self.centers.shape} "
                f"and {self.radii.shape}"
            )
        if self.box_lower.shape != (2,) or self.box_upper.shape != (2,):
            raise ValueError("box_lower and box_upper must be 2-vectors")

    @property
    def packing_fraction(self) -> float:
        """Total disk area divided by the box area."""
        area = float(np.prod(self.box_upper - self.box_lower))
        return float(np.pi * np.sum(self.radii**2) / area)


def _positive(name: str, value: float) -> float:
    """Return ``value`` as a float, or raise ValueError if it is not finite and positive."""
    value = float(value)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} = {value:g} must be a finite positive number")
    return value


class _Pile:
    """The disks placed so far, binned by their centre's x in columns of width
    w ≥ 2 r_max + clearance (a falling disk at x can only touch disks of its own column and
    its two neighbours); each column is a list from the newest disk back (``previous``), with
    ``top_below[j]`` = the highest top y + r among disk j and the older disks of its column.
    At most 4 columns a disk (wider ones where the box is far wider than the disks: the
    columns' memory stays O(count); one 61 µm disk in a 51 km box asked 7 GiB)."""

    def __init__(self, count: int, width: float, largest_radius: float, clearance: float
                 ) -> None:
        self.column_width = max(2.0 * largest_radius + clearance, width / (4 * count + 1))
        self.newest = -np.ones(int(width / self.column_width) + 1, np.int64)
        self.previous = -np.ones(count, np.int64)
        self.top_below = np.zeros(count)
        self.centers = np.empty((count, 2))
        self.radii = np.empty(count)
        self.size = 0

    def drop_heights(self, x: np.ndarray, r: float, clearance: float) -> np.ndarray:
        """Lowest admissible centre height of a disk of radius ``r`` falling at each x: it
        comes from above and stops at the first contact (at distance ``clearance``) with the
        floor or a placed disk, y = max(r + c, max_j y_j + √((r_j + r + c)² − (x − x_j)²))."""
        heights, _ = _drop_heights(np.asarray(x, float), r, clearance, self.centers,
                                   self.radii, self.newest, self.previous, self.top_below,
                                   self.column_width)
        return heights

    def place(self, center: np.ndarray, radius: float) -> None:
        """Add a disk (its column list and running top)."""
        i = self.size
        column = min(max(int(center[0] / self.column_width), 0), self.newest.size - 1)
        below = self.newest[column]
        self.previous[i] = below
        top = center[1] + radius
        self.top_below[i] = top if below < 0 else max(top, self.top_below[below])
        self.newest[column] = i
        self.centers[i], self.radii[i] = center, radius
        self.size += 1


@njit(cache=True)
def _drop_heights(x, r, clearance, centers, radii, newest, previous, top_below, column_width):
    """``_Pile.drop_heights`` over the three columns about each x, each walked from its newest
    disk back until no older disk can reach above the best height found (its running top
    + r + c is below it). Returns the heights and the number of disks examined."""
    add = r + clearance
    margin = 1e-9 * column_width  # round-off of the bound y_j + √(·) ≤ y_j + r_j + r + c
    heights = np.empty(x.size)
    examined = 0
    for t in range(x.size):
        best = add
        column = min(max(int(x[t] / column_width), 0), newest.size - 1)
        for k in range(max(column - 1, 0), min(column + 2, newest.size)):
            j = newest[k]
            while j >= 0 and top_below[j] + add + margin > best:
                examined += 1
                reach = radii[j] + add
                dx = x[t] - centers[j, 0]
                h2 = reach**2 - dx**2
                if h2 > 0.0:
                    best = max(best, centers[j, 1] + np.sqrt(h2))
                j = previous[j]
        heights[t] = best
    return heights, examined


def _deposit(rng: np.random.Generator, radii: np.ndarray, width: float, clearance: float,
             height: float | None, tries: int, budget: int) -> tuple[np.ndarray | None, int]:
    """Drop the disks in order, each at the lowest of ``tries`` random x positions.

    Returns the centres and the number of random drops used, or None for the centres if a disk
    found no place below ``height`` within ``RETRIES`` extra batches or the ``budget`` ran out.
    """
    pile = _Pile(len(radii), width, float(radii.max()), clearance)
    used = 0
    for r in radii:
        lo, hi = r + clearance, width - r - clearance
        for _ in range(1 + RETRIES):
            if used + tries > budget:
                return None, used
            used += tries
            x = rng.uniform(lo, hi, size=tries)
            y = pile.drop_heights(x, r, clearance)
            best = int(np.argmin(y))
            if height is None or y[best] + r + clearance <= height:
                pile.place(np.array([x[best], y[best]]), r)
                break
        else:
            return None, used
    return pile.centers, used


def generate_disks(count: int, mean_diameter: float, polydispersity: float, box_width: float,
                   seed: int, clearance: float = 0.0, box_height: float | None = None,
                   max_attempts: int | None = None) -> DiskSample:
    """Generate a loose, non-overlapping rain deposit of ``count`` disks in a box.

    Diameters are uniform in [d(1 − p), d(1 + p)] with d = ``mean_diameter`` and
    p = ``polydispersity``. Each disk, in drawing order, is dropped at ``TRIES_PER_DISK``
    random x positions and kept at the lowest resting place (see the module docstring). Every
    disk stays at least ``clearance`` (surface to surface) from every other disk and from the
    box faces. The box is [0, box_width] × [0, H]; if ``box_height`` is None, H is the top of
    the highest disk plus ``clearance``, otherwise every disk must fit below ``box_height``:
    a disk whose best drop does not fit gets ``RETRIES`` more batches, after which the whole
    deposit restarts with twice as many tries per disk (denser); ``max_attempts`` bounds the
    total number of random drops (None: max(200 000, 64 × TRIES_PER_DISK × count), room for
    the restarts up to 1024 tries per disk). Each drop is checked against the disks of three
    columns about it, newest first (``_Pile``): the cost grows about as count, not count². A
    roomy ``box_height`` gives the same disks as None.
    The same ``seed`` gives a bit-identical sample. Raises ValueError for impossible requests.
    """
    if isinstance(count, bool) or int(count) != count or count < 1:
        raise ValueError(f"count = {count} must be an integer >= 1 (the number of disks)")
    count = int(count)
    mean_diameter = _positive("mean_diameter", mean_diameter)
    box_width = _positive("box_width", box_width)
    polydispersity = float(polydispersity)
    if not 0.0 <= polydispersity < 1.0:
        raise ValueError(
            f"polydispersity = {polydispersity:g} must lie in [0, 1): diameters are drawn in "
            f"[d(1 - p), d(1 + p)], so p >= 1 would give non-positive diameters"
        )
    clearance = float(clearance)
    if not np.isfinite(clearance) or clearance < 0.0:
        raise ValueError(f"clearance = {clearance:g} m must be a finite number >= 0")
    if box_height is not None:
        box_height = _positive("box_height", box_height)
    if max_attempts is None:
        max_attempts = max(200_000, 64 * TRIES_PER_DISK * count)
    if isinstance(max_attempts, bool) or int(max_attempts) != max_attempts:
        raise ValueError(f"max_attempts = {max_attempts} must be an integer")
    max_attempts = int(max_attempts)
    needed = count * TRIES_PER_DISK
    if max_attempts < needed:
        raise ValueError(
            f"max_attempts = {max_attempts} is smaller than the {needed} random drops the deposit "
            f"needs at least ({TRIES_PER_DISK} per disk for {count} disks); raise max_attempts"
        )

    rng = np.random.default_rng(seed)
    diameters = rng.uniform(mean_diameter * (1.0 - polydispersity),
                            mean_diameter * (1.0 + polydispersity), size=count)
    radii = 0.5 * diameters
    largest = float(diameters.max())
    if box_width < largest + 2.0 * clearance:
        raise ValueError(
            f"box_width = {box_width:g} m is smaller than the largest diameter {largest:g} m "
            f"+ 2 × clearance ({2.0 * clearance:g} m); widen the box or reduce mean_diameter, "
            f"polydispersity or clearance"
        )
    if box_height is not None:
        if box_height < largest + 2.0 * clearance:
            raise ValueError(
                f"box_height = {box_height:g} m is smaller than the largest diameter {largest:g} m "
                f"+ 2 × clearance ({2.0 * clearance:g} m); raise box_height or leave it None"
            )
        disk_area = float(np.pi * np.sum(radii**2))
        if disk_area > box_width * box_height:
            raise ValueError(
                f"the total disk area {disk_area:g} m² is larger than the box area "
                f"box_width × box_height = {box_width * box_height:g} m²; use fewer or smaller "
                f"disks or a larger box (or leave box_height None)"
            )

    centers, tries, attempts = None, TRIES_PER_DISK, 0
    while centers is None:
        centers, used = _deposit(rng, radii, box_width, clearance, box_height, tries,
                                 max_attempts - attempts)
        attempts += used
        if centers is None:
            tries = min(2 * tries, 1024)
            if attempts + count * tries > max_attempts:
                raise ValueError(
                    f"box_height = {box_height:g} m is too small: the disks found no place "
                    f"below it after max_attempts = {max_attempts} random drops; raise "
                    f"box_height (or leave it None), use fewer or smaller disks, or raise "
                    f"max_attempts"
                )

    if box_height is None:
        box_height = float(np.max(centers[:, 1] + radii)) + clearance
    return DiskSample(centers=centers, radii=radii, box_lower=np.zeros(2),
                      box_upper=np.array([box_width, box_height]))

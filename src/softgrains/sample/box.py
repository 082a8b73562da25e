"""A generated sample in its box: the grains of packing.py and four kinematic walls.

The box's inner faces are x = 0, x = W (side walls), y = 0 (bottom) and y = H (top wall,
which the loading protocol moves). Walls are rectangles of material points of thickness t:

    bottom [−t, W + t] × [−t, 0]    left  [−t, 0] × [0, H + t]
    top    [0, W] × [H, H + t]      right [W, W + t] × [0, H + t]

Kinematic walls never interact with each other (contact/coupling.py skips such pairs).
"""

from __future__ import annotations

from dataclasses import dataclass

from softgrains.sample.packing import DiskSample, generate_disks

WALLS = ("wall_bottom", "wall_top", "wall_left", "wall_right")
GRAIN_PREFIX = "grain"


@dataclass(frozen=True)
class BoxLayout:
    """The grains and the inner box of a generated sample."""

    grains: DiskSample
    width: float
    height: float
    thickness: float

    def wall_rectangles(self) -> dict[str, tuple[list[float], list[float]]]:
        """Lower and upper corners of each wall, by name."""
        W, H, t = self.width, self.height, self.thickness
        return {
            "wall_bottom": ([-t, -t], [W + t, 0.0]),
            "wall_top": ([0.0, H], [W, H + t]),
            "wall_left": ([-t, 0.0], [0.0, H + t]),
            "wall_right": ([W, 0.0], [W + t, H + t]),
        }

    def body_tables(self, material: str, wall_material: str) -> list[dict]:
        """The grains and walls as ``[[bodies]]`` tables (grains first)."""
        tables = [
            {"name": f"{GRAIN_PREFIX}{i:03d}", "shape": "disk", "center": [float(c) for c in x],
             "radius": float(r), "material": material}
            for i, (x, r) in enumerate(zip(self.grains.centers, self.grains.radii, strict=True))
        ]
        for name, (lower, upper) in self.wall_rectangles().items():
            tables.append({"name": name, "shape": "rectangle", "lower": lower, "upper": upper,
                           "material": wall_material, "kind": "kinematic"})
        return tables

    def domain(self, cell_size: float) -> tuple[list[float], list[float]]:
        """Grid origin and size enclosing the box and its walls, one cell of margin."""
        t, m = self.thickness, cell_size
        origin = [-t - m, -t - m]
        size = [self.width + 2 * (t + m), self.height + 2 * (t + m)]
        return origin, size


def box_layout(count: int, mean_diameter: float, polydispersity: float, box_width: float,
               seed: int, clearance: float, thickness: float) -> BoxLayout:
    """Deposit the grains (packing.py) and put the top wall ``clearance`` above the pile."""
    grains = generate_disks(count, mean_diameter, polydispersity, box_width, seed,
                            clearance=clearance)
    return BoxLayout(grains, box_width, float(grains.box_upper[1]), thickness)

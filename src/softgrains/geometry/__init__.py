"""Body shapes and material-point seeding (ALGORITHM.md §1)."""

from softgrains.geometry.shapes import (
    Disk,
    Polygon,
    Rectangle,
    Shape,
    seed_disk_rings,
    seed_points,
    translated,
)

__all__ = ["Disk", "Polygon", "Rectangle", "Shape", "seed_disk_rings", "seed_points", "translated"]

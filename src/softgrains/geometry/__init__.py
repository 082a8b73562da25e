"""Body shapes and material-point seeding (ALGORITHM.md §1)."""

from softgrains.geometry.shapes import (
    Disk,
    PointCells,
    Polygon,
    Rectangle,
    Shape,
    disk_ring_cells,
    lattice_cells,
    seed_disk_rings,
    seed_points,
    translated,
)

__all__ = ["Disk", "PointCells", "Polygon", "Rectangle", "Shape", "disk_ring_cells",
           "lattice_cells", "seed_disk_rings", "seed_points", "translated"]

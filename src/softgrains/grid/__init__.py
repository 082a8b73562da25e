"""The background lattice, shape functions and per-body node sets (ALGORITHM.md §2)."""

from softgrains.grid.lattice import Lattice, NodeBox
from softgrains.grid.shape_functions import SHAPE_FUNCTIONS, compute_stencils, stencil_width

__all__ = ["SHAPE_FUNCTIONS", "Lattice", "NodeBox", "compute_stencils", "stencil_width"]

"""Grains drawn as continuous bodies (issue #13, item 1), 2D.

Each grain is filled by a triangulation of its material points and of the vertices of its
outline (observe/shapes.grain_outline: the boundary of its deformed cells), with the
triangles outside the outline removed, so that it is filled without holes up to its true
boundary. A point field is shaded linearly over the triangles (Gouraud); the outline
vertices take the inverse-distance mean of their three nearest points. All grains of a
frame go into one triangulation (one artist, fast for 1000 grains); kinematic walls are
drawn as the rectangles their points fill.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import Colormap, Normalize
from matplotlib.patches import Rectangle
from matplotlib.path import Path as PolygonPath
from matplotlib.tri import Triangulation
from scipy.spatial import Delaunay, cKDTree

from softgrains.observe.shapes import grain_outline

OUTLINE_SPACING = 0.5  # outline vertices kept for the triangulation, in point spacings
OUTLINE_PIXELS = 4  # raster pixels per point spacing for a drawn outline (the shape
# descriptors average a raster twice as fine: observe/shapes.py)
_EDGE_COLOR = "black"
_EDGE_WIDTH = 0.4
_WALL_COLOR = "0.6"


@dataclass(frozen=True)
class GrainPoints:
    """The points of one frame: positions (n, 2), deformation gradients (n, 2, 2), initial
    cell sides √V0 (n,), body index per point (n,) and which bodies are kinematic walls."""

    positions: np.ndarray
    F: np.ndarray
    side: np.ndarray
    body: np.ndarray
    wall_bodies: frozenset[int]


@dataclass(frozen=True)
class GrainMesh:
    """Every grain of a frame as one triangulation: vertices (m, 2) — the points, then the
    outline vertices —, triangles (t, 3) into them, which point each vertex takes its
    value from (inverse-distance weights over ``sources`` (m, 3) with ``weights``), the
    outlines (one closed polygon per grain), the grains' body indices and which grain
    (position in ``grains``) each triangle belongs to."""

    vertices: np.ndarray
    triangles: np.ndarray
    sources: np.ndarray
    weights: np.ndarray
    outlines: list[np.ndarray]
    grains: list[int]
    triangle_grain: np.ndarray

    def values(self, point_values: np.ndarray) -> np.ndarray:
        """A point field at the mesh vertices."""
        return np.einsum("mk,mk->m", self.weights, np.asarray(point_values)[self.sources])

    def filled_area(self, grain_index: int | None = None) -> float:
        """Area of the triangles (of one grain, by its position in ``grains``, or of all)."""
        tri = (self.triangles if grain_index is None
               else self.triangles[self.triangle_grain == grain_index])
        a, b, c = (self.vertices[tri[:, k]] for k in range(3))
        ab, ac = b - a, c - a
        return float(0.5 * np.sum(np.abs(ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])))


def _grain_points(points: GrainPoints):
    """(body, indices of its points) of every grain (not a wall) of ``points``."""
    for body in np.unique(points.body):
        if int(body) not in points.wall_bodies:
            yield int(body), np.flatnonzero(points.body == body)


def _outline(points: GrainPoints, index: np.ndarray) -> np.ndarray:
    """The drawn outline of the grain made of the points ``index``."""
    return grain_outline(points.positions[index], points.F[index], points.side[index],
                         OUTLINE_PIXELS, subpixels=1)


def grain_outlines(points: GrainPoints) -> list[np.ndarray]:
    """The outline of every grain of ``points`` (closed polygons, in body order)."""
    return [_outline(points, index) for _, index in _grain_points(points)]


def grain_mesh(points: GrainPoints) -> GrainMesh:
    """Triangulate every grain of ``points`` (see the module docstring)."""
    vertices, triangles, sources, weights, outlines, grains, owner = [], [], [], [], [], [], []
    count = 0
    for body, index in _grain_points(points):
        x = points.positions[index]
        outline = _outline(points, index)
        spacing = float(np.median(points.side[index]))
        ring = _resample(outline, OUTLINE_SPACING * spacing)
        local = np.vstack([x, ring])
        simplices = Delaunay(local).simplices
        centroids = local[simplices].mean(axis=1)
        inside = PolygonPath(outline).contains_points(centroids)
        near = min(3, len(x))
        distance, nearest = cKDTree(x).query(ring, k=near)
        distance = np.asarray(distance).reshape(len(ring), near)
        nearest = np.asarray(nearest).reshape(len(ring), near)
        idw = 1.0 / np.maximum(distance, 1e-12 * spacing)
        idw /= idw.sum(axis=1, keepdims=True)
        src = np.zeros((len(local), 3), np.int64)
        wts = np.zeros((len(local), 3))
        src[: len(x), 0], wts[: len(x), 0] = index, 1.0
        src[len(x):, :near], wts[len(x):, :near] = index[nearest], idw
        vertices.append(local)
        triangles.append(simplices[inside] + count)
        sources.append(src)
        weights.append(wts)
        outlines.append(outline)
        owner.append(np.full(int(inside.sum()), len(grains)))
        grains.append(body)
        count += len(local)
    if not grains:
        none = np.zeros((0, 3), np.int64)
        return GrainMesh(np.zeros((0, 2)), none, none, np.zeros((0, 3)), [], [],
                         np.zeros(0, np.int64))
    return GrainMesh(np.vstack(vertices), np.vstack(triangles), np.vstack(sources),
                     np.vstack(weights), outlines, grains, np.concatenate(owner))


def _resample(outline: np.ndarray, spacing: float) -> np.ndarray:
    """Vertices along the closed ``outline`` about ``spacing`` apart."""
    closed = np.vstack([outline, outline[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    count = max(int(np.ceil(arc[-1] / spacing)), 8)
    at = np.linspace(0.0, arc[-1], count, endpoint=False)
    return np.column_stack([np.interp(at, arc, closed[:, 0]), np.interp(at, arc, closed[:, 1])])


def draw_grains(ax: Axes, mesh: GrainMesh, point_values: np.ndarray, norm: Normalize,
                cmap: str | Colormap = "viridis"):
    """Fill the grains of ``mesh`` shaded by ``point_values`` and draw their outlines;
    returns the filled artist (for a colour bar)."""
    if not mesh.grains:
        return None
    triangulation = Triangulation(mesh.vertices[:, 0], mesh.vertices[:, 1], mesh.triangles)
    filled = ax.tripcolor(triangulation, mesh.values(point_values), shading="gouraud",
                          norm=norm, cmap=cmap, rasterized=True)
    ax.add_collection(LineCollection([np.vstack([o, o[:1]]) for o in mesh.outlines],
                                     colors=_EDGE_COLOR, linewidths=_EDGE_WIDTH),
                      autolim=False)
    return filled


def wall_rectangles(points: GrainPoints) -> list[tuple[np.ndarray, np.ndarray]]:
    """(lower corner, upper corner) of each wall body: the box its points' cells fill."""
    boxes = []
    for body in sorted(points.wall_bodies):
        index = points.body == body
        if not np.any(index):
            continue
        half = 0.5 * points.side[index, None] * np.abs(points.F[index]).sum(axis=2)
        boxes.append(((points.positions[index] - half).min(axis=0),
                      (points.positions[index] + half).max(axis=0)))
    return boxes


def draw_walls(ax: Axes, points: GrainPoints) -> None:
    """Draw the kinematic walls as grey rectangles at their true position."""
    for lower, upper in wall_rectangles(points):
        ax.add_patch(Rectangle(tuple(lower), *(upper - lower), facecolor=_WALL_COLOR,
                               edgecolor="none"))

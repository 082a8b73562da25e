"""VTK XML output of material points (``.vtu``) and of their time series (``.pvd``).

We write the format ourselves rather than depend on ``vtk`` or ``meshio``: a point cloud of
vertex cells with binary inline arrays is about a page of code, while those packages are
large binary or extra dependencies for a single file type.

Each ``.vtu`` holds one ``VTK_VERTEX`` cell per point so that ParaView draws the points (or
``VTK_LINE`` cells between given pairs of points, with cell arrays: the force chains); point
arrays are scalars (one component), vectors (padded to 3 components) or tensors (padded to
3x3, written as 9 components). Arrays are base64-encoded little-endian binary, each preceded by
its byte count as a UInt64 header encoded separately.
"""

from __future__ import annotations

import base64
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path, PurePath

import numpy as np

from softgrains.io.summary import write_bytes_atomic

_VTK_VERTEX = 1
_VTK_LINE = 3
_HEADER = np.dtype("<u8")
_HEADER_CHARS = 4 * -(-_HEADER.itemsize // 3)  # base64 length of the encoded header
_VTK_TYPES = {
    np.dtype(np.int8): "Int8",
    np.dtype(np.uint8): "UInt8",
    np.dtype(np.int16): "Int16",
    np.dtype(np.uint16): "UInt16",
    np.dtype(np.int32): "Int32",
    np.dtype(np.uint32): "UInt32",
    np.dtype(np.int64): "Int64",
    np.dtype(np.uint64): "UInt64",
    np.dtype(np.float32): "Float32",
    np.dtype(np.float64): "Float64",
}
_NUMPY_TYPES = {name: dtype for dtype, name in _VTK_TYPES.items()}


def _pad(array: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Zero-pad ``array`` to ``shape`` (same number of axes)."""
    padded = np.zeros(shape, dtype=array.dtype)
    padded[tuple(slice(0, s) for s in array.shape)] = array
    return padded


def _components(name: str, values: np.ndarray, n: int, kind: str = "point") -> np.ndarray:
    """A point or cell array as ``(n, components)``: scalar -> 1, vector -> 3, tensor -> 9."""
    if values.shape[:1] != (n,):
        raise ValueError(f"{kind} array {name!r} has shape {values.shape}, expected ({n}, ...)")
    if values.ndim == 1:
        return values.reshape(n, 1)
    if values.ndim == 2 and values.shape[1] in (2, 3):
        return _pad(values, (n, 3))
    if values.ndim == 3 and values.shape[1:] in ((2, 2), (3, 3)):
        return _pad(values, (n, 3, 3)).reshape(n, 9)
    raise ValueError(
        f"{kind} array {name!r} has shape {values.shape}: expected (n,), (n, d) or (n, d, d) "
        "with d = 2 or 3"
    )


def _data_array(parent: ET.Element, values: np.ndarray, name: str | None = None) -> None:
    """Append a binary ``DataArray`` holding ``values`` (shape ``(n,)`` or ``(n, k)``)."""
    if values.dtype == np.bool_:
        values = values.astype(np.uint8)
    vtk_type = _VTK_TYPES.get(values.dtype)
    if vtk_type is None:
        raise TypeError(f"point array {name!r}: unsupported dtype {values.dtype}")
    data = np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("<")).tobytes()
    header = np.array([len(data)], dtype=_HEADER).tobytes()
    attributes = {"type": vtk_type, "format": "binary"}
    if name is not None:
        attributes["Name"] = name
    if values.ndim == 2:
        attributes["NumberOfComponents"] = str(values.shape[1])
    element = ET.SubElement(parent, "DataArray", attributes)
    element.text = (base64.b64encode(header) + base64.b64encode(data)).decode("ascii")


def write_points_vtu(
    path: str | Path, positions: np.ndarray, point_data: Mapping[str, np.ndarray],
    lines: np.ndarray | None = None, line_data: Mapping[str, np.ndarray] | None = None
) -> None:
    """Write material points at ``positions`` ``(n, d)`` with their ``point_data`` to ``path``.

    Each array is ``(n,)`` scalar, ``(n, d)`` vector or ``(n, d, d)`` tensor, float or int.
    The cells are one vertex per point, or, when ``lines`` ``(k, 2)`` (point indices) is
    given, one line per row with its ``line_data`` (cell arrays, ``(k, ...)``): e.g. the
    force chains. The file is replaced atomically.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] not in (2, 3):
        raise ValueError(f"positions have shape {positions.shape}, expected (n, d), d = 2 or 3")
    n = positions.shape[0]
    if lines is None:
        connectivity = np.arange(n, dtype=np.int64)
        offsets = np.arange(1, n + 1, dtype=np.int64)
        types = np.full(n, _VTK_VERTEX, dtype=np.uint8)
    else:
        lines = np.asarray(lines, dtype=np.int64).reshape(-1, 2)
        connectivity = lines.ravel()
        offsets = 2 * np.arange(1, len(lines) + 1, dtype=np.int64)
        types = np.full(len(lines), _VTK_LINE, dtype=np.uint8)

    root = ET.Element(
        "VTKFile",
        type="UnstructuredGrid",
        version="1.0",
        byte_order="LittleEndian",
        header_type="UInt64",
    )
    grid = ET.SubElement(root, "UnstructuredGrid")
    piece = ET.SubElement(grid, "Piece", NumberOfPoints=str(n), NumberOfCells=str(len(types)))
    data = ET.SubElement(piece, "PointData")
    for name, values in point_data.items():
        _data_array(data, _components(name, np.asarray(values), n), name)
    if line_data:
        cell_data = ET.SubElement(piece, "CellData")
        for name, values in line_data.items():
            _data_array(cell_data, _components(name, np.asarray(values), len(types), "cell"),
                        name)
    points = ET.SubElement(piece, "Points")
    _data_array(points, _pad(positions, (n, 3)))
    cells = ET.SubElement(piece, "Cells")
    _data_array(cells, connectivity, "connectivity")
    _data_array(cells, offsets, "offsets")
    _data_array(cells, types, "types")

    ET.indent(root)
    write_bytes_atomic(path, ET.tostring(root, encoding="utf-8", xml_declaration=True))


def _read_data_array(element: ET.Element) -> np.ndarray:
    """Decode a binary ``DataArray`` written by :func:`write_points_vtu` into ``(n, k)``."""
    text = "".join((element.text or "").split())
    size = int(np.frombuffer(base64.b64decode(text[:_HEADER_CHARS]), dtype=_HEADER)[0])
    dtype = _NUMPY_TYPES[element.attrib["type"]].newbyteorder("<")
    values = np.frombuffer(base64.b64decode(text[_HEADER_CHARS:])[:size], dtype=dtype)
    components = int(element.get("NumberOfComponents", "1"))
    return values.astype(dtype.newbyteorder("=")).reshape(-1, components)


def read_points_vtu(
    path: str | Path, dim: int | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Read a file written by :func:`write_points_vtu`: ``(positions, point_data)``.

    Positions and vectors come back with 3 components and tensors as 3x3, unless ``dim`` is
    given, which trims them to ``d`` and ``d x d``; scalars come back as ``(n,)``.
    """
    root = ET.parse(path).getroot()
    if root.get("header_type") != "UInt64" or root.get("byte_order") != "LittleEndian":
        raise ValueError(f"{path}: not a little-endian UInt64-header VTK file")
    piece = root.find("UnstructuredGrid/Piece")
    points = piece.find("Points/DataArray") if piece is not None else None
    if piece is None or points is None:
        raise ValueError(f"{path}: no UnstructuredGrid piece with points")
    d = 3 if dim is None else dim
    positions = _read_data_array(points)[:, :d]
    point_data: dict[str, np.ndarray] = {}
    for element in piece.iterfind("PointData/DataArray"):
        values = _read_data_array(element)
        n, k = values.shape
        if k == 1:
            point_data[element.attrib["Name"]] = values[:, 0]
        elif k == 9:
            point_data[element.attrib["Name"]] = values.reshape(n, 3, 3)[:, :d, :d]
        else:
            point_data[element.attrib["Name"]] = values[:, :d]
    return positions, point_data


class PvdSeries:
    """A ``.pvd`` collection of snapshot files, rewritten atomically after each :meth:`add`."""

    def __init__(self, path: str | Path, entries: list[tuple[float, str]] | None = None) -> None:
        """Start a collection at ``path`` (replacing any previous one) with ``entries``
        (default: none; a resumed run passes the entries it keeps)."""
        self.path = Path(path)
        self.entries: list[tuple[float, str]] = list(entries or [])
        self._write()

    def add(self, time: float, vtu_relative_path: str | PurePath) -> None:
        """Register the snapshot ``vtu_relative_path`` (relative to the ``.pvd``) at ``time``."""
        self.entries.append((float(time), PurePath(vtu_relative_path).as_posix()))
        self._write()

    def _write(self) -> None:
        root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
        collection = ET.SubElement(root, "Collection")
        for time, file in self.entries:
            ET.SubElement(collection, "DataSet", timestep=repr(time), group="", part="0", file=file)
        ET.indent(root)
        write_bytes_atomic(self.path, ET.tostring(root, encoding="utf-8", xml_declaration=True))


def read_pvd(path: str | Path) -> list[tuple[float, str]]:
    """The ``(time, file)`` entries of a ``.pvd`` collection, in file order."""
    root = ET.parse(path).getroot()
    return [
        (float(element.attrib["timestep"]), element.attrib["file"])
        for element in root.iterfind("Collection/DataSet")
    ]

"""write_points_vtu / read_points_vtu round trips and the .pvd series."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from softgrains.io import PvdSeries, read_points_vtu, read_pvd, write_points_vtu
from softgrains.io.vtk import _read_data_array


@pytest.mark.parametrize("dim", [2, 3])
def test_vtu_round_trip(tmp_path: Path, dim: int) -> None:
    rng = np.random.default_rng(1)
    n = 11
    positions = rng.normal(size=(n, dim))
    data = {
        "J": rng.random(n),
        "velocity": rng.normal(size=(n, dim)),
        "stress": rng.normal(size=(n, dim, dim)),
        "body": np.arange(n, dtype=np.int32) % 3,
        "index": np.arange(n, dtype=np.int64),
    }
    path = tmp_path / "snapshots" / "s.vtu"
    write_points_vtu(path, positions, data)

    read_positions, read_data = read_points_vtu(path, dim=dim)
    assert np.array_equal(read_positions, positions)
    assert read_data.keys() == data.keys()
    for name, values in data.items():
        assert read_data[name].dtype == values.dtype, name
        assert np.array_equal(read_data[name], values), name

    padded_positions, padded = read_points_vtu(path)
    assert padded_positions.shape == (n, 3)
    assert np.all(padded_positions[:, dim:] == 0.0)
    assert padded["velocity"].shape == (n, 3)
    assert padded["stress"].shape == (n, 3, 3)
    assert np.array_equal(padded["stress"][:, :dim, :dim], data["stress"])


def test_vtu_has_one_vertex_cell_per_point(tmp_path: Path) -> None:
    path = tmp_path / "s.vtu"
    write_points_vtu(path, np.zeros((4, 2)), {})
    root = ET.parse(path).getroot()
    assert root.attrib["header_type"] == "UInt64"
    piece = root.find("UnstructuredGrid/Piece")
    assert piece is not None
    assert piece.attrib == {"NumberOfPoints": "4", "NumberOfCells": "4"}
    names = [e.attrib["Name"] for e in piece.iterfind("Cells/DataArray")]
    assert names == ["connectivity", "offsets", "types"]


def test_vtu_rejects_bad_shapes(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="'v'"):
        write_points_vtu(tmp_path / "s.vtu", np.zeros((3, 2)), {"v": np.zeros((2, 2))})
    with pytest.raises(ValueError, match="positions"):
        write_points_vtu(tmp_path / "s.vtu", np.zeros(3), {})
    with pytest.raises(TypeError, match="'c'"):
        write_points_vtu(tmp_path / "s.vtu", np.zeros((1, 2)), {"c": np.zeros(1, complex)})


def test_pvd_lists_every_step_and_stays_valid(tmp_path: Path) -> None:
    pvd_path = tmp_path / "snapshots.pvd"
    series = PvdSeries(pvd_path)
    assert read_pvd(pvd_path) == []
    times = [0.0, 0.1 + 0.2, 1e-300]
    for step, time in enumerate(times):
        series.add(time, Path("snapshots") / f"step_{step:06d}.vtu")
        root = ET.parse(pvd_path).getroot()
        assert root.attrib["type"] == "Collection"
        assert read_pvd(pvd_path) == [
            (t, f"snapshots/step_{s:06d}.vtu") for s, t in enumerate(times[: step + 1])
        ]
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_vtu_lines_carry_their_cell_data(tmp_path: Path) -> None:
    """The force chains' file: line cells between given points, with cell arrays."""
    path = tmp_path / "chains.vtu"
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 1.0]])
    write_points_vtu(path, points, {}, np.array([[0, 1], [2, 3]]),
                     {"force": np.array([3.0, 5.0]), "alpha": np.array([0, 1], np.int32)})
    piece = ET.parse(path).getroot().find("UnstructuredGrid/Piece")
    assert piece.attrib == {"NumberOfPoints": "4", "NumberOfCells": "2"}
    cells = {e.attrib["Name"]: _read_data_array(e) for e in piece.iterfind("Cells/DataArray")}
    assert cells["connectivity"].ravel().tolist() == [0, 1, 2, 3]
    assert cells["offsets"].ravel().tolist() == [2, 4]
    assert cells["types"].ravel().tolist() == [3, 3]  # VTK_LINE
    data = {e.attrib["Name"]: _read_data_array(e) for e in piece.iterfind("CellData/DataArray")}
    assert data["force"].ravel().tolist() == [3.0, 5.0]
    assert data["alpha"].ravel().tolist() == [0, 1]
    with pytest.raises(ValueError, match="cell array 'force'"):
        write_points_vtu(path, points, {}, np.array([[0, 1]]), {"force": np.zeros(3)})

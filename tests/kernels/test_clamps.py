"""Clamped faces (grid/clamps.py): the odd reflection of the B-spline ghost nodes behind a
face that prescribes every velocity component."""

import numpy as np
import pytest

from softgrains.grid.clamps import clamp_faces
from softgrains.grid.lattice import Lattice
from softgrains.grid.shape_functions import SHAPE_FUNCTIONS
from softgrains.grid.stencils import body_stencils
from softgrains.integrator.implicit import DirichletBox

H = 0.25
LATTICE = Lattice.covering([-1.0, -1.0], [4.0, 4.0], H)  # x = 0 and y = 1 are node planes
BSPLINE = SHAPE_FUNCTIONS["bspline2"]


def _box(lower, upper, components=(True, True)):
    return DirichletBox(np.array(lower, float), np.array(upper, float),
                        np.array(components), np.zeros(2))


# (box, axis, face coordinate, direction from the face into the body)
FACES = {
    "upper x face": (_box([-1.0, -1.0], [0.0, 3.0]), 0, 0.0, 1.0),
    "lower y face": (_box([-1.0, 1.0], [3.0, 3.0]), 1, 1.0, -1.0),
}


def _points(axis, face, direction, n=400, seed=2):
    """Points on the body's side of the face, half of them within the ghosts' reach."""
    rng = np.random.default_rng(seed)
    x = 0.5 + 1.5 * rng.random((n, 2))
    x[:, axis] = face + direction * H * np.where(np.arange(n) % 2, 0.5, 3.0) * rng.random(n)
    x[0, axis] = face + direction * 1e-12 * H  # on the face
    return x


def _stencils(x, clamps):
    stencils = body_stencils(LATTICE, BSPLINE, x, clamps=clamps)
    return stencils, LATTICE.node_positions(stencils.box)[stencils.nodes]


def test_clamp_faces_are_the_node_plane_faces_of_full_boxes():
    faces = clamp_faces(LATTICE, [_box([-1.0, -1.0], [0.0, 3.0])])
    assert sorted(map(tuple, faces[:, :3])) == sorted([
        (0, 6, 1), (0, 2, -1), (1, 18, 1), (1, 2, -1)])  # node_origin = −1 − 2h
    assert clamp_faces(LATTICE, [_box([-1.0, -1.0], [0.0, 3.0], (True, False))]).size == 0
    off_plane = clamp_faces(LATTICE, [_box([-1.0, -1.0], [0.1, 3.0])])
    assert 6 not in off_plane[off_plane[:, 0] == 0, 1]
    assert clamp_faces(LATTICE, [_box([0.0, -1.0], [0.0, 3.0])])[:, 0].tolist() == [1, 1]


@pytest.mark.parametrize("face", FACES.values(), ids=FACES.keys())
def test_reflected_functions_keep_unity_and_linear_fields(face):
    box, axis, coordinate, direction = face
    x = _points(axis, coordinate, direction)
    stencils, pos = _stencils(x, clamp_faces(LATTICE, [box]))
    N, dN = stencils.N, stencils.dN
    assert np.allclose(N.sum(axis=1), 1.0, atol=1e-14)
    assert np.allclose(dN.sum(axis=1), 0.0, atol=1e-12)
    assert np.all(N >= -1e-15)
    assert np.allclose(np.einsum("pk,pkj->pj", N, pos), x, atol=1e-12)
    assert np.allclose(np.einsum("pki,pkj->pij", pos, dN), np.eye(2), atol=1e-12)
    ghost = direction * (pos[..., axis] - coordinate) < -1e-9 * H
    assert ghost.any() and np.all(N[ghost] == 0.0) and np.all(dN[ghost] == 0.0)
    plain, _ = _stencils(x, None)
    far = np.abs(x[:, axis] - coordinate) > 0.5 * H  # beyond the ghosts' reach: unchanged
    assert np.array_equal(N[far], plain.N[far]) and np.array_equal(dN[far], plain.dN[far])


@pytest.mark.parametrize("face", FACES.values(), ids=FACES.keys())
def test_the_field_at_the_face_is_the_prescribed_value(face):
    """Nodes in the box at v̄ = 0, the others arbitrary: v(x_f) = 0, where fixing the ghosts
    alone leaves v(x_f) = v_{f+1}/8 along the face's normal."""
    box, axis, coordinate, direction = face
    x = _points(axis, coordinate, direction)[:1]
    values = {}
    for clamps in (clamp_faces(LATTICE, [box]), None):
        stencils, pos = _stencils(x, clamps)
        inside = np.all((pos >= box.lower - 1e-9) & (pos <= box.upper + 1e-9), axis=-1)
        v = np.where(inside, 0.0, 1.0 + pos[..., 1 - axis])  # free nodes: 1 + tangential
        values[clamps is None] = float(np.sum(stencils.N * v))
    assert abs(values[False]) < 1e-10
    tangential = x[0, 1 - axis]
    assert values[True] == pytest.approx((1.0 + tangential) / 8.0, rel=0.05)

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


def _box(lower, upper, components=(True, True), velocity=(0.0, 0.0)):
    return DirichletBox(np.array(lower, float), np.array(upper, float),
                        np.array(components), np.array(velocity, float))


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
    x[0, axis] = face  # on the face
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
    far = clamp_faces(LATTICE, [_box([-1.0, -1e20], [0.0, 1e20])])  # beyond the lattice
    assert far[:, :3].tolist() == [[0, 6, 1], [0, 2, -1]]


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
@pytest.mark.parametrize("prescribed", [0.0, -0.7])
def test_the_field_at_the_face_is_the_prescribed_value(face, prescribed):
    """Nodes in the box at v̄, the others arbitrary: v(x_f) = v̄, where fixing the ghosts
    alone leaves v(x_f) = v̄ + (v_{f+1} − v̄)/8 along the face's normal."""
    box, axis, coordinate, direction = face
    x = _points(axis, coordinate, direction)[:1]  # on the face
    values = {}
    for clamps in (clamp_faces(LATTICE, [box]), None):
        stencils, pos = _stencils(x, clamps)
        inside = np.all((pos >= box.lower - 1e-9) & (pos <= box.upper + 1e-9), axis=-1)
        v = np.where(inside, prescribed, 1.0 + pos[..., 1 - axis])  # free: 1 + tangential
        values[clamps is None] = float(np.sum(stencils.N * v))
    assert values[False] == pytest.approx(prescribed, abs=1e-12)
    free = 1.0 + x[0, 1 - axis]  # the free nodes' field, linear along the face
    assert values[True] == pytest.approx(prescribed + (free - prescribed) / 8.0, rel=1e-9)


def test_a_corner_the_body_wraps_round_keeps_positive_weights():
    """A body round a box's corner: each point reflects across the face in front of it
    only, so the weights stay ≥ 0 and do not depend on the order of the faces."""
    box = _box([-1.0, -1.0], [0.0, 1.0])
    rng = np.random.default_rng(3)
    x = np.column_stack((0.6 * H * rng.random(300), 1.0 + 0.6 * H * rng.random(300)))
    x = np.vstack((x, [[0.0025, 1.0025], [0.0, 1.0]]))
    faces = clamp_faces(LATTICE, [box])
    stencils, pos = _stencils(x, faces)
    reversed_order, _ = _stencils(x, faces[::-1].copy())
    assert np.all(stencils.N >= 0.0)
    assert np.allclose(stencils.N.sum(axis=1), 1.0, atol=1e-14)
    assert np.allclose(np.einsum("pk,pkj->pj", stencils.N, pos), x, atol=1e-12)
    assert np.array_equal(stencils.N, reversed_order.N)


def test_linear_hats_have_no_ghost_nodes():
    x = _points(0, 0.0, 1.0)
    faces = clamp_faces(LATTICE, [FACES["upper x face"][0]])
    plain = body_stencils(LATTICE, SHAPE_FUNCTIONS["linear"], x)
    clamped = body_stencils(LATTICE, SHAPE_FUNCTIONS["linear"], x, clamps=faces)
    assert np.array_equal(plain.N, clamped.N) and np.array_equal(plain.dN, clamped.dN)

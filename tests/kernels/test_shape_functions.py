"""Shape functions: partition of unity and exact reproduction of linear fields (ALGORITHM.md §2)."""

import numpy as np
import pytest

from softgrains.grid.shape_functions import SHAPE_FUNCTIONS, compute_stencils, stencil_width


def _stencil_positions(base, s, h, origin):
    n, d = base.shape
    ns = s**d
    pos = np.empty((n, ns, d))
    for k in range(ns):
        rem = k
        for j in range(d):
            pos[:, k, j] = origin[j] + h * (base[:, j] + rem % s)
            rem //= s
    return pos


@pytest.mark.parametrize("kind", list(SHAPE_FUNCTIONS))
def test_partition_of_unity_and_linear_reproduction(kind):
    rng = np.random.default_rng(1)
    code = SHAPE_FUNCTIONS[kind]
    s = stencil_width(code)
    h, origin = 0.3, np.array([-1.0, 2.0])
    x = origin + 2 * h + rng.random((500, 2)) * 5 * h
    base = np.empty((500, 2), dtype=np.int64)
    N = np.empty((500, s * s))
    dN = np.empty((500, s * s, 2))
    compute_stencils(x, origin, h, code, base, N, dN)
    pos = _stencil_positions(base, s, h, origin)
    assert np.allclose(N.sum(axis=1), 1.0, atol=1e-14)
    assert np.allclose(dN.sum(axis=1), 0.0, atol=1e-12)
    assert np.all(N >= 0.0)
    # Σ N_I x_I = x and Σ x_I ⊗ ∇N_I = I
    assert np.allclose(np.einsum("pk,pkj->pj", N, pos), x, atol=1e-12)
    assert np.allclose(np.einsum("pki,pkj->pij", pos, dN), np.eye(2), atol=1e-12)


@pytest.mark.parametrize("kind", list(SHAPE_FUNCTIONS))
def test_gradient_matches_finite_difference(kind):
    code = SHAPE_FUNCTIONS[kind]
    s = stencil_width(code)
    h, origin = 0.5, np.zeros(2)
    x = np.array([[1.37, 2.21]])
    eps = 1e-7
    base = np.empty((1, 2), dtype=np.int64)
    N = np.empty((1, s * s))
    dN = np.empty((1, s * s, 2))
    compute_stencils(x, origin, h, code, base, N, dN)
    for j in range(2):
        xp = x.copy()
        xp[0, j] += eps
        bp = np.empty_like(base)
        Np = np.empty_like(N)
        compute_stencils(xp, origin, h, code, bp, Np, np.empty_like(dN))
        assert np.array_equal(bp, base)
        assert np.allclose((Np - N) / eps, dN[:, :, j], atol=1e-5)


@pytest.mark.parametrize("d", [2, 3])
def test_node_positions_of_a_box_and_of_some_of_its_nodes(d):
    """Lattice.node_positions: node (i_0, …) of a box at node_origin + h (lower + i), local
    order axis 0 fastest (np.meshgrid's 'ij' grid raveled in Fortran order), and for
    chosen local nodes exactly those rows."""
    from softgrains.grid.lattice import Lattice, NodeBox

    lattice = Lattice.covering(np.full(d, -0.3), np.full(d, 1.0), 0.07)
    box = NodeBox(np.arange(2, 2 + d), np.arange(3, 3 + d))
    axes = [lattice.node_origin[j] + lattice.h * (box.lower[j] + np.arange(box.shape[j]))
            for j in range(d)]
    grid = np.stack([m.ravel(order="F") for m in np.meshgrid(*axes, indexing="ij")], axis=1)
    every = lattice.node_positions(box)
    np.testing.assert_array_equal(every, grid)
    some = np.array([box.size - 1, 0, 5, 5])
    np.testing.assert_array_equal(lattice.node_positions(box, some), grid[some])

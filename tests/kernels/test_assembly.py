"""Internal force and consistent tangent (ALGORITHM.md §3): f = −∂W/∂u, K = −∂f/∂u by finite
differences."""

import numpy as np
import pytest
import scipy.sparse as sp

from softgrains.integrator.assembly import (
    block_pattern,
    dimension,
    gather_forces,
    gather_tangent,
    node_point_map,
    pair_codes,
    point_stresses,
    start_strain_energy,
)
from softgrains.materials import lame_parameters

TWO_D = dimension(2)


@pytest.mark.parametrize("kind", [0, 1], ids=["linear", "bspline2"])
@pytest.mark.parametrize("law", [0, 1], ids=["neo-hookean", "linear-elastic"])
def test_tangent_and_force_are_derivatives_of_energy(small_body, kind, law):
    rng = np.random.default_rng(3)
    lat, x, v0, box, nodes, N, dN, s = small_body(kind)
    n = len(x)
    lam, mu = lame_parameters(1.0e6, 0.3)
    F_n = np.eye(2) + 0.05 * rng.standard_normal((n, 2, 2))
    vol_n = v0 * np.linalg.det(F_n)
    laws = np.full(n, law, dtype=np.int64)
    lams, mus = np.full(n, lam), np.full(n, mu)
    active_row = np.full(box.size, -1, dtype=np.int64)
    touched = np.unique(nodes)
    active_row[touched] = np.arange(touched.size)
    u = np.zeros((box.size, 2))
    u[touched] = 0.01 * lat.h * rng.standard_normal((touched.size, 2))
    Pv = np.empty((n, 2, 2))
    Av = np.empty((n, 2, 2, 2, 2))
    ptr, entries = node_point_map(nodes, active_row, touched.size)

    def force(u):
        point_stresses(nodes, dN, u, F_n, vol_n, laws, lams, mus, Pv, Av, False, 4, False,
                       False, TWO_D)
        f = np.empty((touched.size, 2))
        gather_forces(ptr, entries, dN, Pv, f)
        return f.ravel()

    def energy(u):
        return point_stresses(nodes, dN, u, F_n, vol_n, laws, lams, mus, Pv, Av, False, 4,
                              False, False, TWO_D)[1]

    point_stresses(nodes, dN, u, F_n, vol_n, laws, lams, mus, Pv, Av, True, 4, False, False,
                   TWO_D)
    indptr, indices, slot, _ = block_pattern(active_row, box.shape, s)
    data = np.empty((indices.size, 2, 2))
    gather_tangent(ptr, entries, dN, Av, slot, pair_codes(s, 2), data)
    K = sp.bsr_matrix((data, indices, indptr), shape=(2 * touched.size,) * 2).toarray()
    eps = 1e-7 * lat.h
    cols = rng.choice(2 * touched.size, 12, replace=False)
    for c in cols:
        du = np.zeros(2 * touched.size)
        du[c] = eps
        up, um = u.copy(), u.copy()
        up[touched] += du.reshape(-1, 2)
        um[touched] -= du.reshape(-1, 2)
        fd = -(force(up) - force(um)) / (2 * eps)
        assert np.allclose(fd, K[:, c], rtol=1e-5, atol=1e-6 * np.abs(K).max())
        # f^int = −∂W/∂u: the line search's potential is consistent with the residual
        f0 = force(u)
        dW = (energy(up) - energy(um)) / (2 * eps)
        assert dW == pytest.approx(-f0[c], rel=1e-5, abs=1e-7 * np.abs(f0).max())
    if law == 0:
        assert np.allclose(K, K.T, atol=1e-9 * np.abs(K).max())


@pytest.mark.parametrize("d", [2, 3])
def test_tangent_gather_matches_the_sum_over_points_in_2d_and_3d(d):
    """K_(I,i)(J,k) = Σ_p ∇N_I,a (V Ã_p)_iakb ∇N_J,b for random tangents on random stencils
    (box of 4^d nodes, s = 2, first axis fastest), against np.einsum: the gather's loops
    over the dimension are compiled for d = 2 and 3 separately (a literal d)."""
    rng = np.random.default_rng(7 + d)
    s, shape = 2, np.full(d, 4, np.int64)
    n_box, ns = int(np.prod(shape)), s**d
    base = rng.integers(0, 3, size=(9, d))
    offsets = np.array([[(k // s**j) % s for j in range(d)] for k in range(ns)])
    strides = np.cumprod(np.r_[1, shape[:-1]])
    nodes = ((base[:, None, :] + offsets[None]) * strides).sum(axis=2).astype(np.int64)
    dN = rng.standard_normal((len(base), ns, d))
    Av = rng.standard_normal((len(base), d, d, d, d))
    active_row = np.arange(n_box, dtype=np.int64)
    ptr, entries = node_point_map(nodes, active_row, n_box)
    indptr, indices, slot, _ = block_pattern(active_row, shape, s)
    data = np.empty((indices.size, d, d))
    gather_tangent(ptr, entries, dN, Av, slot, pair_codes(s, d), data)
    K = sp.bsr_matrix((data, indices, indptr), shape=(d * n_box,) * 2).toarray()
    expected = np.zeros((n_box, d, n_box, d))
    blocks = np.einsum("pxa,piakb,pyb->pxiyk", dN, Av, dN)
    for p in range(len(base)):
        expected[np.ix_(nodes[p], range(d), nodes[p], range(d))] += blocks[p]
    assert np.allclose(K, expected.reshape(d * n_box, d * n_box), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("chunks", [1, 4, 100])
def test_start_strain_energy_is_the_stress_kernels_energy_at_rest(small_body, chunks):
    """start_strain_energy (a θ = 1 step's start: no f^int(0)) is point_stresses' energy
    at u = 0 to the last bit (its serial twin's: the parallel one may sum the chunks in
    another order), for both laws and any chunking, an inverted point left out."""
    rng = np.random.default_rng(5)
    lat, x, v0, box, nodes, N, dN, s = small_body(1)
    n = len(x)
    lam, mu = lame_parameters(1.0e6, 0.3)
    F_n = np.eye(2) + 0.1 * rng.standard_normal((n, 2, 2))
    vol_n = v0 * np.linalg.det(F_n)
    F_n[3] = [[1.0, 0.0], [0.0, -0.5]]  # an inverted point: left out by both
    laws = rng.integers(0, 2, n).astype(np.int64)
    lams, mus = np.full(n, lam), np.full(n, mu)
    _, energy = point_stresses.serial(nodes, dN, np.zeros((box.size, 2)), F_n, vol_n, laws, lams,
                                      mus, np.empty((n, 2, 2)), np.empty((n, 2, 2, 2, 2)),
                                      False, chunks, False, False, TWO_D)
    assert energy > 0.0
    assert start_strain_energy(F_n, vol_n, laws, lams, mus, chunks) == energy


def test_internal_force_of_uniform_stress_sums_to_zero(small_body):
    """Σ_I f_I = −Σ_p V_p σ_p Σ_I ∇N_I = 0: internal forces cannot move the centre of mass."""
    rng = np.random.default_rng(4)
    lat, x, v0, box, nodes, N, dN, s = small_body(0)
    n = len(x)
    lam, mu = lame_parameters(1.0e6, 0.3)
    F_n = np.eye(2) + 0.1 * rng.standard_normal((n, 2, 2))
    Pv = np.empty((n, 2, 2))
    point_stresses(nodes, dN, np.zeros((box.size, 2)), F_n, v0 * np.linalg.det(F_n),
                   np.zeros(n, dtype=np.int64), np.full(n, lam), np.full(n, mu), Pv,
                   np.empty((n, 2, 2, 2, 2)), False, 4, False, False, TWO_D)
    active_row = np.arange(box.size)
    ptr, entries = node_point_map(nodes, active_row, box.size)
    f = np.empty((box.size, 2))
    gather_forces(ptr, entries, dN, Pv, f)
    assert np.abs(f.sum(axis=0)).max() < 1e-10 * np.abs(f).max()

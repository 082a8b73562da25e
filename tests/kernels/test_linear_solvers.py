"""The bodies' Newton solves (integrator/linear_solvers.py): the dense LU used for small
bodies gives what SuperLU gives, for one right-hand side and for many (the contact
compliance [A⁻¹]_cc), and fails the way SuperLU does on a singular matrix."""

import numpy as np
import pytest
import scipy.sparse as sp

from softgrains.integrator import linear_solvers
from softgrains.integrator.linear_solvers import DenseLU, LinearSolver, factorize


def _stiffness_like(n, seed=0):
    """A sparse, nonsymmetric, well-conditioned n × n matrix (a banded Laplacian plus a
    random perturbation of its pattern)."""
    rng = np.random.default_rng(seed)
    A = sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(n, n)).tolil()
    for _ in range(3 * n):
        i, j = rng.integers(0, n, 2)
        A[i, j] += 0.1 * rng.standard_normal()
    return sp.bsr_matrix(A.tocsr())


@pytest.mark.parametrize("n", [40, 2 * linear_solvers.DENSE_LIMIT])
def test_the_factorization_solves_one_and_many_right_hand_sides(n):
    A = _stiffness_like(n)
    lu = factorize(A)
    assert isinstance(lu, DenseLU) == (n <= linear_solvers.DENSE_LIMIT)
    rng = np.random.default_rng(1)
    b, B = rng.standard_normal(n), rng.standard_normal((n, 7))
    dense = A.toarray()
    assert np.allclose(dense @ lu.solve(b), b, atol=1e-10)
    assert np.allclose(dense @ lu.solve(B), B, atol=1e-10)
    solver = LinearSolver("direct")
    x = solver.solve(A, b, np.zeros(0, np.int64))
    assert np.allclose(dense @ x, b, atol=1e-10) and solver.last_factorization is not None


def test_a_singular_matrix_fails_like_superlu():
    """A zero row: SuperLU raises RuntimeError ("exactly singular"), which a body's Newton
    turns into a SimulationError with its diagnosis; the dense LU must do the same rather
    than return Inf/NaN."""
    A = _stiffness_like(30).tolil()
    A[5, :] = 0.0
    A = sp.csr_matrix(A)
    with pytest.raises(RuntimeError):
        DenseLU(A)

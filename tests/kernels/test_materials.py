"""Constitutive laws: P = ∂W/∂F and A = ∂P/∂F by finite differences; σ and its plane-strain zz."""

import numpy as np
import pytest

from softgrains.materials import cauchy_stress, lame_parameters, pk1_and_tangent, strain_energy

LAWS = {"neo-hookean": 0, "linear-elastic": 1}


def _scratch():
    return np.empty((2, 2)), np.empty((2, 2, 2, 2)), np.empty((2, 2))


F0 = np.array([[1.12, 0.23], [-0.17, 0.91]])


@pytest.mark.parametrize("law", LAWS.values(), ids=LAWS.keys())
def test_stress_is_energy_derivative_and_tangent_is_stress_derivative(law):
    lam, mu = lame_parameters(2.0e6, 0.35)
    P = np.empty((2, 2))
    A = np.empty((2, 2, 2, 2))
    pk1_and_tangent(law, F0, lam, mu, P, A, np.empty((2, 2)))
    eps = 1e-6
    for k in range(2):
        for b in range(2):
            dF = np.zeros((2, 2))
            dF[k, b] = eps
            Wp = strain_energy(law, F0 + dF, lam, mu)
            Wm = strain_energy(law, F0 - dF, lam, mu)
            assert (Wp - Wm) / (2 * eps) == pytest.approx(P[k, b], rel=1e-6, abs=1e-3)
            Pp = np.empty((2, 2))
            Pm = np.empty((2, 2))
            pk1_and_tangent(law, F0 + dF, lam, mu, Pp, np.empty((2, 2, 2, 2)), np.empty((2, 2)))
            pk1_and_tangent(law, F0 - dF, lam, mu, Pm, np.empty((2, 2, 2, 2)), np.empty((2, 2)))
            assert np.allclose((Pp - Pm) / (2 * eps), A[:, :, k, b], rtol=1e-6, atol=1e-2)


def test_neo_hookean_cauchy_stress_kirchhoff_form():
    """σ = [μ(b − I) + λ ln J I]/J, σ_zz = λ ln J / J (plane strain, b_zz = 1)."""
    lam, mu = lame_parameters(1.0e6, 0.3)
    sigma = np.empty((3, 3))
    cauchy_stress(0, F0, lam, mu, sigma, *_scratch())
    J = np.linalg.det(F0)
    b = F0 @ F0.T
    expected = (mu * (b - np.eye(2)) + lam * np.log(J) * np.eye(2)) / J
    assert np.allclose(sigma[:2, :2], expected, rtol=1e-12)
    assert sigma[2, 2] == pytest.approx(lam * np.log(J) / J, rel=1e-12)
    assert sigma[0, 2] == sigma[1, 2] == 0.0


def test_linear_elastic_plane_strain_zz():
    lam, mu = lame_parameters(1.0e6, 0.3)
    sigma = np.empty((3, 3))
    F = np.eye(2) + np.array([[1e-3, 2e-4], [2e-4, -5e-4]])
    cauchy_stress(1, F, lam, mu, sigma, *_scratch())
    assert sigma[2, 2] == pytest.approx(0.3 * (sigma[0, 0] + sigma[1, 1]), rel=1e-12)


def test_rotation_gives_no_neo_hookean_stress():
    lam, mu = lame_parameters(1.0e6, 0.3)
    c, s = np.cos(0.9), np.sin(0.9)
    sigma = np.empty((3, 3))
    cauchy_stress(0, np.array([[c, -s], [s, c]]), lam, mu, sigma, *_scratch())
    assert np.abs(sigma).max() < 1e-9 * mu

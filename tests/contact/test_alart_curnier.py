"""The Alart–Curnier function and its generalized Jacobian (contact/alart_curnier.py)
against their definitions: Φ contact by contact, G by central differences of Φ."""

import numpy as np
import pytest

from softgrains.contact.alart_curnier import linearise


def random_contacts(rng, n, d):
    r = rng.normal(size=(n, d))
    u = rng.normal(size=(n, d))
    bias = rng.normal(scale=0.3, size=n)
    mu = rng.uniform(0.0, 0.8, n)
    rho = rng.uniform(0.5, 2.0, n)
    movable = rng.uniform(size=n) > 0.2
    threshold = rng.uniform(0.0, 1.0, n)
    return r, u, bias, mu, rho, movable, threshold


def phi_by_definition(r, u, bias, mu, rho, movable, threshold):
    """Φ_n = r_n − max(0, λ_n), Φ_t = r_t − proj of λ_t on the ball of radius
    μ max(0, λ_n) (Coulomb, threshold None) or the threshold (Tresca); at a contact no body
    moves (movable false) Φ_n = r_n and Φ_t = r_t."""
    phi = np.empty_like(r)
    for c in range(r.shape[0]):
        lam_n = r[c, 0] - rho[c] * (u[c, 0] + bias[c])
        lam_t = r[c, 1:] - rho[c] * u[c, 1:]
        if not movable[c]:
            phi[c] = r[c]
            continue
        phi[c, 0] = r[c, 0] - max(lam_n, 0.0)
        radius = mu[c] * max(lam_n, 0.0) if threshold is None else threshold[c]
        norm = np.linalg.norm(lam_t)
        phi[c, 1:] = r[c, 1:] - (lam_t if norm <= radius else radius * lam_t / norm)
    return phi


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("law", ["coulomb", "tresca"])
def test_phi_is_the_alart_curnier_function(d, law):
    rng = np.random.default_rng(3 + d)
    r, u, bias, mu, rho, movable, threshold = random_contacts(rng, 200, d)
    threshold = threshold if law == "tresca" else None
    lin = linearise(r, u, bias, mu, rho, movable, threshold)
    np.testing.assert_allclose(lin.phi, phi_by_definition(r, u, bias, mu, rho, movable,
                                                          threshold), rtol=1e-13, atol=1e-15)
    # every case of the law occurs: open, pressed and sticking, pressed and sliding
    lam_n = r[:, 0] - rho * (u[:, 0] + bias)
    pressed = movable & (lam_n > 0.0)
    assert (~pressed & movable).any() and pressed.any()
    assert (pressed & (lin.G[:, 1, 1] == 1.0)).any() and (pressed & (lin.G[:, 1, 1] < 1.0)).any()


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("law", ["coulomb", "tresca"])
def test_G_is_the_derivative_of_the_projections(d, law):
    """With u fixed, ∂Φ/∂r = I − G (λ moves with r one for one): central differences of Φ
    at random points (none on a kink of the projections, which have measure zero)."""
    rng = np.random.default_rng(9 + d)
    r, u, bias, mu, rho, movable, threshold = random_contacts(rng, 100, d)
    threshold = threshold if law == "tresca" else None
    G = linearise(r, u, bias, mu, rho, movable, threshold).G
    step = 1e-7
    for j in range(d):
        e = np.zeros((1, d))
        e[0, j] = step
        ahead = linearise(r + e, u, bias, mu, rho, movable, threshold).phi
        behind = linearise(r - e, u, bias, mu, rho, movable, threshold).phi
        derivative = (ahead - behind) / (2.0 * step)
        expected = np.eye(d)[j] - G[:, :, j]
        np.testing.assert_allclose(derivative, expected, atol=1e-6)

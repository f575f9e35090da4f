"""The modified Archimedes law (seed Eq. 27-29, Kang et al. 2018) in grainscale.theory."""

import math

import numpy as np
import pytest

from grainscale.theory.archimedes import PHI_MAX_DEG, _k_phi, k_phi, phi_for_k

# docs/validation.md, section 3: K_phi at phi (deg), printed to one decimal.
PUBLISHED = [(20.0, 10.3), (25.0, 20.1), (26.8, 26.0), (30.0, 41.9), (35.0, 94.4)]


@pytest.mark.parametrize(("phi", "k"), PUBLISHED)
def test_published_values(phi, k):
    # The values are printed rounded to 0.1: a correct K_phi rounds to them, i.e. lies
    # within half a unit of the last printed digit (0.05). Anything looser would let a
    # wrong reading pass (at 26.8 deg the printed Eq. 29c with R = 0.5 m is 1.5 away).
    assert k_phi(phi) == pytest.approx(k, abs=0.05)


def test_zero_friction_is_archimedes():
    # phi = 0: A = 1, int_0^1 eta d eta = 1/2, K = 2 * 1/2 = 1 (p = rho g d).
    assert k_phi(0.0) == pytest.approx(1.0, rel=1e-13)


def test_independent_of_radius():
    base = k_phi(26.8)
    for radius in (0.01, 0.25, 0.5, 2.0, 7.0):
        assert _k_phi(26.8, radius=radius) == pytest.approx(base, rel=1e-13)
        assert _k_phi(33.0, radius=radius) == pytest.approx(k_phi(33.0), rel=1e-13)


def test_printed_eq_29c_differs_when_radius_is_not_one():
    # Eq. 29c as printed (r2 = R (1 + R (1 - eta)/tan beta ...)) coincides with the
    # corrected one at R = 1 only; a reintroduced typo shows at the seed's R = 0.5 m.
    assert _k_phi(26.8, radius=1.0, printed_29c=True) == pytest.approx(k_phi(26.8), rel=1e-13)
    assert abs(_k_phi(26.8, radius=0.5, printed_29c=True) - k_phi(26.8)) > 1.0
    assert abs(_k_phi(26.8, radius=2.0, printed_29c=True) - k_phi(26.8)) > 1.0


def test_monotone_in_phi():
    ks = np.array([k_phi(p) for p in np.linspace(0.0, PHI_MAX_DEG, 121)])
    assert np.all(np.diff(ks) > 0)


def test_quadrature_converged():
    for phi in (0.0, 10.0, 20.0, 26.8, 35.0, 45.0, 60.0):
        assert _k_phi(phi, n_eta=128, n_psi=128) == pytest.approx(k_phi(phi), rel=1e-12)


def _k_plain(phi_deg, n=400):
    """A second, unmapped evaluation (plain Gauss-Legendre in eta and psi, Eq. 28 taken
    literally as a product): slow to converge at small eta but independent of the
    module's substitutions."""
    phi = math.radians(phi_deg)
    beta = math.pi / 4 - phi / 2
    x, w = np.polynomial.legendre.leggauss(n)
    eta, w_eta = (x + 1) / 2, w / 2
    psi, w_psi = math.pi / 4 * (x + 1), math.pi / 4 * w
    e, p = eta[:, None], psi[None, :]
    ex = np.exp(p * math.tan(phi))
    z = np.sum(w_psi * (e - 1) * ex * np.cos(p + beta) / (
        math.cos(phi) * (math.sin(beta) + (1 - e) * ex * np.sin(p - beta))), axis=1)
    tb2 = math.tan(beta) ** 2
    spread = math.exp(math.pi / 2 * math.tan(phi)) / math.tan(beta)
    r1, r2, r3 = 1 + 2 * (1 - eta) * spread, 1 + (1 - eta) * spread, eta
    a = (r1 ** (1 + tb2) / (r2 ** tb2 * r3)) ** math.sin(phi) \
        * np.exp(math.sin(phi) * math.tan(beta) * z)
    s = math.sin(phi)
    return 2 * (1 + s) / (1 - s) * math.exp(math.pi * math.tan(phi)) * np.sum(w_eta * eta * a)


@pytest.mark.parametrize("phi", [20.0, 26.8, 35.0])
def test_agrees_with_unmapped_quadrature(phi):
    assert _k_plain(phi) == pytest.approx(k_phi(phi), rel=1e-8)


@pytest.mark.parametrize("phi", [0.5, 12.0, 20.0, 26.8, 30.0, 35.0, 44.4, 59.0])
def test_inverse_round_trip(phi):
    assert phi_for_k(k_phi(phi)) == pytest.approx(phi, abs=1e-8)


def test_inverse_of_seed_slope():
    # The seed's fitted 23.024 implies 25.95 deg, inside its measured 26.8 +- 1.5 deg.
    phi = phi_for_k(23.024)
    assert k_phi(phi) == pytest.approx(23.024, rel=1e-10)
    assert 25.3 < phi < 28.3
    assert phi_for_k(1.0) == 0.0


def test_out_of_range():
    with pytest.raises(ValueError, match="friction angle"):
        k_phi(-1.0)
    with pytest.raises(ValueError, match="friction angle"):
        k_phi(75.0)
    with pytest.raises(ValueError, match="K_phi"):
        phi_for_k(0.5)
    with pytest.raises(ValueError, match="K_phi"):
        phi_for_k(1e7)

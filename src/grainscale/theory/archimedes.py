"""The modified Archimedes law (Kang et al. 2018, Nature Communications 9:1101; seed
Eq. 27-29): the slope K_phi of the steady intrusion regime

    p_u / (rho g R) = K_phi d / R + p_0

as a function of the friction (repose) angle phi of the intruded granular medium alone,
whatever the intruder's cross-section:

    K_phi = 2 (1 + sin phi) / (1 - sin phi) e^{pi tan phi} int_0^1 eta A(eta, phi) d eta   (27)

    A(eta, phi) = ( r1^{1 + tan^2 beta} / (r2^{tan^2 beta} r3) )^{sin phi}
                  e^{sin phi tan beta Z(eta, phi)}                                       (28)

    beta = pi/4 - phi/2                                                                  (29a)
    r1 = R (1 + 2 (1 - eta) / tan beta e^{(pi/2) tan phi})                               (29b)
    r2 = R (1 + (1 - eta) / tan beta e^{(pi/2) tan phi})                                 (29c)
    r3 = R eta                                                                           (29d)
    Z(eta, phi) = int_0^{pi/2} (eta - 1) e^{psi tan phi} cos(psi + beta)
                  / (cos phi [sin beta + (1 - eta) e^{psi tan phi} sin(psi - beta)]) d psi  (29e)

Eq. 29c as printed in the seed reads r2 = R (1 + R (1 - eta) / tan beta ...): the inner R
is a typo (it makes A depend on the intruder size, and the bracket adds a length to a
number); without it r1, r2 and r3 all scale with R and the exponents of Eq. 28 sum to
zero (1 + tan^2 beta - tan^2 beta - 1), so A, and K_phi, are dimensionless and independent
of R. This reading gives K_phi = 10.3, 20.1, 26.0, 41.9, 94.4 at phi = 20, 25, 26.8, 30,
35 degrees (docs/validation.md) and K_phi = 1 at phi = 0 (Archimedes' buoyancy: the
pressure at depth d is rho g d).

Quadrature (numpy Gauss-Legendre; scipy is not a dependency of the project):

- Z: at small eta the denominator of Eq. 29e nearly vanishes at psi = 0 (it equals
  eta sin beta there and grows like (1 - eta) psi sin beta / cos phi), a near-pole at
  psi ~ -c with c = eta cos phi / (1 - eta). The substitution psi = e^s - c removes it
  (d psi = (psi + c) ds), and Gauss-Legendre in s converges exponentially; c is capped
  at 1 where the pole is far (eta near 1), which keeps the map harmless.
- eta: as eta -> 0, r3 = R eta -> 0 and r3^{-sin phi} diverges like eta^{-sin phi}, but
  Z ~ -ln(1/eta) cos beta / cos(beta + phi) and cos(beta + phi) = sin beta, so the
  exponential factor goes like eta^{+sin phi} and A tends to a finite limit: eta A -> 0 and
  the integrand is bounded. A is evaluated through its logarithm so the two factors
  cancel without overflow. The endpoint still slows Gauss-Legendre in eta to an
  algebraic rate (about n^-6 in the nodes, found by trial); in u = sqrt(eta) (eta = u^2,
  d eta = 2 u du) it converges exponentially (32 nodes agree with 512 to 1e-15 relative
  at 26.8 deg). Nodes are interior, so eta = 0 itself is never evaluated.

With the default 64 x 64 nodes K_phi agrees with 128 x 128 nodes to better than 1e-12
relative for 0 <= phi <= 60 degrees (tests/test_archimedes.py).
"""

from __future__ import annotations

import math

import numpy as np

PHI_MAX_DEG = 60.0  # beyond this K_phi > 6e4 and the default quadrature loses digits
N_ETA = 64
N_PSI = 64


def _k_phi(phi_deg: float, radius: float = 1.0, printed_29c: bool = False,
           n_eta: int = N_ETA, n_psi: int = N_PSI) -> float:
    """Eq. 27 with an explicit intruder radius R (m). printed_29c=True uses Eq. 29c as
    printed, r2 = R (1 + R (1 - eta) / tan beta e^{(pi/2) tan phi}), which depends on R;
    the default is the corrected, R-free reading."""
    phi = math.radians(phi_deg)
    s, t, cphi = math.sin(phi), math.tan(phi), math.cos(phi)
    beta = math.pi / 4.0 - phi / 2.0
    tb = math.tan(beta)
    spread = math.exp(0.5 * math.pi * t)

    x, w = np.polynomial.legendre.leggauss(n_eta)
    u = 0.5 * (x + 1.0)
    eta = u * u                                    # eta = u^2 on (0, 1)
    w_eta = 0.5 * w * 2.0 * u                      # d eta = 2 u du, du = dx / 2

    # Z(eta, phi), Eq. 29e: psi = e^s - c over s in [ln c, ln(pi/2 + c)].
    xp, wp = np.polynomial.legendre.leggauss(n_psi)
    e = eta[:, None]
    c = np.minimum(e * cphi / (1.0 - e), 1.0)
    lo, hi = np.log(c), np.log(0.5 * math.pi + c)
    sv = 0.5 * (hi - lo) * xp[None, :] + 0.5 * (hi + lo)
    psi = np.exp(sv) - c
    w_psi = 0.5 * (hi - lo) * wp[None, :] * np.exp(sv)
    grow = (1.0 - e) * np.exp(psi * t)
    f = -grow * np.cos(psi + beta) / (cphi * (math.sin(beta) + grow * np.sin(psi - beta)))
    z = np.sum(f * w_psi, axis=1)

    big_r = radius if printed_29c else 1.0
    r1 = radius * (1.0 + 2.0 * (1.0 - eta) / tb * spread)            # 29b
    r2 = radius * (1.0 + big_r * (1.0 - eta) / tb * spread)          # 29c
    r3 = radius * eta                                                # 29d
    log_a = s * ((1.0 + tb * tb) * np.log(r1) - tb * tb * np.log(r2) - np.log(r3)) \
        + s * tb * z                                                 # 28
    integral = float(np.sum(w_eta * eta * np.exp(log_a)))
    return 2.0 * (1.0 + s) / (1.0 - s) * math.exp(math.pi * t) * integral  # 27


def _check_phi(phi_deg: float) -> float:
    phi_deg = float(phi_deg)
    if not 0.0 <= phi_deg <= PHI_MAX_DEG:
        raise ValueError(f"friction angle {phi_deg} deg outside [0, {PHI_MAX_DEG}] deg")
    return phi_deg


def k_phi(phi_deg: float) -> float:
    """K_phi (dimensionless) of the modified Archimedes law, seed Eq. 27-29 (Kang et al.
    2018, Eq. 29c without the printed inner R), for a friction angle phi in degrees,
    0 <= phi <= 60. K_phi(0) = 1; K_phi(26.8) = 26.02; increasing in phi."""
    return _k_phi(_check_phi(phi_deg))


def phi_for_k(k: float, tol_deg: float = 1e-10) -> float:
    """The friction angle (degrees) at which k_phi equals k (dimensionless, 1 <= k <=
    k_phi(60)): the angle a measured steady slope implies. Bisection on the monotone
    k_phi, to tol_deg."""
    k = float(k)
    lo, hi = 0.0, PHI_MAX_DEG
    k_hi = k_phi(hi)
    if not 1.0 <= k <= k_hi:
        raise ValueError(f"K_phi = {k} outside [1, {k_hi:.6g}] (phi in [0, {hi}] deg)")
    if k == 1.0:
        return 0.0
    # Regula falsi on ln K (nearly linear in phi), Illinois-modified, bracket kept.
    g_lo, g_hi = -math.log(k), math.log(k_hi / k)
    side = 0
    for _ in range(200):
        mid = hi - g_hi * (hi - lo) / (g_hi - g_lo)
        if not lo < mid < hi:
            mid = 0.5 * (lo + hi)
        g = math.log(k_phi(mid) / k)
        if g == 0.0:
            return mid
        if g < 0.0:
            lo, g_lo = mid, g
            if side == -1:
                g_hi *= 0.5
            side = -1
        else:
            hi, g_hi = mid, g
            if side == 1:
                g_lo *= 0.5
            side = 1
        if hi - lo < tol_deg:
            break
    else:  # pragma: no cover (Illinois converges superlinearly)
        raise RuntimeError(f"phi_for_k({k}) did not converge: [{lo}, {hi}]")
    return 0.5 * (lo + hi)

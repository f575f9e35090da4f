"""mu(I) rheology of dense granular flow (Jop, Forterre & Pouliquen 2006, Nature 441:727),
integrated as in the MPM of Dunatunga & Kamrin 2015 (JFM 779:483): an elastic predictor,
no tension, and a rate-dependent return at constant pressure. The phenomenological
baseline that multiscale (DEM RVE) runs are compared against.

Conventions (compression positive, tension-positive Cauchy stress sigma inside the code):

    p     = -tr(sigma)/3                     Pa, pressure
    s     = sigma + p I                      Pa, stress deviator
    tau   = sqrt(s:s / 2)                    Pa, equivalent shear stress (= q / sqrt 3)
    gdot  = sqrt(2 D':D')                    1/s, equivalent shear rate, D' = dev sym(L)

Both are normalised on simple shear: v_x = gdot z gives D'_xz = D'_zx = gdot/2, so
sqrt(2 D':D') = gdot; a stress whose only deviator is s_xz = s_zx = tau gives
sqrt(s:s/2) = tau. The flow rule is

    tau = mu(I) p   while flowing,  I = gdot_p d sqrt(rho_s / p),
    mu(I) = mu_s + (mu_2 - mu_s) / (I_0 / I + 1),

d the grain diameter (m), rho_s the grains' solid density (kg/m^3), gdot_p the plastic
shear rate; below tau = mu_s p there is no flow.

Step (Hughes-Winget rotation and isotropic Hooke as in the other laws): the trial stress
sigma_tr = R sigma R^T + lambda tr(de) I + 2 G de, de = sym(dH), with p_tr and tau_tr.

- p_tr <= 0: the grains separate; sigma = 0 (no tension, no cohesion). How they touch
  again is the `separation` setting:
  - "reset" (default): on the first compression; the stress grows from zero by Hooke's
    law, the material keeps no memory of how far it opened;
  - "recompact": only once the volume opened while separated is closed again. The point
    keeps the opening, phi = -p_tr/K at separation (K = lam + 2G/3; the volumetric strain
    beyond zero pressure), plus tr(de) of every step while phi > 0, and carries zero
    stress until phi <= 0; the compression left in that step, phi, then loads it from
    zero stress. This is Dunatunga & Kamrin's disconnected state (stress-free below a
    critical density, here the density at which the point separated), and what a packing
    of grains does: a dilated packing carries nothing until it is compacted back to
    contact.
- tau_tr <= mu_s p_tr: elastic, sigma = sigma_tr.
- otherwise plastic flow along s_tr/tau_tr at constant pressure (no dilatancy):
  D_p = (gdot_p / 2) s / tau, which lowers tau by G dt gdot_p. With
  xi = I_0 sqrt(p/rho_s)/d (so I_0/I = xi/gdot_p), S0 = mu_s p, S2 = mu_2 p, a = G dt,
  tau_tr - a gdot_p = S0 + (S2 - S0) gdot_p / (gdot_p + xi) is the quadratic

      a gdot_p^2 - b gdot_p - c = 0,   b = tau_tr - a xi - S2,   c = (tau_tr - S0) xi > 0,

  whose one positive root is taken in the cancellation-free form
  (b + sqrt(b^2 + 4ac)) / (2a) for b > 0, 2c / (sqrt(b^2 + 4ac) - b) otherwise
  (backward Euler: unconditionally stable; steady simple shear at rate gdot gives
  tau = mu(I(gdot)) p for any step, up to O((tau/G)^2) from the rotation). The deviator
  is scaled by tau/tau_tr, tau = p mu(I).
- dt = 0 (no time passes): no plastic flow can happen, and no rate can be measured; the
  stress is only capped at tau = mu_2 p, the largest ratio any rate supports (the limit of
  the step above as dt -> 0 at a fixed increment), and I keeps its last value. A
  zero step (dH = 0) therefore leaves a flowing point's stress as it was.

State per point: `plastic_strain`, sum gdot_p dt (-), `inertial_number`, I of the
last step (-, 0 where the point did not flow or separated), and with "recompact"
`opening`, phi (-, 0 where the grains touch).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from grainscale.mpm.materials.base import (
    PlasticState,
    add_elastic,
    lame,
    rotate_objective,
)
from grainscale.mpm.parallel import CHUNK, parallel_for


@njit(cache=True, fastmath=True, nogil=True)
def _mu_i_task(t, nt, dH, dt, stress, eps_p, inertial, opening, recompact, lam, G, mu_s,
               mu_2, I_0, d, rho_s):
    P = stress.shape[0]
    nchunks = (P + CHUNK - 1) // CHUNK
    a = G * dt
    K = lam + 2.0 * G / 3.0
    for c in range(t, nchunks, nt):
        A = np.empty((3, 3))
        B = np.empty((3, 3))
        s = np.empty((3, 3))
        de = np.empty((3, 3))
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            for i in range(3):
                for j in range(3):
                    de[i, j] = dH[p, i, j]
            if recompact and opening[p] > 0.0:
                ev = de[0, 0] + de[1, 1] + de[2, 2]
                opening[p] += ev
                if opening[p] > 0.0:  # still open: nothing to carry
                    for i in range(3):
                        for j in range(3):
                            stress[p, i, j] = 0.0
                    inertial[p] = 0.0
                    continue
                # closed in this step: only the compression beyond contact loads it
                for i in range(3):
                    de[i, i] -= (ev - opening[p]) / 3.0
                opening[p] = 0.0
            rotate_objective(de, stress[p], s, A, B)
            add_elastic(de, lam, G, s)
            pm = -(s[0, 0] + s[1, 1] + s[2, 2]) / 3.0
            if pm <= 0.0:
                # separated grains carry nothing
                for i in range(3):
                    for j in range(3):
                        stress[p, i, j] = 0.0
                inertial[p] = 0.0
                if recompact:
                    opening[p] = -pm / K
                continue
            for i in range(3):
                s[i, i] += pm  # s is now the deviator
            ss = 0.0
            for i in range(3):
                for j in range(3):
                    ss += s[i, j] * s[i, j]
            tau_tr = math.sqrt(0.5 * ss)
            S0 = mu_s * pm
            scale = 1.0
            if tau_tr <= S0:
                inertial[p] = 0.0
            else:
                S2 = mu_2 * pm
                if a > 0.0:
                    xi = I_0 * math.sqrt(pm / rho_s) / d  # 1/s: gdot_p at I = I_0
                    b = tau_tr - a * xi - S2
                    cc = (tau_tr - S0) * xi
                    root = math.sqrt(b * b + 4.0 * a * cc)
                    if b > 0.0:
                        g = (b + root) / (2.0 * a)
                    else:
                        g = 2.0 * cc / (root - b)
                    # p mu(I) rather than tau_tr - a g: no cancellation when tau_tr >> tau
                    tau = S0 + (S2 - S0) * g / (g + xi)
                    inertial[p] = I_0 * g / xi
                    eps_p[p] += g * dt
                else:
                    tau = min(tau_tr, S2)
                scale = tau / tau_tr
            for i in range(3):
                for j in range(3):
                    stress[p, i, j] = s[i, j] * scale
                stress[p, i, i] -= pm


def mu_i_kernel(dH, dt, stress, eps_p, inertial, opening, recompact, lam, G, mu_s, mu_2,
                I_0, d, rho_s):
    parallel_for(_mu_i_task, dH, float(dt), stress, eps_p, inertial, opening,
                 bool(recompact), lam, G, mu_s, mu_2, I_0, d, rho_s)


class MuI(PlasticState):
    """mu(I) rheology: bulk density (kg/m^3), E (Pa) and nu of the elastic predictor,
    mu_s, mu_2 (> mu_s), I_0 (> 0), grain diameter d (m), grain density rho_s (kg/m^3),
    and how separated grains touch again, `separation` "reset" or "recompact"."""

    def __init__(self, name: str, n_points: int, *, density: float, youngs_modulus: float,
                 poisson_ratio: float, mu_s: float, mu_2: float, I_0: float,
                 grain_diameter: float, grain_density: float, separation: str = "reset"):
        if separation not in ("reset", "recompact"):
            raise ValueError(f"separation = {separation!r}: valid 'reset', 'recompact'")
        self.name = name
        self.density = density
        self.E = youngs_modulus
        self.nu = poisson_ratio
        self.lam, self.G = lame(self.E, self.nu)
        self.mu_s, self.mu_2, self.I_0 = mu_s, mu_2, I_0
        self.d = grain_diameter
        self.rho_s = grain_density
        self.recompact = separation == "recompact"
        self.eps_p = np.zeros(n_points)
        self.inertial = np.zeros(n_points)
        self.opening = np.zeros(n_points)

    def update(self, dH: np.ndarray, dt: float, stress: np.ndarray) -> None:
        mu_i_kernel(dH, dt, stress, self.eps_p, self.inertial, self.opening, self.recompact,
                    self.lam, self.G, self.mu_s, self.mu_2, self.I_0, self.d, self.rho_s)

    def _own(self) -> dict[str, np.ndarray]:
        return {"inertial_number": self.inertial,
                **({"opening": self.opening} if self.recompact else {})}

    def state(self) -> dict[str, np.ndarray]:
        return {**super().state(), **self._own()}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        super().load_state(state)
        self.inertial[:] = state["inertial_number"]
        if self.recompact:
            self.opening[:] = state["opening"]

    def point_fields(self) -> dict[str, np.ndarray]:
        return {**super().point_fields(), **self._own()}

"""Nonlocal granular fluidity (NGF): mu(I) with a cooperativity length, the grain-size
effect a local rheology lacks (Kamrin & Koval 2012, PRL 108:178301; Henann & Kamrin 2013,
PNAS 110:6730; dynamic form: Henann & Kamrin 2014, IJP 60:145; thin layers on inclines,
the stopping height h_stop: Kamrin & Henann 2015, Soft Matter 11:179).

The plastic shear rate is carried by a field, the granular fluidity g (1/s):

    gdot_p = g mu,    mu = tau / p    (tau, p, gdot as in mu_i.py)

and g obeys the dynamic NGF equation, a reaction-diffusion equation

    t_0 dg/dt = A^2 d^2 lap(g) + (mu - mu_s) g - c(mu, p) g^2,
    c = mu (mu_2 - mu)_+ d sqrt(rho_s / p) / I_0,

A the nonlocal amplitude (-), d the grain diameter (m), t_0 a time scale (s). Without
the Laplacian the steady state is g = r / c with r = mu - mu_s: gdot = I sqrt(p/rho_s)/d
with I = I_0 (mu - mu_s) / (mu_2 - mu), which is Jop's mu(I) of mu_i.py exactly (Henann &
Kamrin write the source with the linearised law mu_s + b I, b = (mu_2 - mu_s)/I_0, equal
to this one as mu -> mu_s). So homogeneous steady flows are those of `mu_i`; the
Laplacian lets flow spread into, and be suppressed by, its surroundings over the
cooperativity length xi = A d / sqrt|mu - mu_s|. On a rough base (g = 0) a layer of
uniform mu > mu_s flows only if it is thicker than

    h_stop = pi A d / (2 sqrt(mu - mu_s))

(the lowest mode sin(pi z / 2h) of the linearised equation, zero at the base and flat at
the free surface, grows only then: Kamrin & Henann 2015), the arrest of thin layers
(Pouliquen 1999) that no local law has.

Step of one point (the elastic predictor, rotation and no-tension rule of mu_i.py): the
trial deviator relaxes at constant pressure with the point's fluidity, backward Euler in
the stress: tau = tau_tr / (1 + G dt g / p) (from tau = tau_tr - G dt gdot_p,
gdot_p = g tau / p), the deviator scaled by tau / tau_tr. The fluidity itself advances
on the grid before the stress update (mpm/fluidity.py), with these rules:
- g = 0 is a solution of the equation everywhere: where mu > mu_s the fluidity is kept at
  least g_seed = SEED sqrt(p / rho_s) / d, so that a flow the nonlocal term allows can
  start (it grows from there at the rate (mu - mu_s) / t_0); below h_stop the layer
  creeps at that rate, an inertial number of SEED mu, against 1e-3-0.1 where it flows;
- a separated point (p <= 0) has no stress ratio: it takes part in the diffusion only.

State per point: `fluidity` g (1/s), besides those of mu_i.py (`plastic_strain`,
`inertial_number` I = gdot_p d sqrt(rho_s / p), and `opening` with "recompact").
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from grainscale.mpm.materials.base import add_elastic, rotate_objective
from grainscale.mpm.materials.mu_i import MuI
from grainscale.mpm.parallel import CHUNK, parallel_for

SEED = 1e-4  # g_seed d / sqrt(p / rho_s): the least fluidity where mu > mu_s


@njit(cache=True, fastmath=True, inline="always")
def trial_deviator(p, dH, stress, opening, recompact, lam, G, K, de, s, A, B):
    """mu_i.py's elastic predictor and no-tension rule for point p (that kernel keeps its
    own inline copy: its results are pinned to the last bit by its tests, and moving the
    code into a shared helper changes the rounding): returns the trial pressure pm (Pa)
    and leaves the trial deviator in s; pm <= 0 where the grains are apart, the point's
    stress then already zero."""
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
            return 0.0
        for i in range(3):  # closed in this step: only the compression beyond contact
            de[i, i] -= (ev - opening[p]) / 3.0
        opening[p] = 0.0
    rotate_objective(de, stress[p], s, A, B)
    add_elastic(de, lam, G, s)
    pm = -(s[0, 0] + s[1, 1] + s[2, 2]) / 3.0
    if pm <= 0.0:  # separated grains carry nothing
        for i in range(3):
            for j in range(3):
                stress[p, i, j] = 0.0
        if recompact:
            opening[p] = -pm / K
        return pm
    for i in range(3):
        s[i, i] += pm  # s is now the deviator
    return pm


@njit(cache=True, fastmath=True, inline="always")
def shear_stress(s):
    """tau = sqrt(s:s / 2) of a deviator s (Pa)."""
    ss = 0.0
    for i in range(3):
        for j in range(3):
            ss += s[i, j] * s[i, j]
    return math.sqrt(0.5 * ss)


@njit(cache=True, fastmath=True, nogil=True)
def _relax_task(t, nt, dH, dt, stress, eps_p, inertial, opening, recompact, fluidity, lam,
                G, d, rho_s):
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
            pm = trial_deviator(p, dH, stress, opening, recompact, lam, G, K, de, s, A, B)
            if pm <= 0.0:
                inertial[p] = 0.0
                continue
            g = fluidity[p]
            scale = 1.0 / (1.0 + a * g / pm)
            rate = g * shear_stress(s) * scale / pm  # plastic shear rate g mu, 1/s
            eps_p[p] += rate * dt
            root_p = math.sqrt(pm / rho_s)  # m/s; 0 if pm/rho_s underflows
            inertial[p] = rate * d / root_p if root_p > 0.0 else 0.0
            for i in range(3):
                for j in range(3):
                    stress[p, i, j] = s[i, j] * scale
                stress[p, i, i] -= pm


class NonlocalMuI(MuI):
    """mu(I) with nonlocal granular fluidity: the parameters of MuI, plus the nonlocal
    amplitude A (-) and the fluidity's time scale t_0 (s). The step advances
    `fluidity` (1/s, per point) on the grid before each update (mpm/fluidity.py)."""

    def __init__(self, name: str, n_points: int, *, nonlocal_amplitude: float,
                 fluidity_time: float, **mu_i):
        super().__init__(name, n_points, **mu_i)
        self.A = nonlocal_amplitude
        self.t_0 = fluidity_time
        self.fluidity = np.zeros(n_points)

    def update(self, dH: np.ndarray, dt: float, stress: np.ndarray) -> None:
        parallel_for(_relax_task, dH, float(dt), stress, self.eps_p, self.inertial,
                     self.opening, self.recompact, self.fluidity, self.lam, self.G, self.d,
                     self.rho_s)

    def max_dt(self, h: float) -> float:
        """Largest step (s) of the explicit diffusion of g on cells of size h (m): the
        lumped linear-element Laplacian's largest eigenvalue on a cubic grid is 12/h^2,
        and forward Euler needs dt A^2 d^2 / t_0 * 12 / h^2 <= 2 (GIMP's wider
        weights only lower the eigenvalue)."""
        return self.t_0 * h * h / (6.0 * (self.A * self.d) ** 2)

    def _own(self) -> dict[str, np.ndarray]:
        return {**super()._own(), "fluidity": self.fluidity}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        super().load_state(state)
        self.fluidity[:] = state["fluidity"]

"""Drucker-Prager perfectly plastic material, non-associated flow, tension cut-off.

With p = -tr(sigma)/3 (compression positive) and q = sqrt(3/2 s:s):

    f = q - M p - k,     g = q - M_psi p,
    M = 6 sin(phi)/(3 - sin(phi)),  k = 6 c cos(phi)/(3 - sin(phi)),
    M_psi = 6 sin(psi)/(3 - sin(psi))

(the cone through the triaxial-compression corners of Mohr-Coulomb). Radial return:
dgamma = f_trial / (3 G + K M M_psi), q = q_tr - 3 G dgamma, p = p_tr + K M_psi dgamma;
beyond the apex (q < 0) the stress returns to the apex p = -k/M, s = 0. Tension cut-off:
p >= -T (T capped at the apex tension k/M).

State per point: `plastic_strain`, the accumulated plastic multiplier (-).
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
def _drucker_prager_task(t, nt, dH, stress, eps_p, K, G, M, Mpsi, k, tcut):
    P = stress.shape[0]
    nchunks = (P + CHUNK - 1) // CHUNK
    lam = K - 2.0 * G / 3.0
    for c in range(t, nchunks, nt):
        A = np.empty((3, 3))
        B = np.empty((3, 3))
        s = np.empty((3, 3))
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            rotate_objective(dH[p], stress[p], s, A, B)
            add_elastic(dH[p], lam, G, s)
            pm = -(s[0, 0] + s[1, 1] + s[2, 2]) / 3.0
            for i in range(3):
                s[i, i] += pm  # s is now the deviator
            J2 = 0.0
            for i in range(3):
                for j in range(3):
                    J2 += s[i, j] * s[i, j]
            q = math.sqrt(1.5 * J2)
            f = q - M * pm - k
            scale = 1.0
            if f > 1e-12 * (abs(q) + abs(pm) + abs(k) + 1e-300):
                dg = f / (3.0 * G + K * M * Mpsi)
                qn = q - 3.0 * G * dg
                pn = pm + K * Mpsi * dg
                if qn < 0.0 or (M > 0 and M * pn + k < 0.0):
                    # apex: no deviator left
                    pn = -k / M if M > 0 else pm
                    qn = 0.0
                scale = qn / q if q > 0 else 0.0
                pm = pn
                eps_p[p] += dg
            if pm < -tcut:
                pm = -tcut
                qmax = max(M * pm + k, 0.0)
                if q * scale > qmax:
                    scale = qmax / q if q > 0 else 0.0
            for i in range(3):
                for j in range(3):
                    stress[p, i, j] = s[i, j] * scale
                stress[p, i, i] -= pm


def drucker_prager_kernel(dH, stress, eps_p, K, G, M, Mpsi, k, tcut):
    parallel_for(_drucker_prager_task, dH, stress, eps_p, K, G, M, Mpsi, k, tcut)


class DruckerPrager(PlasticState):
    """Drucker-Prager matched to Mohr-Coulomb in triaxial compression: E (Pa), nu,
    friction and dilation angles (deg), cohesion c (Pa), tension cut-off T (Pa)."""

    def __init__(self, name: str, n_points: int, *, density: float, youngs_modulus: float,
                 poisson_ratio: float, friction_angle: float, dilation_angle: float = 0.0,
                 cohesion: float = 0.0, tension_cutoff: float = 0.0):
        self.name = name
        self.density = density
        self.E = youngs_modulus
        self.nu = poisson_ratio
        lam, self.G = lame(self.E, self.nu)
        self.K = lam + 2.0 * self.G / 3.0
        sphi = math.sin(math.radians(friction_angle))
        spsi = math.sin(math.radians(dilation_angle))
        self.M = 6 * sphi / (3 - sphi)
        self.Mpsi = 6 * spsi / (3 - spsi)
        self.k = 6 * cohesion * math.cos(math.radians(friction_angle)) / (3 - sphi)
        apex = self.k / self.M if self.M > 0 else math.inf
        self.tcut = min(tension_cutoff, apex)
        self.eps_p = np.zeros(n_points)

    def update(self, dH: np.ndarray, dt: float, stress: np.ndarray) -> None:
        drucker_prager_kernel(dH, stress, self.eps_p, self.K, self.G, self.M, self.Mpsi,
                              self.k, self.tcut)

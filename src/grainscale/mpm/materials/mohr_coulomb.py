"""Mohr-Coulomb perfectly plastic material, non-associated flow, tension cut-off.

Principal stresses (tension positive) s1 >= s2 >= s3. Yield function and plastic
potential of the active plane (s1, s3):

    f = (s1 - s3) + (s1 + s3) sin(phi) - 2 c cos(phi)
    g = (s1 - s3) + (s1 + s3) sin(psi)

Return mapping in principal space (elastic predictor in the rotated frame, then closest
return along C : dg/dsigma, Clausen et al. 2007): to the main plane; if the result
violates the ordering, to the edge s1 = s2 (triaxial compression) or s2 = s3 (triaxial
extension) with two multipliers; if those are negative or the ordering still fails, to
the apex s1 = s2 = s3 = c cot(phi). Finally principal stresses above the tension cut-off
T (<= c cot(phi)) are set to T (lowering s_i only lowers f, so the result stays
admissible). Eigenvectors of the trial stress are kept (isotropic elasticity).

State per point: `plastic_strain`, the accumulated plastic multiplier sum |dlambda| (-).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from grainscale.mpm.materials.base import (
    PlasticState,
    add_elastic,
    eig_sym3,
    from_principal,
    lame,
    rotate_objective,
)
from grainscale.mpm.parallel import CHUNK, parallel_for


@njit(cache=True, fastmath=True, inline="always")
def mc_return(s, lam, G, sphi, cphi, spsi, coh, tcut, out):
    """Return the principal trial stresses s (3,) (descending) onto the Mohr-Coulomb
    surface; writes out (3,) and returns the plastic multiplier sum (0 if elastic)."""
    apex = coh * cphi / sphi if sphi > 1e-12 else 1e300
    f1 = (s[0] - s[2]) + (s[0] + s[2]) * sphi - 2.0 * coh * cphi
    tol = 1e-12 * (abs(s[0]) + abs(s[2]) + coh + 1e-300)
    dl = 0.0
    for i in range(3):
        out[i] = s[i]
    if f1 > tol:
        k2 = lam + 2.0 * G
        # plane (1,3): a = (1+sphi, 0, -(1-sphi)), b = (1+spsi, 0, -(1-spsi))
        b1 = (1.0 + spsi, 0.0, -(1.0 - spsi))
        a1 = (1.0 + sphi, 0.0, -(1.0 - sphi))
        Cb1 = (k2 * b1[0] + lam * b1[2], lam * (b1[0] + b1[2]), lam * b1[0] + k2 * b1[2])
        aCb11 = a1[0] * Cb1[0] + a1[2] * Cb1[2]
        l1 = f1 / aCb11
        for i in range(3):
            out[i] = s[i] - l1 * Cb1[i]
        dl = l1
        if out[1] > out[0] or out[2] > out[1]:
            if out[1] > out[0]:
                # edge s1 = s2: second plane (2,3)
                a2 = (0.0, 1.0 + sphi, -(1.0 - sphi))
                b2 = (0.0, 1.0 + spsi, -(1.0 - spsi))
                f2 = (s[1] - s[2]) + (s[1] + s[2]) * sphi - 2.0 * coh * cphi
            else:
                # edge s2 = s3: second plane (1,2)
                a2 = (1.0 + sphi, -(1.0 - sphi), 0.0)
                b2 = (1.0 + spsi, -(1.0 - spsi), 0.0)
                f2 = (s[0] - s[1]) + (s[0] + s[1]) * sphi - 2.0 * coh * cphi
            Cb2 = (k2 * b2[0] + lam * (b2[1] + b2[2]),
                   k2 * b2[1] + lam * (b2[0] + b2[2]),
                   k2 * b2[2] + lam * (b2[0] + b2[1]))
            m11 = aCb11
            m12 = a1[0] * Cb2[0] + a1[1] * Cb2[1] + a1[2] * Cb2[2]
            m21 = a2[0] * Cb1[0] + a2[1] * Cb1[1] + a2[2] * Cb1[2]
            m22 = a2[0] * Cb2[0] + a2[1] * Cb2[1] + a2[2] * Cb2[2]
            det = m11 * m22 - m12 * m21
            la = (f1 * m22 - m12 * f2) / det
            lb = (m11 * f2 - m21 * f1) / det
            for i in range(3):
                out[i] = s[i] - la * Cb1[i] - lb * Cb2[i]
            dl = la + lb
            if la < 0.0 or lb < 0.0 or out[0] < out[2] - tol or out[0] > apex:
                for i in range(3):
                    out[i] = apex
                dl = abs(f1) / aCb11
    for i in range(3):
        if out[i] > tcut:
            out[i] = tcut
    return dl


@njit(cache=True, fastmath=True, nogil=True)
def _mohr_coulomb_task(t, nt, dH, stress, eps_p, lam, G, sphi, cphi, spsi, coh, tcut):
    P = stress.shape[0]
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in range(t, nchunks, nt):
        A = np.empty((3, 3))
        B = np.empty((3, 3))
        s = np.empty((3, 3))
        vals = np.empty(3)
        vecs = np.empty((3, 3))
        ret = np.empty(3)
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            rotate_objective(dH[p], stress[p], s, A, B)
            add_elastic(dH[p], lam, G, s)
            eig_sym3(s, vals, vecs)
            dl = mc_return(vals, lam, G, sphi, cphi, spsi, coh, tcut, ret)
            if dl > 0.0 or ret[0] != vals[0] or ret[1] != vals[1] or ret[2] != vals[2]:
                from_principal(ret, vecs, s)
                eps_p[p] += dl
            for i in range(3):
                for j in range(3):
                    stress[p, i, j] = s[i, j]


def mohr_coulomb_kernel(dH, stress, eps_p, lam, G, sphi, cphi, spsi, coh, tcut):
    parallel_for(_mohr_coulomb_task, dH, stress, eps_p, lam, G, sphi, cphi, spsi, coh, tcut)


class MohrCoulomb(PlasticState):
    """Mohr-Coulomb: E (Pa), nu, friction and dilation angles (deg), cohesion c (Pa),
    tension cut-off T (Pa, >= 0, capped at the apex c cot(phi))."""

    def __init__(self, name: str, n_points: int, *, density: float, youngs_modulus: float,
                 poisson_ratio: float, friction_angle: float, dilation_angle: float = 0.0,
                 cohesion: float = 0.0, tension_cutoff: float = 0.0):
        self.name = name
        self.density = density
        self.E = youngs_modulus
        self.nu = poisson_ratio
        self.lam, self.G = lame(self.E, self.nu)
        phi = math.radians(friction_angle)
        self.sphi, self.cphi = math.sin(phi), math.cos(phi)
        self.spsi = math.sin(math.radians(dilation_angle))
        self.coh = cohesion
        apex = cohesion * self.cphi / self.sphi if self.sphi > 0 else math.inf
        self.tcut = min(tension_cutoff, apex)
        self.eps_p = np.zeros(n_points)

    def update(self, dH: np.ndarray, dt: float, stress: np.ndarray) -> None:
        mohr_coulomb_kernel(dH, stress, self.eps_p, self.lam, self.G, self.sphi, self.cphi,
                            self.spsi, self.coh, self.tcut)

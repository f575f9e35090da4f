"""The material interface, and small numba helpers shared by the phenomenological laws.

Interface (the DEM RVE material of the coupling issue plugs into the same slot). A
material owns the points whose material index is its own, in the order they appear in
the point set, and keeps whatever per-point state it needs:

    update(dH, dt, stress) -> None
        dH     (P,3,3) float64, the full incremental displacement gradient of the step,
               dH[p, a, b] = d(Delta u_a)/d x_b = dt sum_I v_Ia dS_Ip/dx_b (seed Eq. 17),
               spin included (objective rates are the material's business);
        dt     float, s, the step (rate-dependent materials, DEM sub-stepping);
        stress (P,3,3) float64, Cauchy stress in Pa, tension positive: read as the stress
               at the start of the step, overwritten with the stress at its end.
    wave_speed() -> float        largest P-wave speed (m/s) for the CFL time step
    state() -> dict[str, ndarray]      per-point state arrays, leading axis P (checkpoints)
    load_state(dict) -> None           inverse of state()
    point_fields() -> dict[str, ndarray]   extra per-point output (VTK, history), (P,) or (P,k)

Stresses in reports use geomechanics signs: p = -tr(sigma)/3, q = sqrt(3/2 s:s).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numba import njit

from grainscale.linalg3 import inv3


class Material(Protocol):
    name: str
    density: float  # kg/m^3, initial density of the points that use it

    def update(self, dH: np.ndarray, dt: float, stress: np.ndarray) -> None: ...

    def wave_speed(self) -> float: ...

    def state(self) -> dict[str, np.ndarray]: ...

    def load_state(self, state: dict[str, np.ndarray]) -> None: ...

    def point_fields(self) -> dict[str, np.ndarray]: ...


class PlasticState:
    """State and outputs shared by the perfectly plastic laws: the accumulated plastic
    strain per point (`eps_p`), with elastic constants E, nu and density set by the law."""

    E: float
    nu: float
    density: float
    eps_p: np.ndarray

    def wave_speed(self) -> float:
        return p_wave_speed(self.E, self.nu, self.density)

    def state(self) -> dict[str, np.ndarray]:
        return {"plastic_strain": self.eps_p}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        self.eps_p[:] = state["plastic_strain"]

    def point_fields(self) -> dict[str, np.ndarray]:
        return {"plastic_strain": self.eps_p}


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lame constants (lambda, G) from Young's modulus E (Pa) and Poisson's ratio nu."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def p_wave_speed(E: float, nu: float, rho: float) -> float:
    """sqrt((K + 4G/3) / rho), m/s."""
    lam, G = lame(E, nu)
    return float(np.sqrt((lam + 2 * G) / rho))


@njit(cache=True, fastmath=True, inline="always")
def rotate_objective(dH, sig, out, A, B):
    """out = R sig R^T with the Hughes-Winget rotation R = (I - W/2)^-1 (I + W/2),
    W = (dH - dH^T)/2 the incremental spin. A, B are (3,3) scratch arrays."""
    w01 = 0.5 * (dH[0, 1] - dH[1, 0])
    w02 = 0.5 * (dH[0, 2] - dH[2, 0])
    w12 = 0.5 * (dH[1, 2] - dH[2, 1])
    # M = I - W/2 (W antisymmetric: W01 = w01, W10 = -w01, ...) in B, A = M^-1
    B[0, 0] = 1.0
    B[0, 1] = -0.5 * w01
    B[0, 2] = -0.5 * w02
    B[1, 0] = 0.5 * w01
    B[1, 1] = 1.0
    B[1, 2] = -0.5 * w12
    B[2, 0] = 0.5 * w02
    B[2, 1] = 0.5 * w12
    B[2, 2] = 1.0
    inv3(B, A)
    # R = A (I + W/2) stored in B
    for i in range(3):
        a0 = A[i, 0]
        a1 = A[i, 1]
        a2 = A[i, 2]
        B[i, 0] = a0 - a1 * 0.5 * w01 - a2 * 0.5 * w02
        B[i, 1] = a0 * 0.5 * w01 + a1 - a2 * 0.5 * w12
        B[i, 2] = a0 * 0.5 * w02 + a1 * 0.5 * w12 + a2
    # A = R sig ; out = A R^T
    for i in range(3):
        for j in range(3):
            A[i, j] = B[i, 0] * sig[0, j] + B[i, 1] * sig[1, j] + B[i, 2] * sig[2, j]
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[j, 0] + A[i, 1] * B[j, 1] + A[i, 2] * B[j, 2]


@njit(cache=True, fastmath=True, inline="always")
def add_elastic(dH, lam, G, sig):
    """sig += lam tr(de) I + 2 G de with de = sym(dH) (isotropic Hooke, increment form)."""
    tr = dH[0, 0] + dH[1, 1] + dH[2, 2]
    for i in range(3):
        for j in range(3):
            sig[i, j] += G * (dH[i, j] + dH[j, i])
        sig[i, i] += lam * tr


@njit(cache=True, fastmath=True, inline="always")
def eig_sym3(A, vals, vecs):
    """Eigen-decomposition of a symmetric 3x3 A by cyclic Jacobi rotations.

    vals (3,) sorted descending (largest = least compressive), vecs (3,3) columns are the
    eigenvectors. A is not modified.
    """
    a = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            a[i, j] = 0.5 * (A[i, j] + A[j, i])
            vecs[i, j] = 1.0 if i == j else 0.0
    scale = abs(a[0, 0]) + abs(a[1, 1]) + abs(a[2, 2]) + abs(a[0, 1]) + abs(a[0, 2]) + abs(a[1, 2])
    for _sweep in range(50):
        off = abs(a[0, 1]) + abs(a[0, 2]) + abs(a[1, 2])
        if off <= 1e-15 * scale or off == 0.0:
            break
        for p in range(2):
            for q in range(p + 1, 3):
                if a[p, q] == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * a[p, q])
                t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(3):
                    akp = a[k, p]
                    akq = a[k, q]
                    a[k, p] = c * akp - s * akq
                    a[k, q] = s * akp + c * akq
                for k in range(3):
                    apk = a[p, k]
                    aqk = a[q, k]
                    a[p, k] = c * apk - s * aqk
                    a[q, k] = s * apk + c * aqk
                for k in range(3):
                    vkp = vecs[k, p]
                    vkq = vecs[k, q]
                    vecs[k, p] = c * vkp - s * vkq
                    vecs[k, q] = s * vkp + c * vkq
    for i in range(3):
        vals[i] = a[i, i]
    # sort descending (3 elements: insertion sort, swapping eigenvector columns too)
    for i in range(1, 3):
        j = i
        while j > 0 and vals[j] > vals[j - 1]:
            tmp = vals[j]
            vals[j] = vals[j - 1]
            vals[j - 1] = tmp
            for k in range(3):
                tv = vecs[k, j]
                vecs[k, j] = vecs[k, j - 1]
                vecs[k, j - 1] = tv
            j -= 1


@njit(cache=True, fastmath=True, inline="always")
def from_principal(vals, vecs, out):
    """out = sum_i vals[i] n_i n_i^T."""
    for i in range(3):
        for j in range(3):
            out[i, j] = (vals[0] * vecs[i, 0] * vecs[j, 0] + vals[1] * vecs[i, 1] * vecs[j, 1]
                         + vals[2] * vecs[i, 2] * vecs[j, 2])

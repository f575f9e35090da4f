"""Linear elastic material (hypoelastic, objective Hughes-Winget update).

sigma_{n+1} = R sigma_n R^T + lambda tr(de) I + 2 G de,  de = sym(dH),
R = (I - W/2)^-1 (I + W/2), W = skew(dH): the Jaumann rate integrated with an exactly
orthogonal rotation, so a rigid rotation leaves the stress invariants unchanged.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from grainscale.mpm.materials.base import add_elastic, lame, p_wave_speed, rotate_objective
from grainscale.mpm.parallel import CHUNK, parallel_for


@njit(cache=True, fastmath=True, nogil=True)
def _elastic_task(t, nt, dH, stress, lam, G):
    P = stress.shape[0]
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in range(t, nchunks, nt):
        A = np.empty((3, 3))
        B = np.empty((3, 3))
        s = np.empty((3, 3))
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            rotate_objective(dH[p], stress[p], s, A, B)
            add_elastic(dH[p], lam, G, s)
            for i in range(3):
                for j in range(3):
                    stress[p, i, j] = s[i, j]


def elastic_kernel(dH, stress, lam, G):
    parallel_for(_elastic_task, dH, stress, lam, G)


class LinearElastic:
    """Isotropic linear elasticity: E (Pa), nu (-), density (kg/m^3)."""

    def __init__(self, name: str, n_points: int, *, density: float, youngs_modulus: float,
                 poisson_ratio: float):
        self.name = name
        self.density = density
        self.E = youngs_modulus
        self.nu = poisson_ratio
        self.lam, self.G = lame(self.E, self.nu)
        self.n = n_points

    def update(self, dH: np.ndarray, dt: float, stress: np.ndarray) -> None:
        elastic_kernel(dH, stress, self.lam, self.G)

    def wave_speed(self) -> float:
        return p_wave_speed(self.E, self.nu, self.density)

    def state(self) -> dict[str, np.ndarray]:
        return {}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        pass

    def point_fields(self) -> dict[str, np.ndarray]:
        return {}

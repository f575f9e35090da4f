"""Macroscopic quantities of RVEs (seed Eq. 11-15), in the project's conventions.

Internally stress is Cauchy, tension positive; reports use geomechanics signs:
p = -tr(sigma)/3 (compression positive), q = sqrt(3/2 s:s) with s = sigma + p I,
eps_v = ln(V/V0) (positive = dilation, seed Eq. 14).
"""

from __future__ import annotations

import numpy as np

from grainscale.dem.state import RVEBatch
from grainscale.stress import deviatoric_stress, mean_stress


def volumetric_strain(batch: RVEBatch) -> np.ndarray:
    """eps_v = ln(V/V0), positive = dilation (seed Eq. 14), (R,)."""
    return np.log(np.linalg.det(batch.h) / np.linalg.det(batch.h0))


def coordination(batch: RVEBatch) -> np.ndarray:
    """Mean number of contacts per grain 2 Nc / N, (R,) (a clump is one grain, however
    many of its members touch)."""
    return 2.0 * batch.ncontact / batch.n_bodies


def mean_rotation(batch: RVEBatch) -> np.ndarray:
    """theta = (1/N) sum theta_p (seed Eq. 15), theta_p = integral of |omega| dt [rad], (R,)."""
    return batch.rot.mean(axis=1)


def mean_spin(batch: RVEBatch) -> np.ndarray:
    """d theta / dt = mean |omega| over the particles [rad/s], (R,) (seed Fig. 15)."""
    return np.linalg.norm(batch.w, axis=2).mean(axis=1)


def summary(batch: RVEBatch) -> dict[str, np.ndarray]:
    """All reported scalars of every RVE: p, q, q/p, eps_v, porosity, coordination, ..."""
    p = mean_stress(batch.stress)
    q = deviatoric_stress(batch.stress)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(p > 0, q / p, 0.0)
    return {
        "p": p, "q": q, "q_over_p": ratio, "volumetric_strain": volumetric_strain(batch),
        "porosity": batch.porosity(), "coordination": coordination(batch),
        "sigma_xx": batch.stress[:, 0, 0], "sigma_yy": batch.stress[:, 1, 1],
        "sigma_zz": batch.stress[:, 2, 2], "mean_rotation": mean_rotation(batch),
        "mean_spin": mean_spin(batch), "unbalanced": batch.unbalanced.copy(),
    }

"""Stress invariants in report conventions, shared by both solvers.

Cauchy stress sigma (..., 3, 3), tension positive, as stored everywhere in the code;
reports use compression-positive p = -tr(sigma)/3 and q = sqrt(3/2 s:s) (seed Eq. 13),
s = sigma + p I the deviator.
"""

from __future__ import annotations

import numpy as np


def mean_stress(sigma: np.ndarray) -> np.ndarray:
    """p = -tr(sigma)/3 [Pa], compression positive; sigma (..., 3, 3)."""
    return -np.trace(sigma, axis1=-2, axis2=-1) / 3.0


def deviatoric_stress(sigma: np.ndarray) -> np.ndarray:
    """q = sqrt(3/2 s:s) [Pa] (seed Eq. 13), s the deviator of sigma."""
    s = sigma + mean_stress(sigma)[..., None, None] * np.eye(3)
    return np.sqrt(1.5 * np.einsum("...ab,...ab->...", s, s))


def p_q(sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p, q) of sigma [Pa]."""
    return mean_stress(sigma), deviatoric_stress(sigma)

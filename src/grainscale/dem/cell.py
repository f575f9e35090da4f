"""The periodic deformable cell as small pure functions over fractional coordinates.

The cell matrix `h` (3x3) has the three edge vectors as *columns*; a point with
fractional coordinates s in [0, 1)^3 sits at x = h s, and the cell volume is det h.
Deforming the cell with fractional coordinates held fixed moves every particle with the
mean field (affine motion); particles' own (fluctuating) motion changes s.

Minimum image: a branch vector h (s_j - s_i + k) with integer image shift k. Rounding the
fractional difference gives the minimum image only while every perpendicular cell width
exceeds twice the interaction range; the neighbour search therefore refuses cells thinner
than that (see `perpendicular_widths`), and a lattice reduction re-expresses a sheared
cell by a compact basis before that happens.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from grainscale.linalg3 import det3


@njit(cache=True)
def perpendicular_widths(h: np.ndarray) -> np.ndarray:
    """Distance between each pair of opposite faces [m]: w_k = det h / |a_i x a_j|."""
    out = np.empty(3)
    vol = abs(det3(h))
    for k in range(3):
        i = (k + 1) % 3
        j = (k + 2) % 3
        c0 = h[1, i] * h[2, j] - h[2, i] * h[1, j]
        c1 = h[2, i] * h[0, j] - h[0, i] * h[2, j]
        c2 = h[0, i] * h[1, j] - h[1, i] * h[0, j]
        out[k] = vol / np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    return out


@njit(cache=True)
def perpendicular_widths_batch(h: np.ndarray) -> np.ndarray:
    """(R,3) perpendicular widths of a batch of cells h (R,3,3) [m]."""
    out = np.empty((h.shape[0], 3))
    for r in range(h.shape[0]):
        out[r] = perpendicular_widths(h[r])
    return out


def lattice_reduce(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A compact basis of the same lattice: returns (h_new, M) with h_new = h M, M unimodular.

    Greedy pairwise reduction (3D Lagrange–Gauss): repeatedly subtract integer multiples of
    one edge from another while that shortens it. The periodic system is unchanged (same
    lattice), so contact history survives; fractional coordinates transform as
    s_new = M^-1 s (then wrap).
    """
    h = h.copy()
    m = np.eye(3, dtype=np.int64)
    for _ in range(100):
        changed = False
        for i in range(3):
            for j in range(3):
                if i == j:
                    continue
                q = np.dot(h[:, i], h[:, j]) / np.dot(h[:, j], h[:, j])
                k = int(np.round(q))
                if k != 0:
                    trial = h[:, i] - k * h[:, j]
                    if np.dot(trial, trial) < np.dot(h[:, i], h[:, i]) * (1 - 1e-12):
                        h[:, i] = trial
                        m[:, i] -= k * m[:, j]
                        changed = True
        if not changed:
            break
    if np.linalg.det(h) < 0:  # keep a right-handed basis
        h[:, 0] *= -1
        m[:, 0] *= -1
    return h, m

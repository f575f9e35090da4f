"""Shape functions: GIMP (default) and linear, batched over points in numba.

Both are tensor products of 1D functions. The 1D GIMP weight of a node at distance
r = x_p - x_I, for a point of half-width l_p in a cell of size h (Bardenhagen & Kober
2004, seed ref. 31, the "S_Ip" of seed Eq. 4-6 and 16-19):

    |r| < l_p            S = 1 - (r^2 + l_p^2) / (2 h l_p)
    l_p <= |r| < h - l_p S = 1 - |r| / h
    h - l_p <= |r| < h + l_p   S = (h + l_p - |r|)^2 / (4 h l_p)

With l_p = 0 the first and last branches are empty and GIMP is the linear hat function,
so one kernel serves both; only the stencil width differs (3 nodes per axis for GIMP,
2 for linear).

Layout: for point p and axis a, `base[p, a]` is the first node index of the stencil and
`w[p, a, k]`, `dw[p, a, k]` the 1D weight and derivative (1/m) of node `base[p, a] + k`.
A point whose support crosses the grid boundary has the weight of the missing nodes
folded onto the boundary node, so the partition of unity and sum(grad S) = 0 hold
everywhere inside the grid (the boundary node then stands for the wall).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from grainscale.mpm.grid import Grid
from grainscale.mpm.parallel import CHUNK, parallel_for
from grainscale.mpm.points import half_widths

GIMP = "GIMP"
LINEAR = "linear"


def stencil_width(kind: str) -> int:
    """Nodes per axis touched by one point: 3 for GIMP (l_p <= h/2), 2 for linear."""
    return 3 if kind == GIMP else 2


@njit(cache=True, fastmath=True, inline="always")
def _gimp_1d(r, h, lp):
    """1D GIMP weight and derivative d S / d x_p for r = x_p - x_I (linear when lp = 0)."""
    ar = abs(r)
    sgn = 1.0 if r >= 0.0 else -1.0
    if ar < lp:
        return 1.0 - (r * r + lp * lp) / (2.0 * h * lp), -r / (h * lp)
    if ar < h - lp:
        return 1.0 - ar / h, -sgn / h
    if ar < h + lp:
        d = h + lp - ar
        return d * d / (4.0 * h * lp), -sgn * d / (2.0 * h * lp)
    return 0.0, 0.0


@njit(cache=True, fastmath=True, inline="always")
def _evaluate_point(p, x, origin, h, cells, lp, ns, base, w, dw):
    for a in range(3):
        ha = h[a]
        l = lp[p, a] if ns == 3 else 0.0
        xi = (x[p, a] - origin[a]) / ha
        # first node whose support (|r| < h + l) can contain the point
        if ns == 2:
            i0 = int(np.floor(xi))
        else:
            i0 = int(np.floor(xi - 1.0 - l / ha)) + 1
        b = min(max(i0, 0), cells[a] + 1 - ns)
        base[p, a] = b
        for k in range(3):
            w[p, a, k] = 0.0
            dw[p, a, k] = 0.0
        for k in range(ns):
            i = i0 + k
            s, g = _gimp_1d(x[p, a] - (origin[a] + i * ha), ha, l)
            slot = min(max(i, 0), cells[a]) - b  # fold missing nodes onto the wall
            w[p, a, slot] += s
            dw[p, a, slot] += g


@njit(cache=True, fastmath=True, nogil=True)
def _evaluate_task(t, nt, x, origin, h, cells, lp, ns, base, w, dw):
    P = x.shape[0]
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            _evaluate_point(p, x, origin, h, cells, lp, ns, base, w, dw)


def evaluate_kernel(x, origin, h, cells, lp, ns, base, w, dw):
    """Fill base (P,3) int64, w and dw (P,3,3) for points x (P,3) with half-widths lp
    (P,3)."""
    parallel_for(_evaluate_task, x, origin, h, cells, lp, ns, base, w, dw)


def evaluate(x: np.ndarray, lp: np.ndarray, grid: Grid, kind: str = GIMP, out=None):
    """Shape functions of all points: returns (base, w, dw) as described above.

    `out` may pass preallocated (base, w, dw) arrays to fill (no allocation per step).
    """
    P = x.shape[0]
    if np.ndim(lp) < 2:  # one half-width per point: the same on every axis
        lp = half_widths(lp, P)
    if grid.axes is not None:  # rectilinear: a stencil as wide as the widest domain needs
        from grainscale.mpm import rectilinear

        return rectilinear.evaluate(x, lp, grid.axes, gimp=kind == GIMP, out=out)
    ns = stencil_width(kind)
    if out is None:
        out = (np.empty((P, 3), dtype=np.int64), np.empty((P, 3, 3)), np.empty((P, 3, 3)))
    base, w, dw = out
    evaluate_kernel(x, grid.origin, grid.cell_size, grid.cells, lp, ns, base, w, dw)
    return base, w, dw

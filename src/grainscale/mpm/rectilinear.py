"""Rectilinear (tensor-product) grids: node coordinates per axis, graded axes, and the
linear and GIMP shape functions on cells of unequal size (docs/mpm.md: graded grids;
Grid.rectilinear; the case file's [grid] nodes_x, nodes_y, nodes_z).

A rectilinear grid has, along each axis a, strictly increasing node coordinates
X_0 < X_1 < ... < X_n (ParaView's RectilinearGrid); cell c spans [X_c, X_c+1]. Node I's
linear hat N_I rises over its left cell (width h_L) and falls over its right one (h_R):

    N_I(x) = (x - X_I-1) / h_L  on [X_I-1, X_I],   (X_I+1 - x) / h_R  on [X_I, X_I+1].

The boundary nodes keep the value 1 outside the grid (the weight of the missing nodes
folded onto the wall, as on the uniform grid, mpm/shape.py). GIMP (Bardenhagen & Kober
2004, the S_Ip of seed Eq. 4-6) is the hat averaged over the point's domain
[x_p - l_p, x_p + l_p], whose half-width l_p (on this axis) is the point's own wherever
it goes:

    S_I(x_p) = (H_I(x_p + l_p) - H_I(x_p - l_p)) / (2 l_p),
    dS_I/dx_p = (N_I(x_p + l_p) - N_I(x_p - l_p)) / (2 l_p),

with H_I(x) = integral of N_I from X_I to x, piecewise quadratic and exact. Because the
hats sum to 1 and sum_I N_I X_I = x on the grid, S and its gradient keep the partition
of unity and linear completeness (sum S_I = 1, sum S_I X_I = x_p, sum dS_I = 0,
sum dS_I X_I = 1) on any grading; on a uniform grid this is the formula of mpm/shape.py.
A point's domain may span several small cells, so the stencil is as wide as the widest
domain needs (`stencil_width`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# the largest size ratio of neighbouring cells accepted on input: beyond it, a point
# filled in the larger cell (l_p = h / 2n) covers more than n / MAX_RATIO small cells,
# and the error of a gradient taken across the step grows with the ratio
MAX_RATIO = 2.0


def check_nodes(nodes, key: str) -> np.ndarray:
    """The node coordinates of one axis as float64, checked: at least 2, finite,
    strictly increasing, neighbouring cells within MAX_RATIO of each other. ValueError
    names `key`, the offending value and the valid range."""
    x = np.asarray(nodes, dtype=np.float64)
    if x.ndim != 1 or x.size < 2:
        raise ValueError(f"{key}: at least 2 node coordinates, got {np.size(nodes)}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{key}: coordinates must be finite numbers")
    h = np.diff(x)
    bad = np.flatnonzero(h <= 0)
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{key}[{i + 1}] = {float(x[i + 1])!r}: coordinates must increase "
                         f"strictly ({key}[{i}] = {float(x[i])!r})")
    ratio = np.maximum(h[1:] / h[:-1], h[:-1] / h[1:])
    bad = np.flatnonzero(ratio > MAX_RATIO * (1 + 1e-9))
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{key}: cells {i} and {i + 1} ({h[i]:.6g} m and {h[i + 1]:.6g} m) "
                         f"differ by a factor {ratio[i]:.4g}; valid: at most {MAX_RATIO:g} "
                         "between neighbouring cells")
    return x


def graded_axis(lo: float, hi: float, fine_lo: float, fine_hi: float, cell: float,
                ratio: float, max_cell: float | None = None) -> np.ndarray:
    """Node coordinates [m] from lo to hi: cells of size `cell` over [fine_lo, fine_hi]
    (a whole number of them), growing geometrically by `ratio` per cell away from it on
    each side, up to `max_cell`; the cells of each side are then scaled together so
    that they end exactly at lo and hi (never below `cell`). ValueError names the
    argument out of range."""
    if not lo <= fine_lo < fine_hi <= hi:
        raise ValueError(f"fine = [{fine_lo}, {fine_hi}]: must lie in [{lo}, {hi}] with "
                         "fine_lo < fine_hi")
    if not cell > 0:
        raise ValueError(f"cell = {cell}: must be > 0")
    if not 1.0 <= ratio <= MAX_RATIO:
        raise ValueError(f"ratio = {ratio}: valid 1 to {MAX_RATIO:g}")
    max_cell = math.inf if max_cell is None else max_cell
    if not max_cell >= cell:
        raise ValueError(f"max_cell = {max_cell}: must be >= cell = {cell}")
    n = (fine_hi - fine_lo) / cell
    if abs(n - round(n)) > 1e-6:
        raise ValueError(f"fine = [{fine_lo}, {fine_hi}]: its length {fine_hi - fine_lo:.6g} m "
                         f"is not a whole number of cells of {cell:g} m")
    fine = fine_lo + cell * np.arange(round(n) + 1)
    fine[-1] = fine_hi
    left = _side(fine_lo - lo, cell, ratio, max_cell)
    right = _side(hi - fine_hi, cell, ratio, max_cell)
    return np.concatenate([fine_lo - np.cumsum(left)[::-1], fine,
                           fine_hi + np.cumsum(right)])


def _side(length: float, cell: float, ratio: float, max_cell: float) -> np.ndarray:
    """Cell sizes filling `length` outward from a fine cell: geometric by `ratio`, capped
    at max_cell, the fewest cells that reach `length`, scaled to end on it; a remainder
    below one fine cell is spread over the cells instead (scaling up)."""
    if length <= 1e-12 * cell:
        return np.zeros(0)
    sizes, total, h = [], 0.0, cell
    while total < length * (1 - 1e-12):
        h = min(h * ratio, max_cell)
        sizes.append(h)
        total += h
    sizes = np.array(sizes)
    if sizes.size > 1 and total - length > sizes[-1] - cell:
        sizes = sizes[:-1]  # dropping the last cell and stretching the rest scales less
    return sizes * (length / sizes.sum())


def stencil_width(nodes: np.ndarray, lp_max: float) -> int:
    """Nodes per axis one point can touch: the most nodes a domain of half-width lp_max
    spans anywhere on the axis, plus the hats reaching into its end cells (2 for
    lp_max = 0, the linear hats)."""
    h_min = float(np.diff(nodes).min())
    return int(math.floor(2.0 * lp_max / h_min)) + 3 if lp_max > 0 else 2


@njit(cache=True, inline="always")
def _cell_of(nodes, x):
    """The cell whose span holds x, clamped to the grid's cells (binary search)."""
    n = nodes.shape[0] - 1
    if x <= nodes[0]:
        return 0
    if x >= nodes[n]:
        return n - 1
    lo, hi = 0, n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if nodes[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def _hat(nodes, i, x):
    """N_i(x) and dN_i/dx of node i, 1 outside the grid for the boundary nodes; at a
    node the slope of the cell to its right (as mpm/shape.py)."""
    n = nodes.shape[0] - 1
    xi = nodes[i]
    if x >= xi:
        if i == n:
            return 1.0, 0.0
        hr = nodes[i + 1] - xi
        if x >= nodes[i + 1]:
            return 0.0, 0.0
        return (nodes[i + 1] - x) / hr, -1.0 / hr
    if i == 0:
        return 1.0, 0.0
    hl = xi - nodes[i - 1]
    if x <= nodes[i - 1]:
        return 0.0, 0.0
    return (x - nodes[i - 1]) / hl, 1.0 / hl


@njit(cache=True, inline="always")
def _hat_integral(nodes, i, x):
    """H_i(x): the integral of N_i from X_i to x (exact; N_i = 1 beyond a boundary)."""
    n = nodes.shape[0] - 1
    xi = nodes[i]
    if x >= xi:
        if i == n:
            return x - xi
        hr = nodes[i + 1] - xi
        if x >= nodes[i + 1]:
            return 0.5 * hr
        d = nodes[i + 1] - x
        return 0.5 * hr - d * d / (2.0 * hr)
    if i == 0:
        return x - xi
    hl = xi - nodes[i - 1]
    if x <= nodes[i - 1]:
        return -0.5 * hl
    d = x - nodes[i - 1]
    return d * d / (2.0 * hl) - 0.5 * hl


@njit(cache=True)
def weights_1d(nodes, x, lp, ns, base, w, dw):
    """1D weights of points x (P,) with half-widths lp (P,) on the axis `nodes`:
    base[p] the first node of the stencil of `ns` nodes, w[p, k] and dw[p, k] (1/m) the
    weight and derivative of node base[p] + k. lp = 0: the linear hats."""
    n = nodes.shape[0] - 1
    for p in range(x.shape[0]):
        l = lp[p]
        c = _cell_of(nodes, x[p] - l)
        b = min(max(c, 0), n + 1 - ns)
        base[p] = b
        for k in range(ns):
            i = b + k
            if l > 0.0:
                s = (_hat_integral(nodes, i, x[p] + l) - _hat_integral(nodes, i, x[p] - l)) \
                    / (2.0 * l)
                g = (_hat(nodes, i, x[p] + l)[0] - _hat(nodes, i, x[p] - l)[0]) / (2.0 * l)
            else:
                s, g = _hat(nodes, i, x[p])
            w[p, k] = s
            dw[p, k] = g


def stencil(axes, lp_max, gimp: bool = True) -> int:
    """Nodes per axis of the stencil on the grid `axes` for half-widths up to lp_max (one
    value, or one per axis): the widest of the three axes', at most every node of the
    shortest axis."""
    l = np.broadcast_to(np.asarray(lp_max, dtype=np.float64) if gimp else 0.0, (3,))
    return min(max(stencil_width(np.asarray(a), float(l[i])) for i, a in enumerate(axes)),
               min(len(a) for a in axes))


def evaluate(x: np.ndarray, lp: np.ndarray, axes, gimp: bool = True, out=None):
    """Shape functions of points x (P,3) with half-widths lp (P,3) on the rectilinear grid
    of node coordinates `axes` (three arrays): (base (P,3) int64, w and dw (P,3,ns)),
    the layout of mpm/shape.py with ns nodes per axis; gimp=False: the linear hats.
    `out` may pass (base, w, dw) to fill, ns = w.shape[2] (at least `stencil`)."""
    P = x.shape[0]
    if np.ndim(lp) < 2:  # one half-width per point: the same on every axis
        from grainscale.mpm.points import half_widths

        lp = half_widths(lp, P)
    l = np.ascontiguousarray(lp if gimp else np.zeros((P, 3)), dtype=np.float64)
    if out is None:
        ns = stencil(axes, l.max(axis=0) if P else 0.0)
        out = (np.empty((P, 3), dtype=np.int64), np.empty((P, 3, ns)), np.empty((P, 3, ns)))
    base, w, dw = out
    for a in range(3):  # each axis written in place through strided views
        weights_1d(np.asarray(axes[a], dtype=np.float64), x[:, a], l[:, a], w.shape[2],
                   base[:, a], w[:, a], dw[:, a])
    return base, w, dw

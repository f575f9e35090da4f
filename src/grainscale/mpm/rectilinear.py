"""Shape functions on rectilinear (tensor-product, graded) grids: the linear and GIMP
weights on cells of unequal size (docs/mpm.md: graded grids). The grid's geometry (node
lists, graded_axis, the checks) is mpm/grid.py's.

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
sum dS_I X_I = 1) on any grading, provided the stencil holds every node whose hat
meets the domain; on a uniform grid this is the formula of mpm/shape.py. A point's
domain may span several small cells, so each axis' stencil is as wide as its points'
domains need where they are (`stencil`, per axis, taken anew every step).
"""

from __future__ import annotations

import numpy as np
from numba import njit


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
def stencil_1d(nodes, x, lp):
    """Nodes one axis' stencil needs for points x (P,) with half-widths lp (P,): the most
    nodes any point's domain [x - l, x + l] touches, from the left node of the cell
    holding x - l to the right node of the cell holding x + l (2: the linear hats)."""
    need = 2
    for p in range(x.shape[0]):
        c0 = _cell_of(nodes, x[p] - lp[p])
        c1 = _cell_of(nodes, x[p] + lp[p])
        need = max(need, c1 - c0 + 2)
    return need


@njit(cache=True)
def weights_1d(nodes, x, lp, ns, base, w, dw):
    """1D weights of points x (P,) with half-widths lp (P,) on the axis `nodes`:
    base[p] the first node of the stencil of `ns` nodes (at least stencil_1d's), w[p, k]
    and dw[p, k] (1/m) the weight and derivative of node base[p] + k; slots past ns are
    zeroed. lp = 0: the linear hats."""
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
        for k in range(ns, w.shape[1]):
            w[p, k] = 0.0
            dw[p, k] = 0.0


def stencil(x: np.ndarray, lp: np.ndarray, axes, gimp: bool = True) -> np.ndarray:
    """(3,) int64: the nodes per axis that the points x (P,3) with half-widths lp (P,3)
    need on the grid `axes` where they are now (gimp=False: the linear hats, 2). Each
    axis is sized by its own points and cells, so a coarse axis beside a fine one keeps
    a narrow stencil, and no axis is ever cut short of what a domain touches."""
    l = np.zeros_like(x) if not gimp else np.ascontiguousarray(lp, dtype=np.float64)
    return np.array([stencil_1d(np.asarray(axes[a], dtype=np.float64),
                                np.ascontiguousarray(x[:, a]), np.ascontiguousarray(l[:, a]))
                     for a in range(3)], dtype=np.int64)


def evaluate(x: np.ndarray, lp: np.ndarray, axes, gimp: bool = True, out=None, ns=None):
    """Shape functions of points x (P,3) with half-widths lp (P,3) on the rectilinear grid
    of node coordinates `axes` (three arrays): (base (P,3) int64, w and dw (P,3,slots)),
    the layout of mpm/shape.py with ns[a] nodes on axis a (`stencil`, unless given) and
    zeros in the slots past it; gimp=False: the linear hats. `out` may pass
    (base, w, dw) to fill, with at least max(ns) slots."""
    P = x.shape[0]
    if np.ndim(lp) < 2:  # one half-width per point: the same on every axis
        from grainscale.mpm.points import half_widths

        lp = half_widths(lp, P)
    l = np.ascontiguousarray(lp if gimp else np.zeros((P, 3)), dtype=np.float64)
    ns = stencil(x, l, axes) if ns is None else ns
    if out is None:
        slots = int(max(ns))
        out = (np.empty((P, 3), dtype=np.int64), np.empty((P, 3, slots)),
               np.empty((P, 3, slots)))
    base, w, dw = out
    if w.shape[2] < max(ns):
        raise ValueError(f"out: {w.shape[2]} slots per axis, the stencil needs {max(ns)}")
    for a in range(3):
        if not 2 <= ns[a] <= len(axes[a]):
            raise ValueError(f"ns[{a}] = {int(ns[a])}: valid 2 to the axis' {len(axes[a])} "
                             "nodes")
    for a in range(3):  # each axis written in place through strided views
        weights_1d(np.asarray(axes[a], dtype=np.float64), x[:, a], l[:, a], int(ns[a]),
                   base[:, a], w[:, a], dw[:, a])
    return base, w, dw

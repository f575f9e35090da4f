"""Cartesian background grid: uniform, or rectilinear (graded).

Nodes are numbered `I = i + nx * (j + ny * k)` with `nx, ny, nz = cells + 1`; node
(i, j, k) sits at `origin + (i, j, k) * cell_size` on a uniform grid, at
`(axes[0][i], axes[1][j], axes[2][k])` on a rectilinear one (mpm/rectilinear.py), whose
`cell_size` is then each axis' smallest cell (what the time step and the force bounds
need). The grid never moves (the "scratch pad" of seed §2.1); nodal arrays are rebuilt
every step.

Periodic axes: the material lives in [o, o + N h) along such an axis (o, N the case's
origin and cells; on a rectilinear grid, the span of its nodes) and leaves through one
end to re-enter at the other. The grid held here is that period padded by PAD cells at
each end (on a rectilinear grid, the images of as many cells from the other end as
span at least the axis' largest cell, twice the widest point domain's half-width), so every
stencil lies inside it and the kernels see an ordinary grid; `fold` sums each nodal
value with its periodic images and hands the sum back to all of them (after P2G), `wrap`
brings positions back into the period (after G2P).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

PAD = 2  # cells added at each end of a periodic axis (a GIMP stencil reaches 1.25 h)

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
    that they end exactly at lo and hi, never below `cell` (a side shorter than one
    cell is refused). ValueError names the argument out of range."""
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
    for end, gap in (("lo", fine_lo - lo), ("hi", hi - fine_hi)):
        # a side shorter than one fine cell could only end in a cell below `cell` (which
        # would set the CFL step): the fine region must reach the bound or leave a cell
        if 1e-12 * cell < gap < cell * (1 - 1e-9):
            bound = lo if end == "lo" else hi
            raise ValueError(
                f"fine = [{fine_lo}, {fine_hi}] ends {gap:.6g} m from {end} = {bound}, less "
                f"than one cell = {cell}: valid: fine_{end} = {end}, or at least one cell "
                f"({cell}) between them")
    left = _side(fine_lo - lo, cell, ratio, max_cell)
    right = _side(hi - fine_hi, cell, ratio, max_cell)
    return np.concatenate([fine_lo - np.cumsum(left)[::-1], fine,
                           fine_hi + np.cumsum(right)])


def _side(length: float, cell: float, ratio: float, max_cell: float) -> np.ndarray:
    """Cell sizes filling `length` outward from a fine cell: geometric by `ratio`, capped
    at max_cell, the fewest cells that reach `length`, scaled to end on it; a remainder
    below one fine cell is spread over the cells instead (scaling up); where neither
    keeps every cell within [cell, MAX_RATIO x its inner neighbour], equal cells."""
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
    sizes = sizes * (length / sizes.sum())
    steps = sizes / np.concatenate([[cell], sizes[:-1]])
    if sizes.min() < cell * (1 - 1e-9) or steps.max() > MAX_RATIO * (1 + 1e-9):
        # too short a side for the geometric cells to fit both limits (e.g. 2.25 cells at
        # ratio 2): equal cells of 1 to 2 fine cells instead
        n = max(1, int(np.floor(length / cell * (1 + 1e-12))))
        sizes = np.full(n, length / n)
    return sizes


def _cells_spanning(w: np.ndarray, length: float) -> int:
    """The fewest cells taken from each end of the period `w` (cyclically) whose widths
    add up to at least `length` at both ends."""
    N = len(w)
    k = 1
    while (w[(N - k + np.arange(k)) % N].sum() < length * (1 - 1e-12)
           or w[np.arange(k) % N].sum() < length * (1 - 1e-12)):
        k += 1
    return k


@dataclass(frozen=True)
class Grid:
    origin: np.ndarray  # (3,) m, position of node (0, 0, 0)
    cell_size: np.ndarray  # (3,) m, edge lengths of one cell
    cells: np.ndarray  # (3,) int64, number of cells per axis
    period: np.ndarray = None  # (3,) int64 cells of a periodic axis' period, 0 otherwise
    axes: tuple = None  # rectilinear: the node coordinates of each axis (3 arrays, m)
    pad: np.ndarray = None  # (3,) int64 image cells at each end of a periodic axis

    @classmethod
    def make(cls, origin, cell_size, cells, periodic=(False, False, False)) -> Grid:
        """The grid of `cells` from `origin`; periodic axes get PAD cells of padding."""
        h = np.broadcast_to(np.asarray(cell_size, dtype=np.float64), (3,)).copy()
        n = np.asarray(cells, dtype=np.int64).reshape(3).copy()
        if np.any(h <= 0):
            raise ValueError(f"cell size must be > 0, got {h.tolist()}")
        if np.any(n < 1):
            raise ValueError(f"cell counts must be >= 1, got {n.tolist()}")
        per = np.asarray(periodic, dtype=bool).reshape(3)
        o = np.asarray(origin, dtype=np.float64).reshape(3).copy()
        period = np.where(per, n, 0).astype(np.int64)
        return cls(o - PAD * h * per, h, n + 2 * PAD * per, period, None, PAD * per)

    @classmethod
    def rectilinear(cls, axes, periodic=(False, False, False)) -> Grid:
        """The grid of the node coordinates `axes` (x, y, z), each checked by
        check_nodes (ValueError naming nodes_x, nodes_y or nodes_z). A
        periodic axis' period is its nodes' span; it is padded at each end by the images
        of the cells at the other end, at least PAD of them and as many as span the axis'
        largest cell (a point's domain is at most half a cell wide on each side, so it
        never reaches past the padding), and its first and last cells, neighbours across
        the period's ends, must also be within MAX_RATIO of each other."""
        ax = [check_nodes(a, f"nodes_{'xyz'[i]}") for i, a in enumerate(axes)]
        per = np.asarray(periodic, dtype=bool).reshape(3)
        period = np.where(per, [len(a) - 1 for a in ax], 0).astype(np.int64)
        pad = np.zeros(3, dtype=np.int64)
        for i in np.flatnonzero(per):
            w = np.diff(ax[i])
            key = f"nodes_{'xyz'[i]}"
            if len(w) < PAD:
                raise ValueError(f"{key}: a periodic axis needs at least {PAD} cells, got "
                                 f"{len(w)}")
            if max(w[0] / w[-1], w[-1] / w[0]) > MAX_RATIO * (1 + 1e-9):
                raise ValueError(f"{key}: the first and last cells ({w[0]:.6g} m and "
                                 f"{w[-1]:.6g} m) meet across the periodic ends and differ "
                                 f"by a factor {max(w[0] / w[-1], w[-1] / w[0]):.4g}; valid: "
                                 f"at most {MAX_RATIO:g}")
            N = len(w)
            pad[i] = k = max(PAD, _cells_spanning(w, w.max()))
            left = w[(N - k + np.arange(k)) % N]  # the last k cells, cyclically
            right = w[np.arange(k) % N]
            ax[i] = np.concatenate([ax[i][0] - np.cumsum(left[::-1])[::-1], ax[i],
                                    ax[i][-1] + np.cumsum(right)])
        ax = tuple(ax)
        return cls(np.array([a[0] for a in ax]), np.array([np.diff(a).min() for a in ax]),
                   np.array([len(a) - 1 for a in ax], dtype=np.int64), period, ax, pad)

    @property
    def pads(self) -> np.ndarray:
        """(3,) int64 image cells at each end of each axis (0 where not periodic)."""
        return np.zeros(3, dtype=np.int64) if self.pad is None else self.pad

    def reach(self) -> np.ndarray:
        """(3,) m: how far past the period's ends a periodic axis' padding extends (the
        narrower end; inf where not periodic): a point's domain must stay within it."""
        out = np.full(3, np.inf)
        lo, hi = self.period_box()
        for a in np.flatnonzero(self.periodic):
            out[a] = min(lo[a] - self.origin[a], self.upper[a] - hi[a])
        return out

    @cached_property
    def node_table(self) -> np.ndarray:
        """(3, max nodes) m: row a holds axis a's node coordinates (rectilinear grids; the
        kernels' view of `axes`), zero-padded; built once."""
        table = np.zeros((3, int(self.nodes.max())))
        for a in range(3):
            table[a, :self.nodes[a]] = self.axes[a]
        return table

    @cached_property
    def node_volume(self) -> np.ndarray:
        """(n_nodes,) m^3: the volume of the largest cell beside each node (the product
        over axes of the larger of its two neighbouring cells; a grid end's node has
        one), on a rectilinear grid, where a mass threshold stated as a fraction of a
        point must follow the size of the points beside the node (points in a cell 8
        times larger are 8 times heavier)."""
        dual = []
        for a in self.node_axes():
            h = np.diff(a)
            dual.append(np.maximum(np.concatenate([h[:1], h]), np.concatenate([h, h[-1:]])))
        return (dual[2][:, None, None] * dual[1][None, :, None] * dual[0][None, None, :]).ravel()

    def cell_sizes_at(self, x: np.ndarray) -> np.ndarray:
        """(P,3) m: the edges of the grid cell holding each position x (P,3) (a position
        on a node counts in the cell above it; clamped to the grid)."""
        x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
        out = np.empty(x.shape)
        for a, X in enumerate(self.node_axes()):
            c = np.clip(np.searchsorted(X, x[:, a], side="right") - 1, 0, len(X) - 2)
            out[:, a] = np.diff(X)[c]
        return out

    @property
    def cell_max(self) -> np.ndarray:
        """(3,) m, each axis' largest cell."""
        if self.axes is None:
            return self.cell_size
        return np.array([np.diff(a).max() for a in self.axes])

    @property
    def periodic(self) -> np.ndarray:
        """(3,) bool: the periodic axes."""
        return np.zeros(3, dtype=bool) if self.period is None else self.period > 0

    def period_box(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the region the material may occupy: the period along periodic
        axes, the whole grid along the others."""
        lo, hi = self.origin.copy(), self.upper.copy()
        per = self.periodic
        if self.axes is not None:
            for a in np.flatnonzero(per):
                lo[a] = self.axes[a][self.pads[a]]
                hi[a] = self.axes[a][self.pads[a] + self.period[a]]
            return lo, hi
        lo[per] += PAD * self.cell_size[per]
        hi[per] = lo[per] + self.period[per] * self.cell_size[per]
        return lo, hi

    def wrap(self, x: np.ndarray) -> None:
        """Positions (P,3) brought back into the period along periodic axes, in place."""
        lo, hi = self.period_box()
        for a in np.flatnonzero(self.periodic):
            x[:, a] = lo[a] + np.mod(x[:, a] - lo[a], hi[a] - lo[a])

    def fold(self, a: np.ndarray) -> None:
        """Nodal array a (n_nodes, c) made periodic in place: every node gets the sum over
        itself and its periodic images (exact for the integer sums of the transfers)."""
        view = a.reshape(*self.nodes[::-1], a.shape[1])  # [k, j, i, c]
        for ax in np.flatnonzero(self.periodic):
            v = np.moveaxis(view, 2 - ax, 0)  # the periodic axis first
            N = int(self.period[ax])
            image = (np.arange(v.shape[0]) - self.pads[ax]) % N
            total = np.zeros((N, *v.shape[1:]), dtype=a.dtype)
            np.add.at(total, image, v)
            v[...] = total[image]

    @property
    def nodes(self) -> np.ndarray:
        """(3,) int64 node counts per axis."""
        return self.cells + 1

    @property
    def n_nodes(self) -> int:
        return int(np.prod(self.nodes))

    @property
    def upper(self) -> np.ndarray:
        """(3,) m, position of the last node."""
        if self.axes is not None:
            return np.array([a[-1] for a in self.axes])
        return self.origin + self.cells * self.cell_size

    def node_axes(self) -> list[np.ndarray]:
        """The node coordinates of each axis (3 arrays, m; a periodic axis' padding
        included)."""
        if self.axes is not None:
            return [np.asarray(a) for a in self.axes]
        return [self.origin[a] + np.arange(self.nodes[a]) * self.cell_size[a]
                for a in range(3)]

    def node_positions(self) -> np.ndarray:
        """(n_nodes, 3) positions, in node numbering order."""
        axes = self.node_axes()
        z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)

    def contains(self, x: np.ndarray) -> np.ndarray:
        """(P,) bool: point centres inside the closed grid box."""
        return np.all((x >= self.origin) & (x <= self.upper), axis=1)

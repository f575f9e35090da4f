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
each end (on a rectilinear grid, the images of the cells at the other end), so every
stencil lies inside it and the kernels see an ordinary grid; `fold` sums each nodal
value with its periodic images and hands the sum back to all of them (after P2G), `wrap`
brings positions back into the period (after G2P).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

PAD = 2  # cells added at each end of a periodic axis (a GIMP stencil reaches 1.25 h)


@dataclass(frozen=True)
class Grid:
    origin: np.ndarray  # (3,) m, position of node (0, 0, 0)
    cell_size: np.ndarray  # (3,) m, edge lengths of one cell
    cells: np.ndarray  # (3,) int64, number of cells per axis
    period: np.ndarray = None  # (3,) int64 cells of a periodic axis' period, 0 otherwise
    axes: tuple = None  # rectilinear: the node coordinates of each axis (3 arrays, m)

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
        return cls(o - PAD * h * per, h, n + 2 * PAD * per, period)

    @classmethod
    def rectilinear(cls, axes, periodic=(False, False, False)) -> Grid:
        """The grid of the node coordinates `axes` (x, y, z), each checked by
        rectilinear.check_nodes (ValueError naming nodes_x, nodes_y or nodes_z). A
        periodic axis' period is its nodes' span; it is padded by the images of PAD
        cells from its other end, and its first and last cells, neighbours across the
        period's ends, must also be within MAX_RATIO of each other."""
        from grainscale.mpm.rectilinear import MAX_RATIO, check_nodes

        ax = [check_nodes(a, f"nodes_{'xyz'[i]}") for i, a in enumerate(axes)]
        per = np.asarray(periodic, dtype=bool).reshape(3)
        period = np.where(per, [len(a) - 1 for a in ax], 0).astype(np.int64)
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
            ax[i] = np.concatenate([ax[i][0] - np.cumsum(w[::-1][:PAD])[::-1], ax[i],
                                    ax[i][-1] + np.cumsum(w[:PAD])])
        ax = tuple(ax)
        return cls(np.array([a[0] for a in ax]), np.array([np.diff(a).min() for a in ax]),
                   np.array([len(a) - 1 for a in ax], dtype=np.int64), period, ax)

    @cached_property
    def node_table(self) -> np.ndarray:
        """(3, max nodes) m: row a holds axis a's node coordinates (rectilinear grids; the
        kernels' view of `axes`), zero-padded; built once."""
        table = np.zeros((3, int(self.nodes.max())))
        for a in range(3):
            table[a, :self.nodes[a]] = self.axes[a]
        return table

    @cached_property
    def node_volume_ratio(self):
        """The volume of the largest cell beside each node (the product over axes of the
        larger of its two neighbouring cells; a grid end's node has one) over the largest
        cell's: (n_nodes,) on a rectilinear grid, where a mass threshold stated as a
        fraction of a point must follow the size of the points beside the node (points in
        a cell 8 times larger are 8 times heavier); 1.0 on a uniform grid."""
        if self.axes is None:
            return 1.0
        dual = []
        for a in self.axes:
            h = np.diff(a)
            dual.append(np.maximum(np.concatenate([h[:1], h]), np.concatenate([h, h[-1:]])))
        v = (dual[2][:, None, None] * dual[1][None, :, None] * dual[0][None, None, :]).ravel()
        return v / v.max()

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
                lo[a] = self.axes[a][PAD]
                hi[a] = self.axes[a][PAD + self.period[a]]
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
            image = (np.arange(v.shape[0]) - PAD) % N
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

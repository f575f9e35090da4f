"""Regular Cartesian background grid.

Nodes are numbered `I = i + nx * (j + ny * k)` with `nx, ny, nz = cells + 1`; node
(i, j, k) sits at `origin + (i, j, k) * cell_size`. The grid never moves (the "scratch
pad" of seed §2.1); nodal arrays are rebuilt every step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Grid:
    origin: np.ndarray  # (3,) m, position of node (0, 0, 0)
    cell_size: np.ndarray  # (3,) m, edge lengths of one cell
    cells: np.ndarray  # (3,) int64, number of cells per axis

    @classmethod
    def make(cls, origin, cell_size, cells) -> Grid:
        h = np.broadcast_to(np.asarray(cell_size, dtype=np.float64), (3,)).copy()
        n = np.asarray(cells, dtype=np.int64).reshape(3).copy()
        if np.any(h <= 0):
            raise ValueError(f"cell size must be > 0, got {h.tolist()}")
        if np.any(n < 1):
            raise ValueError(f"cell counts must be >= 1, got {n.tolist()}")
        return cls(np.asarray(origin, dtype=np.float64).reshape(3).copy(), h, n)

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
        return self.origin + self.cells * self.cell_size

    def node_positions(self) -> np.ndarray:
        """(n_nodes, 3) positions, in node numbering order."""
        axes = [self.origin[a] + np.arange(self.nodes[a]) * self.cell_size[a] for a in range(3)]
        z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)

    def contains(self, x: np.ndarray) -> np.ndarray:
        """(P,) bool: point centres inside the closed grid box."""
        return np.all((x >= self.origin) & (x <= self.upper), axis=1)

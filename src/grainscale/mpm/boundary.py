"""Boundary conditions on grid nodes and on material points.

- Node constraints (Dirichlet): the nodes of a grid face or of a box of nodes have some
  velocity components held at zero: `fixed` (all three, no-slip) or `roller` (the normal
  one only, frictionless). A constraint can end at a given time (it is removed for
  t >= end_time, as the column release of validation case 2).
- Point tractions (Neumann): a traction vector t (Pa) on the material points selected by
  a box; each carries the force t * A_p with the tributary area A_p = V0_p^(2/3) (the
  face of its cubic sub-cell), mapped to the nodes with S_Ip as the surface term of seed
  Eq. 6. Nominal traction: the area is not updated with the deformation.
- Local non-viscous damping (Cundall): f_I <- f_I - alpha |f_I| sign(v_I) per component,
  for quasi-static initialisation (geostatic stress), switched off at `end_time`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grainscale.mpm.grid import Grid

FACES = {"x-": (0, 0), "x+": (0, 1), "y-": (1, 0), "y+": (1, 1), "z-": (2, 0), "z+": (2, 1)}
AXES = {"x": 0, "y": 1, "z": 2}


@dataclass
class NodeConstraint:
    nodes: np.ndarray  # (n,) int64 node ids
    mask: np.ndarray  # (3,) bool: components held at zero velocity
    end_time: float = np.inf  # s; the constraint acts while time < end_time

    def active(self, time: float) -> bool:
        return time < self.end_time


def face_nodes(grid: Grid, face: str) -> np.ndarray:
    """Node ids of one face of the grid ('x-', 'x+', ...)."""
    axis, side = FACES[face]
    idx = np.arange(grid.n_nodes).reshape(tuple(grid.nodes[::-1]))  # [k, j, i]
    level = 0 if side == 0 else int(grid.cells[axis])
    sl = [slice(None)] * 3
    sl[2 - axis] = level
    return np.ascontiguousarray(idx[tuple(sl)].ravel())


def box_nodes(grid: Grid, lo, hi) -> np.ndarray:
    """Node ids with lo <= x_I <= hi (a tolerance of 1e-6 cell absorbs round-off)."""
    x = grid.node_positions()
    tol = 1e-6 * grid.cell_size
    sel = np.all((x >= np.asarray(lo) - tol) & (x <= np.asarray(hi) + tol), axis=1)
    return np.flatnonzero(sel).astype(np.int64)


def constraint(nodes: np.ndarray, kind: str, normal: int | None,
               end_time: float = np.inf) -> NodeConstraint:
    """`fixed`: all components; `roller`: only component `normal` (0, 1 or 2)."""
    mask = np.zeros(3, dtype=bool)
    if kind == "fixed":
        mask[:] = True
    elif kind == "roller":
        mask[normal] = True
    else:
        raise ValueError(f"unknown constraint type {kind!r}")
    return NodeConstraint(nodes, mask, end_time)


def apply_constraints(constraints: list[NodeConstraint], time: float, a: np.ndarray) -> None:
    """Zero the constrained components of a nodal vector field a (n_nodes, 3) in place."""
    for c in constraints:
        if c.active(time):
            for comp in np.flatnonzero(c.mask):
                a[c.nodes, comp] = 0.0


def local_damping(f: np.ndarray, v: np.ndarray, alpha: float) -> None:
    """Cundall's local non-viscous damping, in place: f <- f - alpha |f| sign(v)."""
    f -= alpha * np.abs(f) * np.sign(v)


@dataclass
class Traction:
    points: np.ndarray  # (n,) int64 ids of the loaded points
    force: np.ndarray  # (n, 3) N, full force t * A_p of each point
    ramp_time: float = 0.0  # s, linear ramp from start_time
    start_time: float = 0.0
    end_time: float = np.inf

    def factor(self, time: float) -> float:
        if time >= self.end_time or time < self.start_time:
            return 0.0
        if self.ramp_time > 0.0:
            return min(1.0, (time - self.start_time) / self.ramp_time)
        return 1.0


def make_traction(x: np.ndarray, vol0: np.ndarray, lo, hi, traction, **timing) -> Traction:
    """Traction on the points whose centres lie in [lo, hi]; force = t * V0^(2/3)."""
    sel = np.flatnonzero(np.all((x >= np.asarray(lo)) & (x <= np.asarray(hi)), axis=1))
    area = np.cbrt(vol0[sel]) ** 2
    force = area[:, None] * np.asarray(traction, dtype=np.float64)[None, :]
    return Traction(sel.astype(np.int64), force, **timing)


def point_forces(tractions: list[Traction], time: float, out: np.ndarray) -> None:
    """out (P,3) <- sum of the active traction forces on each point."""
    out[:] = 0.0
    for t in tractions:
        k = t.factor(time)
        if k != 0.0:
            np.add.at(out, t.points, k * t.force)

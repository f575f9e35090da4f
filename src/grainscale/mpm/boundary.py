"""Boundary conditions on grid nodes and on material points.

- Node constraints (Dirichlet): the nodes of a grid face or of a box of nodes have some
  velocity components prescribed: `fixed` (all three zero, no-slip), `roller` (the
  normal one zero, frictionless) or `velocity` (the normal one held at a given value,
  e.g. the displacement-controlled top of the unit element test). A constraint can end
  at a given time (it is removed for t >= end_time, as the column release of case 2).
- Wall contact (one-sided, separable): the nodes of a grid face are a rigid wall the
  material may leave but not enter, with Coulomb friction mu (mu = 0: a separable
  roller). The standard contact-on-grid treatment (Bardenhagen et al. 2001; in granular
  MPM e.g. Kumar 2015): with n the wall's normal pointing into the material, a node
  moving into the wall (v.n < 0) loses its normal velocity, dv_n = -v.n, and its
  tangential velocity is reduced by mu dv_n, to zero at most (stick); a node moving away
  is left free. Applied to the nodal velocity before the stress update and to the
  nodal momentum after the force integration, so the friction impulse per step is
  mu times the normal impulse, as Coulomb's law asks.
- Point tractions (Neumann): a traction vector t (Pa) on the material points selected by
  a box; each carries the force t * A_p with the tributary area A_p of its domain's
  face across the surface's normal n: V0_p^(2/3) for a cubic sub-cell, V0_p / (2 l_n)
  for a graded grid's box (so the points of a face add up to its area). The surface
  term of seed Eq. 6, int N_I t dS, is evaluated at the point's surface position
  x_p + l_p n (n the outward normal of the loaded surface) with linear weights, so the
  load reaches the nodes of the surface itself and
  the outermost cell carries the full stress (mapping it from x_p instead leaves a
  quarter of it on the next node plane in). With area "current" (the default) the
  traction is a Cauchy traction on the deformed surface: the area follows Nanson's
  formula a = J |F^-T N| A0 with each point's deformation gradient, so a confining
  pressure stays a pressure while the body deforms, and the load acts at the deformed
  surface x_p + l_p |F N|; "initial" keeps A0 and l_p (nominal).
- Local non-viscous damping (Cundall): f_I <- f_I - alpha |f_I| sign(v_I) per component,
  for quasi-static initialisation (geostatic stress), switched off at `end_time`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grainscale.mpm.grid import Grid
from grainscale.mpm.points import half_extent

FACES = {"x-": (0, 0), "x+": (0, 1), "y-": (1, 0), "y+": (1, 1), "z-": (2, 0), "z+": (2, 1)}
AXES = {"x": 0, "y": 1, "z": 2}


@dataclass
class NodeConstraint:
    nodes: np.ndarray  # (n,) int64 node ids
    mask: np.ndarray  # (3,) bool: components held at a prescribed velocity
    end_time: float = np.inf  # s; the constraint acts while time < end_time
    value: np.ndarray | None = None  # (3,) m/s, prescribed velocity (default zero)

    def active(self, time: float) -> bool:
        return time < self.end_time


@dataclass
class Wall:
    """One-sided (separable) wall with Coulomb friction on the nodes of a grid face."""

    nodes: np.ndarray  # (n,) int64 node ids
    axis: int  # 0, 1 or 2: the wall's normal axis
    inward: float  # +1 or -1: the sign of the normal pointing into the material
    friction: float = 0.0  # Coulomb coefficient mu (0: frictionless, separable roller)
    end_time: float = np.inf  # s; the wall acts while time < end_time

    def active(self, time: float) -> bool:
        return time < self.end_time


def face_wall(grid: Grid, face: str, friction: float = 0.0, end_time: float = np.inf) -> Wall:
    """A one-sided wall on a grid face ('z-' is a floor: the material lies above it)."""
    axis, side = FACES[face]
    return Wall(face_nodes(grid, face), axis, 1.0 if side == 0 else -1.0, friction, end_time)


def apply_walls(walls: list[Wall], time: float, a: np.ndarray) -> None:
    """Wall contact on a nodal velocity or momentum field a (n_nodes, 3), in place (both
    scale with the same nodal mass, so the rule is the same): the approaching normal
    component removed, the tangential one reduced by mu times it (Coulomb)."""
    for wall in walls:
        if not wall.active(time):
            continue
        rows = a[wall.nodes]
        vn = wall.inward * rows[:, wall.axis]
        hit = vn < 0.0  # moving into the wall
        if not hit.any():
            continue
        r = rows[hit]
        dvn = -vn[hit]  # normal velocity (momentum) removed, > 0
        r[:, wall.axis] = 0.0
        if wall.friction > 0.0:
            vt = np.sqrt((r * r).sum(axis=1))  # the normal part is zero now
            with np.errstate(divide="ignore", invalid="ignore"):
                keep = np.where(vt > 0.0, np.maximum(0.0, 1.0 - wall.friction * dvn / vt), 0.0)
            r *= keep[:, None]
        rows[hit] = r
        a[wall.nodes] = rows


def keep_behind_walls(walls: list[Wall], time: float, grid: Grid, x: np.ndarray,
                      v: np.ndarray) -> None:
    """The points' side of the wall contact, in place: a point centre that crossed a wall
    plane (a point at zero stress, separated from its neighbours, is carried by the
    node velocities only and nothing stops it) is put back on the plane and loses its
    velocity into the wall."""
    for wall in walls:
        if not wall.active(time):
            continue
        a = wall.axis
        plane = grid.origin[a] if wall.inward > 0 else grid.upper[a]
        crossed = wall.inward * (x[:, a] - plane) < 0.0
        if crossed.any():
            x[crossed, a] = plane
            vn = wall.inward * v[crossed, a]
            v[crossed, a] = np.where(vn < 0.0, 0.0, v[crossed, a])


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
               end_time: float = np.inf, velocity: float = 0.0) -> NodeConstraint:
    """`fixed`: all components zero; `roller`: component `normal` (0, 1 or 2) zero;
    `velocity`: component `normal` held at `velocity` (m/s)."""
    mask = np.zeros(3, dtype=bool)
    value = None
    if kind == "fixed":
        mask[:] = True
    elif kind == "roller":
        mask[normal] = True
    elif kind == "velocity":
        mask[normal] = True
        value = np.zeros(3)
        value[normal] = velocity
    else:
        raise ValueError(f"unknown constraint type {kind!r}")
    return NodeConstraint(nodes, mask, end_time, value)


def apply_constraints(constraints: list[NodeConstraint], time: float, a: np.ndarray,
                      mass: np.ndarray | None = None) -> None:
    """Impose the constrained components of a nodal field a (n_nodes, 3) in place: a
    velocity field, or a momentum field when the nodal `mass` is given (m_I v)."""
    for c in constraints:
        if c.active(time):
            for comp in np.flatnonzero(c.mask):
                if c.value is None or c.value[comp] == 0.0:
                    a[c.nodes, comp] = 0.0
                elif mass is None:
                    a[c.nodes, comp] = c.value[comp]
                else:
                    a[c.nodes, comp] = mass[c.nodes] * c.value[comp]


def local_damping(f: np.ndarray, v: np.ndarray, alpha: float) -> None:
    """Cundall's local non-viscous damping, in place: f <- f - alpha |f| sign(v)."""
    f -= alpha * np.abs(f) * np.sign(v)


@dataclass
class Traction:
    points: np.ndarray  # (n,) int64 ids of the loaded points
    force: np.ndarray  # (n, 3) N, full force t * A_p of each point
    normal: np.ndarray  # (3,) outward unit normal of the loaded surface
    ramp_time: float = 0.0  # s, linear ramp from start_time
    start_time: float = 0.0
    end_time: float = np.inf
    current_area: bool = True  # Cauchy traction on the deformed surface (Nanson)

    def factor(self, time: float) -> float:
        if time >= self.end_time or time < self.start_time:
            return 0.0
        if self.ramp_time > 0.0:
            return min(1.0, (time - self.start_time) / self.ramp_time)
        return 1.0


def make_traction(x: np.ndarray, vol0: np.ndarray, lo, hi, traction, surface: str,
                  lp: np.ndarray | None = None, **timing) -> Traction:
    """Traction t [Pa] on the points whose centres lie in [lo, hi], on their `surface`
    side ('x+', 'z-', ...): force = t * A0, with A0 [m^2] the face of the point's domain
    across the surface's normal n, V0 / (2 l_n) for a box of half-widths lp (P,3) (a
    graded grid's sub-cell, V0 = 8 lx ly lz: the points of a face then add up to its area
    exactly), and V0^(2/3) otherwise (a cube, a file point whose domain its cell cut, lp
    None: the digits uniform grids have always used); times the Nanson area ratio if
    current."""
    sel = np.flatnonzero(np.all((x >= np.asarray(lo)) & (x <= np.asarray(hi)), axis=1))
    axis, side = FACES[surface]
    area = np.cbrt(vol0[sel]) ** 2
    if lp is not None:  # a box that is the point's sub-cell (V0 = 8 lx ly lz): its face
        l = np.asarray(lp)[sel]
        box = (((l[:, 0] != l[:, 1]) | (l[:, 1] != l[:, 2]))
               & np.isclose(8.0 * l.prod(axis=1), vol0[sel], rtol=1e-9, atol=0.0))
        area[box] = vol0[sel][box] / (2.0 * l[box, axis])
    force = area[:, None] * np.asarray(traction, dtype=np.float64)[None, :]
    normal = np.zeros(3)
    normal[axis] = 1.0 if side else -1.0
    return Traction(sel.astype(np.int64), force, normal, **timing)


def area_ratio(F: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """a/A0 = J |F^-T N| of each point's surface with unit reference normal N (Nanson),
    taken as |(F T1) x (F T2)| with T1 x T2 = N: J F^-T N is the cofactor of F applied to
    N, which stays defined where F is singular (a surface crushed flat has no area)
    instead of needing F's inverse."""
    t1 = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    return np.linalg.norm(np.cross(F @ t1, F @ t2), axis=1)


def traction_loads(tractions: list[Traction], time: float, x: np.ndarray, lp: np.ndarray,
                   grid: Grid, F: np.ndarray | None = None):
    """The nodal loads of the active tractions as (node ids (k,), forces (k,3)), one
    entry per loaded point and node of its linear stencil at the surface position, or
    None if no traction acts. The caller sums them in fixed point with the internal
    forces, so the nodal totals do not depend on the order of the points or on ranks.
    """
    pieces = []
    for t in tractions:
        k = t.factor(time)
        if k == 0.0:
            continue
        force = t.force
        offset = half_extent(lp[t.points], t.normal)
        if t.current_area and F is not None and len(t.points):
            Fp = F[t.points]
            force = force * area_ratio(Fp, t.normal)[:, None]
            offset = offset * np.linalg.norm(Fp @ t.normal, axis=1)  # stretched half-size
        xs = x[t.points] + offset[:, None] * t.normal[None, :]
        pieces.append(surface_loads(xs, force, grid, k))
    return join_loads(pieces)


def surface_loads(xs: np.ndarray, force: np.ndarray, grid: Grid, factor: float = 1.0):
    """Forces factor * force (k,3) [N] acting at surface positions xs (k,3), spread to
    the 8 nodes of each position's cell with linear weights: (node ids (8k,), forces
    (8k,3))."""
    from grainscale.mpm.shape import LINEAR, evaluate

    base, w, _ = evaluate(np.ascontiguousarray(xs), np.zeros(len(xs)), grid, LINEAR)
    nx, ny = int(grid.nodes[0]), int(grid.nodes[1])
    ids_all, f_all = [], []
    for i in range(2):
        for j in range(2):
            for kk in range(2):
                ids_all.append(base[:, 0] + i + nx * (base[:, 1] + j + ny * (base[:, 2] + kk)))
                S = w[:, 0, i] * w[:, 1, j] * w[:, 2, kk]
                f_all.append((factor * S)[:, None] * force)
    return np.concatenate(ids_all), np.concatenate(f_all)


def join_loads(pieces: list):
    """One (node ids, forces) pair from several, or None if there are none."""
    pieces = [pc for pc in pieces if pc is not None]
    if not pieces:
        return None
    return np.concatenate([pc[0] for pc in pieces]), np.concatenate([pc[1] for pc in pieces])

"""Build an MPMState from a validated case (config.case.Case).

Every input problem that can be seen before the first step is reported here as a
ConfigError naming the key, the value and the valid range: a missing point file, points
outside the grid, a fixed dt above the CFL limit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from grainscale.config.base import ConfigError
from grainscale.config.case import Case
from grainscale.distributed import partition
from grainscale.distributed.comm import Comm
from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.materials import KINDS
from grainscale.mpm.points import (
    concatenate,
    fill_box,
    fill_cylinder,
    make_points,
    read_points,
    sub_cell_half_widths,
    take,
)
from grainscale.mpm.rigid import BOX, CYLINDER, RigidBody, cross_section
from grainscale.mpm.step import MPMState

AXES = {"x": 0, "y": 1, "z": 2}


def _check_extent(grid: Grid, lo, hi, key: str) -> None:
    """A filled shape must lie inside the grid (filling never silently clips it)."""
    lo, hi = np.asarray(lo), np.asarray(hi)
    tol = 1e-9 * grid.cell_size
    glo, ghi = grid.period_box()
    if np.any(lo < glo - tol) or np.any(hi > ghi + tol):
        raise ConfigError(
            f"{key}: extends from {lo.tolist()} to {hi.tolist()}, outside the grid; valid "
            f"range {glo.tolist()} .. {ghi.tolist()} "
            "(the grid's first and last nodes); set "
            "clip_to_grid = true to keep only the part inside (symmetry planes)")


def _shape_extent(shape) -> tuple[np.ndarray, np.ndarray]:
    if shape.shape == "box":
        return np.asarray(shape.lo), np.asarray(shape.hi)
    c = np.asarray(shape.center, dtype=float)
    lo, hi = c - shape.radius, c + shape.radius
    ax = AXES[shape.axis]
    lo[ax], hi[ax] = c[ax], c[ax] + shape.height
    return lo, hi


def _body_points(grid: Grid, body, i: int, case_dir: Path):
    if body.shape != "file" and not body.clip_to_grid:
        _check_extent(grid, *_shape_extent(body), f"bodies[{i}]")
    if body.shape == "box":
        if any(h <= l for l, h in zip(body.lo, body.hi, strict=True)):
            raise ConfigError(f"bodies[{i}].hi = {list(body.hi)}: must exceed lo = "
                              f"{list(body.lo)} on every axis")
        return fill_box(grid, body.lo, body.hi, body.points_per_cell)
    if body.shape == "cylinder":
        return fill_cylinder(grid, body.center, body.radius, body.height, AXES[body.axis],
                             body.points_per_cell)
    path = (case_dir / body.path) if not Path(body.path).is_absolute() else Path(body.path)
    if not path.is_file():
        raise ConfigError(f"bodies[{i}].path = {body.path!r}: file not found ({path})")
    try:
        return read_points(path)
    except ValueError as err:
        raise ConfigError(f"bodies[{i}].path = {body.path!r}: {err}") from None


def build_grid(case: Case) -> Grid:
    g = case.grid
    periodic = [a in g.periodic for a in ("x", "y", "z")]
    if g.axes() is not None:  # checked when the case was read
        return Grid.rectilinear(g.axes(), periodic=periodic)
    return Grid.make(g.origin, g.cell_size, g.cells, periodic=periodic)


def build_state(case: Case, case_dir: Path | str = ".", n_threads: int = 1,
                material_factory=None, comm: Comm | None = None,
                owners: np.ndarray | None = None) -> MPMState:
    """The solver state at time.start.

    `material_factory(name, cfg, x, local)` may supply materials of types this module
    does not know (the coupling's DEM material): x holds the initial positions of the
    material's points over all ranks, local the indices (into those) this rank owns.
    Under MPI (`comm` with several ranks) every rank builds and checks the whole point
    set, then keeps the points it owns (distributed/partition.py, or `owners`: the rank
    of every point, as rebalancing decides); `state.point_ids` holds their global ids,
    in ascending order.
    """
    case_dir = Path(case_dir)
    comm = comm if comm is not None else Comm()
    grid = build_grid(case)
    names = list(case.materials)
    sets = []
    lo, hi = grid.period_box()
    per = grid.periodic
    for i, body in enumerate(case.bodies):
        x, vol = _body_points(grid, body, i, case_dir)
        if x.shape[0] == 0:
            raise ConfigError(f"bodies[{i}]: the {body.shape} contains no material point "
                              "(is it inside the grid, larger than a sub-cell?)")
        # a periodic axis holds [lo, hi): hi is lo's image
        out = ~np.all((x >= lo) & ((x <= hi) & ~per | (x < hi) & per), axis=1)
        if out.any():
            raise ConfigError(
                f"bodies[{i}]: {int(out.sum())} material point(s) outside the grid, e.g. at "
                f"{x[out][0].tolist()}; valid range {lo.tolist()} .. {hi.tolist()} "
                "(the grid's first and last nodes)")
        mcfg = case.materials[body.material]
        if grid.axes is not None and body.shape != "file":  # box-shaped sub-cells
            lp = sub_cell_half_widths(grid, x, body.points_per_cell)
        elif grid.axes is not None:  # a cube of the point's volume, within its own cell
            lp = np.minimum(0.5 * np.cbrt(vol)[:, None], sub_cell_half_widths(grid, x, 1))
        else:
            lp = np.minimum(0.5 * np.cbrt(vol), 0.5 * grid.cell_size.min())
        sets.append(make_points(x, vol, mcfg.density, names.index(body.material),
                                velocity=body.velocity, lp=lp))
    everything = concatenate(sets)
    if owners is None:
        owners = partition.owners(everything.n, comm.size, case.solver.partition_seed)
    point_ids = np.flatnonzero(owners == comm.rank).astype(np.int64)
    pts = take(everything, point_ids)
    materials, mat_points = [], []
    for k, name in enumerate(names):
        ids = np.flatnonzero(pts.mat == k).astype(np.int64)
        everyone = np.flatnonzero(everything.mat == k)  # the material's global point list
        local = np.searchsorted(everyone, point_ids[ids])  # this rank's points in it
        cfg = case.materials[name]
        if cfg.type in KINDS:
            params = cfg.model_dump(exclude={"type"})
            mat = KINDS[cfg.type](name, ids.size, **params)
        elif material_factory is not None:
            mat = material_factory(name, cfg, everything.x[everyone], local)
        else:
            raise ConfigError(f"materials.{name}.type = {cfg.type!r}: unknown material type; "
                              f"valid: {sorted(KINDS)}")
        materials.append(mat)
        mat_points.append(None if ids.size == pts.n else ids)

    t0 = case.time.start
    constraints, walls = [], []
    for i, bc in enumerate(case.boundaries):
        end = np.inf if bc.end_time is None else bc.end_time
        if bc.type == "friction" or bc.separable:
            walls.append(boundary.face_wall(grid, bc.face, bc.friction or 0.0, end))
            continue
        if bc.face is not None:
            nodes = boundary.face_nodes(grid, bc.face)
            normal = boundary.FACES[bc.face][0]
        else:
            nodes = boundary.box_nodes(grid, bc.box.lo, bc.box.hi)
            normal = AXES[bc.normal] if bc.normal else None
            if nodes.size == 0:
                raise ConfigError(f"boundaries[{i}].box = {bc.box.model_dump()}: contains no "
                                  "grid node (nodes sit at origin + k * cell_size)")
        constraints.append(boundary.constraint(nodes, bc.type, normal, end,
                                               velocity=bc.velocity or 0.0))
    tractions = []
    n_loaded = 0
    for i, t in enumerate(case.tractions):
        tr = boundary.make_traction(everything.x, everything.vol0, t.lo, t.hi, t.traction,
                                    t.surface, lp=everything.lp,
                                    ramp_time=t.ramp_time,
                                    start_time=t0 if t.start_time is None else t.start_time,
                                    end_time=np.inf if t.end_time is None else t.end_time,
                                    current_area=t.area == "current")
        if tr.points.size == 0:
            raise ConfigError(f"tractions[{i}]: box lo = {list(t.lo)}, hi = {list(t.hi)} "
                              "selects no material point")
        n_loaded += tr.points.size
        mine = np.isin(tr.points, point_ids)
        tr.points = np.searchsorted(point_ids, tr.points[mine]).astype(np.int64)
        tr.force = np.ascontiguousarray(tr.force[mine])
        tractions.append(tr)
    rigid = None
    if case.rigid is not None:
        r = case.rigid
        if not r.clip_to_grid:
            _check_extent(grid, *_shape_extent(r), "rigid")
        if r.shape == "box":
            x, vol = fill_box(grid, r.lo, r.hi, r.points_per_cell)
        else:
            x, vol = fill_cylinder(grid, r.center, r.radius, r.height, AXES[r.axis],
                                   r.points_per_cell)
        if x.shape[0] == 0:
            raise ConfigError("rigid: the body contains no point inside the grid")
        if r.shape == "box":
            kind, geom = BOX, np.concatenate([r.lo, r.hi, [0.0, 0.0]])
        else:
            axis = np.zeros(3)
            axis[AXES[r.axis]] = 1.0
            kind, geom = CYLINDER, np.concatenate([r.center, axis, [r.radius, r.height]])
        lp = (sub_cell_half_widths(grid, x, r.points_per_cell) if grid.axes is not None
              else np.minimum(0.5 * np.cbrt(vol), 0.5 * grid.cell_size.min()))
        rigid = RigidBody(x=x, lp=lp,
                          velocity=np.asarray(r.velocity, dtype=np.float64),
                          ramp_time=r.ramp_time,
                          start_time=t0 if r.start_time is None else r.start_time,
                          kind=kind, geom=np.asarray(geom, dtype=np.float64),
                          contact=r.contact, penalty=r.penalty,
                          damping_ratio=r.damping_ratio, friction=r.friction)
        moving = np.flatnonzero(np.asarray(r.velocity) != 0.0)
        if len(moving) == 1:  # along a grid axis: the section p_u and d/R refer to
            glo, ghi = grid.period_box()
            rigid.area, rigid.radius = cross_section(kind, rigid.geom, int(moving[0]),
                                                     np.asarray(glo), np.asarray(ghi))
    s = case.solver
    state = MPMState(
        grid=grid, points=pts, materials=materials, mat_points=mat_points,
        constraints=constraints, walls=walls, tractions=tractions, rigid=rigid,
        gravity=np.asarray(s.gravity, dtype=np.float64), scheme=s.scheme, shape=s.shape,
        velocity_update=s.velocity_update, flip=0.0 if s.flip is None else s.flip,
        relaxation_time=(np.inf if s.velocity_relaxation_time is None
                         else s.velocity_relaxation_time), cfl=s.cfl,
        damping=case.damping.alpha,
        damping_end=np.inf if case.damping.end_time is None else case.damping.end_time,
        time=t0, step=0, n_threads=n_threads, comm=comm, n_traction_global=n_loaded)
    state.point_ids = point_ids
    if s.dt is not None and s.dt > state.stable_dt():
        raise ConfigError(f"solver.dt = {s.dt}: above the CFL limit cfl * h / (c + |v|) = "
                          f"{state.stable_dt():.6g} s (cfl = {s.cfl}, h = "
                          f"{grid.cell_size.min()} m, c = {state.wave_speed():.6g} m/s)")
    return state

"""The explicit MPM step as a short sequence of named stages (seed Eq. 3-6, 16-19).

USF (the seed's order, Algorithm 1):
    shape functions -> P2G mass, momentum -> grid velocity (+ BCs) -> dH, F, material
    -> nodal forces -> grid momentum (+ damping, BCs, rigid body) -> G2P
USL: the material update moves after G2P and uses the updated grid velocity.
MUSL: as USL, but the grid velocity is first re-mapped from the updated point momenta.
The stages are plain Python over the numba kernels of `shape` and `transfer`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from grainscale.config.case import FLIP_DEFAULT, DampingCfg, SolverCfg
from grainscale.distributed.comm import Comm
from grainscale.mpm import boundary, rectilinear
from grainscale.mpm.fluidity import advance_fluidity
from grainscale.mpm.grid import Grid
from grainscale.mpm.points import Points
from grainscale.mpm.rigid import RigidBody
from grainscale.mpm.shape import GIMP, evaluate, stencil_width
from grainscale.mpm.transfer import (
    Transfer,
    fixed_point_scale,
    g2p_kernel,
    velocity_gradient_kernel,
)

SCHEMES = ("USF", "USL", "MUSL")
VELOCITY_UPDATES = ("apic", "flip", "aflip")
_SOLVER = SolverCfg()  # the case file's defaults are the only ones
_DAMPING = DampingCfg()
MASS_TOL = 1e-9  # nodes lighter than this fraction of the heaviest point carry no velocity
LIGHT_MASS_TOL = 1e-4  # lighter nodes give C_p their force-free velocity
CONTACT_MASS_TOL = 1e-2  # lighter nodes of a penalty contact's zone get no force


class SimulationError(RuntimeError):
    """The run cannot continue (a point left the grid, a non-finite value appeared)."""


class RemoteFailure(SimulationError):
    """Another rank met a SimulationError (it reports the cause); this rank stops too."""


@dataclass
class MPMState:
    grid: Grid
    points: Points
    materials: list  # objects with the interface of materials.base.Material
    mat_points: list  # per material: (n,) int64 point ids, or None when it owns all points
    constraints: list = field(default_factory=list)  # boundary.NodeConstraint
    walls: list = field(default_factory=list)  # boundary.Wall (one-sided, friction)
    tractions: list = field(default_factory=list)  # boundary.Traction
    rigid: RigidBody | None = None
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))  # m/s^2
    scheme: str = _SOLVER.scheme
    shape: str = _SOLVER.shape
    # "apic"; "flip": the FLIP/PIC blend; "aflip": APIC's affine transfer, FLIP's increment
    velocity_update: str = _SOLVER.velocity_update
    flip: float = FLIP_DEFAULT  # FLIP fraction of "flip" and "aflip" (0 = PIC / APIC)
    # s; finite: "flip" and "aflip" take flip = exp(-dt / relaxation_time) each step
    relaxation_time: float = np.inf
    cfl: float = _SOLVER.cfl
    damping: float = _DAMPING.alpha  # local damping coefficient alpha
    damping_end: float = np.inf  # s, damping acts while time < damping_end
    time: float = 0.0  # s
    step: int = 0
    n_threads: int = 1
    comm: Comm = field(default_factory=Comm)  # ranks sharing the points (serial: one)
    n_traction_global: int = 0  # loaded points over all ranks (fixed-point bound)
    # --- scratch, rebuilt every step -------------------------------------------------
    vmax: float = 0.0  # m/s, largest point speed after the last step
    last_dt: float = 0.0  # s, the last step taken

    def __post_init__(self):
        if self.velocity_update not in VELOCITY_UPDATES:
            raise ValueError(f"velocity_update = {self.velocity_update!r}: valid "
                             f"{VELOCITY_UPDATES}")
        P = self.points.n
        self.n_global = self.comm.total(P)  # points over all ranks
        # the uniform kernels fill 3 slots per axis, linear hats too; a rectilinear grid's
        # stencil is sized per axis every step (shape_functions)
        self.ns = np.full(3, stencil_width(self.shape), dtype=np.int64)
        self.transfer = Transfer(self.grid.n_nodes, P, self.n_threads, self.comm, self.n_global,
                                 fold=self.grid.fold if self.grid.periodic.any() else None)
        self.dH = np.zeros((P, 3, 3))
        self.shape_buf = (np.zeros((P, 3), dtype=np.int64), np.zeros((P, 3, 3)),
                          np.zeros((P, 3, 3)))
        reach = self.grid.reach()
        if P and np.any(self.points.lp.max(axis=0) >= reach):
            a = int(np.argmax(self.points.lp.max(axis=0) - reach))
            raise ValueError(f"lp: a point's half-width on axis {'xyz'[a]} "
                             f"({self.points.lp[:, a].max():.6g} m) reaches past the periodic "
                             f"padding; valid: below {reach[a]:.6g} m (the padding's width)")
        self.fext = np.zeros((P, 3))  # N, point forces (none yet: loads act on nodes)
        vmax = float(np.sqrt((self.points.v**2).sum(axis=1).max())) if P else 0.0
        mmax = float(self.points.m.max()) if P else 0.0
        self.vmax, mmax = self.comm.max([vmax, mmax])
        self.chunk_vmax = np.zeros_like(self.transfer.chunk_max)
        self.chunk_out = np.zeros_like(self.transfer.chunk_count)
        self.m_point_max = mmax
        # the mass of "a point" beside each node: the heaviest point's on a uniform grid;
        # on a graded one, the mass per cell volume of the points (m_p over the volume
        # of the cell each was made in, x0: it does not change as points move) times
        # the largest cell beside the node, the mass of a point made there
        if self.grid.axes is None:
            self.m_point_ref = mmax
        else:
            cells = self.grid.cell_sizes_at(self.points.x0).prod(axis=1)
            ratio = float((self.points.m / cells).max()) if P else 0.0
            self.m_point_ref = float(self.comm.max([ratio])[0]) * self.grid.node_volume
        self.mass_tol = MASS_TOL * self.m_point_ref
        self.contact_loads = None
        lp_min = float(self.points.lp.min()) if P else np.inf
        self.lp_min = -float(self.comm.max([-lp_min])[0])  # smallest half-width, all ranks

    # ---------------------------------------------------------------- time step
    def wave_speed(self) -> float:
        """Largest P-wave speed of any material on any rank (m/s)."""
        c = max((m.wave_speed() for m in self.materials), default=0.0)
        return float(self.comm.max([c])[0])

    def critical_dt(self) -> float:
        """CFL limit dt = h_min / (c + |v|_max), or the period bound of a rigid body's
        penalty contact, or a material's own limit over the CFL number, whichever is
        smallest (multiply by the CFL number to use it)."""
        h = float(self.grid.cell_size.min())
        dt = h / (self.wave_speed() + self.vmax)
        for m in self.materials:  # a material's own limit (nonlocal fluidity's diffusion)
            if hasattr(m, "max_dt"):
                dt = min(dt, m.max_dt(h) / self.cfl)
        if self.rigid is not None:
            dt = min(dt, self.rigid.critical_dt(self.lp_min))
        return dt

    def stable_dt(self) -> float:
        return self.cfl * self.critical_dt()


# ------------------------------------------------------------------------- stages
def shape_functions(s: MPMState) -> None:
    """S_Ip and grad S_Ip at the current point positions; on a graded grid each axis'
    stencil sized from where the points are now (rectilinear.stencil)."""
    if s.grid.axes is None:
        s.base, s.w, s.dw = evaluate(s.points.x, s.points.lp, s.grid, s.shape,
                                     out=s.shape_buf)
    else:
        gimp = s.shape == GIMP
        ns = rectilinear.stencil(s.points.x, s.points.lp, s.grid.axes, gimp)
        if s.comm.size > 1:  # one width on every rank: the kernels' loops are then alike
            ns = np.asarray(s.comm.max([float(n) for n in ns]), dtype=np.int64)
        if ns.max() > s.shape_buf[1].shape[2]:  # grown, never shrunk: no allocation a step
            P = s.points.n
            s.shape_buf = (s.shape_buf[0], np.zeros((P, 3, int(ns.max()))),
                           np.zeros((P, 3, int(ns.max()))))
        s.ns = ns
        s.base, s.w, s.dw = rectilinear.evaluate(s.points.x, s.points.lp, s.grid.axes, gimp,
                                                 out=s.shape_buf, ns=ns)
    if s.scheme == "MUSL" and s.velocity_update != "flip":
        s.x_start = s.points.x.copy()  # the remap's affine term is taken where S_Ip was


def impose(s: MPMState, a: np.ndarray, mass: np.ndarray | None = None) -> None:
    """Dirichlet constraints, then wall contact, on a nodal velocity field a (or a
    momentum field, given the nodal mass)."""
    boundary.apply_constraints(s.constraints, s.time, a, mass)
    boundary.apply_walls(s.walls, s.time, a)


def p2g(s: MPMState) -> None:
    """Nodal mass and momentum, seed Eq. 16."""
    pts = s.points
    s.mass, s.momentum, ok = s.transfer.mass_momentum(pts.m, pts.v, pts.C, pts.x, s.grid,
                                                      s.base, s.w, s.ns)
    if not ok:
        raise SimulationError(f"step {s.step}: non-finite point velocity")
    s.active = s.mass > s.mass_tol


def fluidity(s: MPMState, dt: float) -> None:
    """The granular fluidity of a nonlocal material (materials/fluidity.py) advanced on
    the grid (mpm/fluidity.py), before the stress update that uses it."""
    for m, ids in zip(s.materials, s.mat_points, strict=True):
        if hasattr(m, "fluidity"):
            advance_fluidity(s, m, ids, dt)


def nodes_contact(s: MPMState) -> bool:
    """Is there a rigid body that imposes its velocity on nodes (`contact = "nodes"`)?"""
    return s.rigid is not None and s.rigid.contact == "nodes"


def rigid_velocity(s: MPMState, dt: float) -> None:
    """Nodes covered by the rigid body and the velocity it imposes during this step."""
    if not nodes_contact(s):
        s.rigid_nodes = np.zeros(0, dtype=np.int64)
        return
    s.rigid_nodes = s.rigid.covered_nodes(s.grid)
    s.rigid_v = s.rigid.velocity_at(s.time + 0.5 * dt)


def grid_velocity(s: MPMState) -> None:
    """v_I = p_I / m_I with the Dirichlet conditions and the rigid body applied."""
    v = np.zeros_like(s.momentum)
    a = s.active
    v[a] = s.momentum[a] / s.mass[a, None]
    # FLIP's increment is taken from the mapped velocity, before the boundaries act, so
    # the impulse of a wall or of the rigid body reaches the points too
    s.v_mapped = v.copy() if s.velocity_update != "apic" else v
    impose(s, v)
    if nodes_contact(s):
        # the material's velocity at the covered nodes before the body imposes its own:
        # the momentum the body takes away there is part of its reaction
        s.rigid_v_material = v[s.rigid_nodes].copy()
        v[s.rigid_nodes] = s.rigid_v
    s.v_old = v


def update_stress(s: MPMState, vgrid: np.ndarray, dt: float) -> None:
    """dH_p = dt sum_I v_I (x) grad S_Ip (seed Eq. 17), F and V, then every material."""
    pts = s.points
    velocity_gradient_kernel(vgrid, s.base, s.w, s.dw, s.grid.nodes, s.ns, dt, s.dH, pts.F,
                             pts.vol0, pts.vol)
    failure = None
    try:
        for mat, ids in zip(s.materials, s.mat_points, strict=True):
            if ids is None:
                mat.update(s.dH, dt, pts.stress)
            elif ids.size:
                sig = pts.stress[ids]
                mat.update(s.dH[ids], dt, sig)
                pts.stress[ids] = sig
    except SimulationError as err:
        failure = err
    # every rank learns of a failure in the same step, so none waits for the others
    if s.comm.any(failure is not None):
        if failure is not None:
            raise failure
        raise RemoteFailure(f"step {s.step}: another rank failed")


def rigid_penalty(s: MPMState, dt: float) -> None:
    """Penalty contact of the rigid body on the points (mpm/rigid.py) as nodal loads, and
    its reaction: minus their sum over all ranks, in fixed point so that it does not
    depend on how the points are split."""
    body = s.rigid
    s.contact_loads = None
    if body is None or body.contact != "penalty":
        return
    if body.wave_speed_ref <= 0.0:  # the stiffness is fixed at the run's first step
        body.wave_speed_ref = s.wave_speed()
    pts = s.points
    _, force, where = body.penalty_forces(pts.x, pts.v, pts.m, pts.lp, s.time, dt)
    bound = float(s.comm.max([float(np.abs(force).sum())])[0])
    if not np.isfinite(bound):
        raise SimulationError(f"step {s.step}: non-finite contact force of the rigid body")
    total = np.zeros(3, dtype=np.int64)
    scale = fixed_point_scale(bound * s.comm.size)
    total[:] = np.rint(force * scale).astype(np.int64).sum(axis=0)
    s.comm.sum_int(total)
    body.force = -total / scale
    if len(force):
        s.contact_loads = boundary.surface_loads(where, force, s.grid)


def nodal_forces(s: MPMState) -> None:
    """f_I = f_int + f_ext (seed Eq. 5-6): stress divergence, gravity, point tractions
    and a rigid body's penalty contact."""
    pts = s.points
    loads = boundary.traction_loads(s.tractions, s.time, pts.x, pts.lp, s.grid, pts.F)
    n_extra = s.n_traction_global
    if s.rigid is not None and s.rigid.contact == "penalty":
        loads = boundary.join_loads([loads, s.contact_loads])
        n_extra += s.n_global  # at most one contact load per point and node
    s.force, ok = s.transfer.force(pts.m, pts.vol, pts.stress, s.fext, s.gravity,
                                   s.grid.cell_size, s.base, s.w, s.dw, s.grid.nodes, s.ns,
                                   extra=loads, n_extra=n_extra)
    if not ok:
        raise SimulationError(f"step {s.step}: non-finite stress or load at a material point")


def integrate_grid(s: MPMState, dt: float) -> None:
    """p_I <- m_I v_I + dt f_I (seed Eq. 3), with damping, Dirichlet conditions and the
    rigid body; the rigid body's reaction is recorded."""
    f = s.force
    if s.contact_loads is not None:
        # nodes of the contact zone holding a sliver of a point's mass get no force: their
        # internal force grows like the overlap, their mass like its square (a loaded
        # surface crossing a node plane), and the acceleration would blow up
        light = np.zeros(len(s.mass), dtype=np.bool_)
        light[s.contact_loads[0]] = True
        light &= s.mass < CONTACT_MASS_TOL * s.m_point_ref
        f[light] = 0.0
    if nodes_contact(s):
        # the force the body exerts on the nodes it covers is (m_I v_body - p_I)/dt - f_I,
        # p_I the material's momentum there (mapped, after the Dirichlet conditions);
        # the material pushes back with minus its sum (damping does not enter: it is a
        # numerical device of the free nodes)
        rn = s.rigid_nodes
        target = s.mass[rn, None] * s.rigid_v[None, :]
        p_rn = s.mass[rn, None] * s.rigid_v_material + dt * f[rn]
        s.rigid.force = -(target - p_rn).sum(axis=0) / dt
    if s.damping > 0.0 and s.time < s.damping_end:
        boundary.local_damping(f, s.v_old, s.damping)
    p = s.mass[:, None] * s.v_old + dt * f
    impose(s, p, s.mass)
    if nodes_contact(s):
        p[rn] = target
    v = np.zeros_like(p)
    a = s.active
    v[a] = p[a] / s.mass[a, None]
    if nodes_contact(s):
        v[s.rigid_nodes] = s.rigid_v  # also on covered nodes without material
    s.v_new = v


def affine_velocity(s: MPMState) -> np.ndarray:
    """The nodal velocity whose gradient the points' affine field C_p takes (APIC,
    AFLIP): v_new, except at nodes lighter than LIGHT_MASS_TOL of a point, which take
    the velocity they would have without this step's force.

    A node holding a sliver of a point's mass (the point's GIMP domain overlapping its
    support by delta) gets a force that grows like delta and a mass like delta^2; its
    acceleration grows like 1/delta, and grad S_Ip like delta, so the sliver adds to C_p
    a term that does not vanish as delta -> 0 and need not resemble the flow (a
    footing's corner point was thrown out of the grid this way, docs/mpm.md). Only C_p
    is spared: v_p and x_p take v_new (weighted by S_Ip ~ delta^2, the sliver's share
    vanishes), so momentum is conserved as before, and C_p's own momentum in P2G is
    zero for shape functions that reproduce linear fields.
    """
    light = (s.mass < LIGHT_MASS_TOL * s.m_point_ref) & s.active
    if s.velocity_update == "flip" or not light.any():
        return s.v_new
    p_free = s.mass[:, None] * s.v_old
    impose(s, p_free, s.mass)
    va = s.v_new.copy()
    va[light] = p_free[light] / s.mass[light, None]
    if nodes_contact(s):
        va[s.rigid_nodes] = s.rigid_v
    return va


def g2p(s: MPMState, dt: float) -> None:
    """Point velocity (APIC, FLIP/PIC or AFLIP, seed Eq. 18) and position (seed Eq. 19)."""
    pts = s.points
    g = s.grid
    if s.velocity_update == "apic":
        flip = 0.0
    elif np.isfinite(s.relaxation_time):
        # the PIC share per unit time: the velocity a point carries beyond the grid's
        # field decays as exp(-t / relaxation_time), whatever the step
        flip = math.exp(-dt / s.relaxation_time)
    else:
        flip = s.flip
    g2p_kernel(s.v_mapped, s.v_new, affine_velocity(s), s.base, s.w, s.dw, g.nodes,
               s.ns, dt, flip, s.velocity_update != "flip", g.origin, g.upper, pts.x, pts.v,
               pts.C, s.chunk_vmax, s.chunk_out)
    n_out = int(s.chunk_out.sum())
    if g.periodic.any():
        g.wrap(pts.x)
    if s.walls:
        boundary.keep_behind_walls(s.walls, s.time, g, pts.x, pts.v)
        n_out = int(np.count_nonzero(~g.contains(pts.x)))
    # finiteness checked here, outside the fastmath kernel (its max drops a NaN); no NaN
    # enters a reduction, where MPI's MAX would give ranks different answers
    finite = bool(np.isfinite(pts.v).all() and np.isfinite(pts.x).all())
    vmax = float(s.chunk_vmax.max()) if pts.n and finite else 0.0
    g_max = s.comm.max([vmax if finite else np.inf, float(n_out)])
    s.vmax = float(g_max[0])
    if g_max[1] > 0 and not n_out:  # reported by the ranks that own them
        raise RemoteFailure(f"step {s.step}: material points of another rank left the grid")
    if n_out:
        out = np.flatnonzero(~g.contains(pts.x))
        ids = getattr(s, "point_ids", np.arange(pts.n))
        raise SimulationError(
            f"step {s.step}: {n_out} material point(s) left the grid, e.g. point "
            f"{int(ids[out[0]])} at {pts.x[out[0]].tolist()} (grid {g.origin.tolist()} .. "
            f"{g.upper.tolist()}); enlarge [grid] or constrain the boundary")
    if not np.isfinite(s.vmax):
        raise SimulationError(f"step {s.step}: non-finite point velocity (time step too large?)")


def remap_velocity(s: MPMState) -> None:
    """MUSL: grid velocity re-mapped from the updated point momenta (same S_Ip)."""
    pts = s.points
    x = s.x_start if s.velocity_update != "flip" else pts.x  # x unused when C = 0
    _, mom, _ = s.transfer.mass_momentum(pts.m, pts.v, pts.C, x, s.grid, s.base, s.w, s.ns)
    v = np.zeros_like(mom)
    a = s.active
    v[a] = mom[a] / s.mass[a, None]
    impose(s, v)
    if nodes_contact(s):
        v[s.rigid_nodes] = s.rigid_v
    s.v_new = v


def advance_rigid(s: MPMState, dt: float) -> None:
    if s.rigid is not None:
        s.rigid.advance(s.time, dt)


# --------------------------------------------------------------------------- step
def step(s: MPMState, dt: float) -> None:
    """One explicit step of size dt (s); USF, USL and MUSL differ only in where
    update_stress sits."""
    shape_functions(s)
    p2g(s)
    fluidity(s, dt)
    rigid_velocity(s, dt)
    grid_velocity(s)
    if s.scheme == "USF":
        update_stress(s, s.v_old, dt)
    rigid_penalty(s, dt)
    nodal_forces(s)
    integrate_grid(s, dt)
    g2p(s, dt)
    if s.scheme == "MUSL":
        remap_velocity(s)
    if s.scheme != "USF":
        update_stress(s, s.v_new, dt)
    advance_rigid(s, dt)
    s.last_dt = dt
    s.time += dt
    s.step += 1


def kinetic_energy(pts: Points) -> float:
    """sum_p m_p |v_p|^2 / 2, J. numpy's pairwise sum, not a BLAS dot product, whose
    result depends on the BLAS thread count."""
    return float(0.5 * np.sum(pts.m * np.einsum("ij,ij->i", pts.v, pts.v)))

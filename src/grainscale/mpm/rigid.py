"""A rigid body (box or cylinder) moving with a prescribed velocity history.

Velocity: zero before `start_time`, a linear ramp to `velocity` over `ramp_time`, then
constant. The body has no mass on the grid (its own inertia is irrelevant to a
prescribed motion). Two contact laws, `contact` in [rigid]:

**penalty**: the body is its exact shape, and each material point whose domain reaches
into it (signed distance phi of the point's centre to the surface, < 0 inside, below
its half-width l_p) is pushed out along the surface normal n by a
spring and dashpot,

    f_n = k_p g + c_p max(-(v_p - v_body) . n, 0),    g = l_p - phi > 0,
    k_p = kappa m_p (c_ref / (2 l_p))^2,               c_p = 2 zeta sqrt(k_p m_p),

never pulling (f_n >= 0), plus Coulomb friction against the relative tangential velocity
v_t, f_t = -min(mu f_n, m_p |v_t| / dt) v_t/|v_t| (at most the force that stops the
slip in one step). k_p is the point's own P-wave stiffness times kappa: a column of
material of the point's size, M (2 l_p)^2 / (2 l_p) with M = rho c_ref^2, c_ref the
largest wave speed at the run's first step (in the intrusion cases the geostatic
stage's start), kept in checkpoints. Its period 4 pi l_p / (sqrt(kappa) c_ref) bounds
the time step (critical_dt). The force of the material on the body is minus the
sum of the contact forces. The contact surface is the body's own and one-sided, with or
without friction; the reaction still ripples as the material around the body crosses
cells (docs/mpm.md: rigid body).

**nodes** (the default): the body imposes its velocity on the grid nodes its points' domains cover
(|x_I - x_p| <= l_p per axis, the points filling the shape); no slip, never separating.
Its reaction is, per covered node with material mass m_I, momentum p_I and force f_I,
F_I = (m_I v_body - p_I)/dt - f_I; the force on the body is -sum F_I. Marking every node
within the shape functions' support instead would reach a cell beyond the surface and
stiffen the contact (a test caught a 33 % excess). The contact surface advances node
plane by node plane: the reaction of a moving body ripples with the period of one cell
in depth (+-25 % at 4 cells over the radius).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from grainscale.mpm.grid import Grid
from grainscale.mpm.transfer import mark_covered_nodes_kernel, mark_covered_nodes_rectilinear

BOX, CYLINDER = 0, 1


@njit(cache=True)
def signed_distance(kind, geom, x, normal):
    """Signed distance [m] from x to the body's surface (< 0 inside) and the outward
    unit normal of the nearest surface point, written to `normal`.

    Box: geom = (lo, hi). Cylinder: geom = (base centre, axis unit vector, radius, height),
    its wall and its two flat ends (exact distance to the solid, edges included).
    """
    if kind == BOX:
        dmax = -np.inf
        amax = 0
        out2 = 0.0
        for a in range(3):
            c = 0.5 * (geom[a] + geom[3 + a])
            half = 0.5 * (geom[3 + a] - geom[a])
            q = x[a] - c
            d = abs(q) - half
            normal[a] = math.copysign(max(d, 0.0), q)
            out2 += max(d, 0.0) ** 2
            if d > dmax:
                dmax = d
                amax = a
        if out2 > 0.0:
            r = math.sqrt(out2)
            for a in range(3):
                normal[a] /= r
            return r
        for a in range(3):
            normal[a] = 0.0
        normal[amax] = math.copysign(1.0, x[amax] - 0.5 * (geom[amax] + geom[3 + amax]))
        return dmax
    # cylinder
    u = 0.0
    for a in range(3):
        u += (x[a] - geom[a]) * geom[3 + a]
    rad = np.empty(3)
    rho = 0.0
    for a in range(3):
        rad[a] = x[a] - geom[a] - u * geom[3 + a]
        rho += rad[a] ** 2
    rho = math.sqrt(rho)
    if rho > 0.0:
        for a in range(3):
            rad[a] /= rho
    else:  # on the axis: any radial direction (only used when the wall is nearest)
        k = 0 if abs(geom[3]) < 0.9 else 1
        for a in range(3):
            rad[a] = (1.0 if a == k else 0.0) - geom[3 + a] * geom[3 + k]
        nr = math.sqrt(rad[0] ** 2 + rad[1] ** 2 + rad[2] ** 2)
        for a in range(3):
            rad[a] /= nr
    radius, height = geom[6], geom[7]
    dr = rho - radius
    below = u < 0.5 * height
    du = -u if below else u - height
    sa = -1.0 if below else 1.0
    if dr > 0.0 or du > 0.0:
        pr, pu = max(dr, 0.0), max(du, 0.0)
        r = math.sqrt(pr * pr + pu * pu)
        for a in range(3):
            normal[a] = (pr * rad[a] + pu * sa * geom[3 + a]) / r
        return r
    if dr > du:
        for a in range(3):
            normal[a] = rad[a]
        return dr
    for a in range(3):
        normal[a] = sa * geom[3 + a]
    return du


@njit(cache=True)
def penalty_kernel(kind, geom, vbody, x, v, m, lp, omega2, damping_ratio, friction, dt,
                   ids, force, where):
    """Penalty contact forces (see the module docstring) on the points in contact: their
    ids, the force on each [N] and where it acts, the point's face toward the body
    x_p - l_p n [m], written to the first `count` rows of ids, force and where.
    omega2 = kappa (c_ref / 2)^2 [m^2/s^2], so k_p = m_p omega2 / l_p^2. l_p is the
    domain's half-extent along n (points.half_extent): its half-width for a cube, else
    sqrt(sum_a (lp_a n_a)^2) of the box lp (P,3). Returns count."""
    n = np.empty(3)
    count = 0
    for p in range(x.shape[0]):
        phi = signed_distance(kind, geom, x[p], n)
        l = lp[p, 0]
        if lp[p, 1] != l or lp[p, 2] != l:
            l = math.sqrt((lp[p, 0] * n[0]) ** 2 + (lp[p, 1] * n[1]) ** 2
                          + (lp[p, 2] * n[2]) ** 2)
        g = l - phi
        if g <= 0.0:
            continue
        k = m[p] * omega2 / (l * l)
        rel0 = v[p, 0] - vbody[0]
        rel1 = v[p, 1] - vbody[1]
        rel2 = v[p, 2] - vbody[2]
        vn = rel0 * n[0] + rel1 * n[1] + rel2 * n[2]
        fn = k * g + 2.0 * damping_ratio * math.sqrt(k * m[p]) * max(-vn, 0.0)
        t0 = rel0 - vn * n[0]
        t1 = rel1 - vn * n[1]
        t2 = rel2 - vn * n[2]
        vt = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        ft = min(friction * fn, m[p] * vt / dt) / vt if vt > 0.0 else 0.0
        ids[count] = p
        force[count, 0] = fn * n[0] - ft * t0
        force[count, 1] = fn * n[1] - ft * t1
        force[count, 2] = fn * n[2] - ft * t2
        for a in range(3):
            where[count, a] = x[p, a] - l * n[a]
        count += 1
    return count


def cross_section(kind: int, geom: np.ndarray, axis: int, glo: np.ndarray,
                  ghi: np.ndarray) -> tuple[float, float]:
    """The body's cross-section normal to grid axis `axis` (its direction of motion):
    (S, R), S the area inside the grid's extent [m^2] and R its radius [m]: the
    cylinder's own if its axis is the motion's, else the equivalent radius
    sqrt(S_full / pi) of the whole section S_full = 2^k S, k the grid faces the shape
    reaches (each taken as a symmetry plane: R_e = sqrt(4 S / pi) for a quarter model,
    seed §4.3)."""
    a, b = [k for k in range(3) if k != axis]
    if kind == BOX or abs(geom[3 + axis]) < 0.5:  # a rectangle
        if kind == BOX:
            lo, hi = geom[:3].copy(), geom[3:6].copy()
        else:  # a cylinder lying across the motion
            c, ax = geom[:3], int(np.argmax(np.abs(geom[3:6])))
            lo, hi = c - geom[6], c + geom[6]
            lo[ax], hi[ax] = c[ax], c[ax] + geom[7]
        ext = [(lo[k], hi[k]) for k in (a, b)]
        area = float(np.prod([max(0.0, min(h, ghi[k]) - max(l, glo[k]))
                              for (l, h), k in zip(ext, (a, b), strict=True)]))
        disc = False
    else:  # a disc: integrate its chords inside the grid (20,000 strips: 1e-7 relative)
        c, r = geom[:3], geom[6]
        x0, x1 = max(c[a] - r, glo[a]), min(c[a] + r, ghi[a])
        n = 20000
        xm = x0 + (np.arange(n) + 0.5) * (x1 - x0) / n
        half = np.sqrt(np.maximum(r * r - (xm - c[a]) ** 2, 0.0))
        chord = np.clip(c[b] + half, glo[b], ghi[b]) - np.clip(c[b] - half, glo[b], ghi[b])
        area = float(chord.sum() * (x1 - x0) / n) if x1 > x0 else 0.0
        lo, hi = c - r, c + r
        ext = [(lo[k], hi[k]) for k in (a, b)]
        disc = True
    tol = 1e-9 * float(np.max(ghi - glo))
    cut = sum(int(l <= glo[k] + tol) + int(h >= ghi[k] - tol)
              for (l, h), k in zip(ext, (a, b), strict=True))
    radius = float(geom[6]) if disc else math.sqrt(area * 2 ** cut / math.pi)
    return area, radius


@dataclass
class RigidBody:
    x: np.ndarray  # (R,3) m, points filling the body (frames; `nodes` contact)
    lp: np.ndarray  # (R,) m, their half-widths; per axis (R,3) on a rectilinear grid
    velocity: np.ndarray  # (3,) m/s, final velocity
    ramp_time: float = 0.0  # s
    start_time: float = 0.0  # s
    kind: int = BOX  # BOX or CYLINDER
    geom: np.ndarray = field(default_factory=lambda: np.zeros(8))  # at rest; signed_distance
    contact: str = "nodes"  # or "penalty"
    penalty: float = 1.0  # kappa
    damping_ratio: float = 0.0  # zeta
    friction: float = 0.0  # mu of the body's surface
    wave_speed_ref: float = 0.0  # m/s, c_ref; 0 until the run's first step sets it
    displacement: np.ndarray = field(default_factory=lambda: np.zeros(3))  # m
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))  # N, material on body
    in_contact: int = 0  # points in penalty contact in the last step
    area: float = math.nan  # m^2, cross-section normal to the motion, inside the grid
    radius: float = math.nan  # m, its (equivalent) radius R (cross_section)

    def velocity_at(self, t: float) -> np.ndarray:
        if t <= self.start_time:
            return np.zeros(3)
        if self.ramp_time > 0.0 and t < self.start_time + self.ramp_time:
            return self.velocity * ((t - self.start_time) / self.ramp_time)
        return self.velocity.copy()

    def covered_nodes(self, grid: Grid) -> np.ndarray:
        """Ids of the nodes the body covers at its current position (`nodes` contact)."""
        mark = np.zeros(grid.n_nodes, dtype=np.bool_)
        if grid.axes is not None:
            mark_covered_nodes_rectilinear(self.x, self.lp, grid.axes, mark)
            return np.flatnonzero(mark)
        mark_covered_nodes_kernel(self.x, self.lp, grid.origin, grid.cell_size, grid.cells,
                                  mark)
        return np.flatnonzero(mark)

    def penalty_forces(self, x, v, m, lp, t: float, dt: float):
        """Contact forces on the points at time t (body velocity at t): (point ids (k,),
        forces (k,3) [N], where they act (k,3) [m])."""
        P = x.shape[0]
        ids = np.empty(P, dtype=np.int64)
        force = np.empty((P, 3))
        where = np.empty((P, 3))
        omega2 = self.penalty * (0.5 * self.wave_speed_ref) ** 2
        k = int(penalty_kernel(self.kind, self.geometry(), self.velocity_at(t), x, v, m, lp,
                               omega2, self.damping_ratio, self.friction, dt, ids, force,
                               where))
        self.in_contact = k
        return ids[:k], force[:k], where[:k]

    def geometry(self) -> np.ndarray:
        """The shape's parameters at the current displacement (see signed_distance)."""
        g = self.geom.copy()
        g[:3] += self.displacement
        if self.kind == BOX:
            g[3:6] += self.displacement
        return g

    def critical_dt(self, lp_min: float) -> float:
        """The period bound 2 / omega of the stiffest contact spring [s]."""
        if self.contact != "penalty" or self.wave_speed_ref <= 0.0:
            return math.inf
        return 4.0 * lp_min / (math.sqrt(self.penalty) * self.wave_speed_ref)

    def advance(self, t: float, dt: float) -> None:
        """Move the body from t to t + dt (midpoint velocity: exact for the ramp)."""
        d = dt * self.velocity_at(t + 0.5 * dt)
        self.x += d
        self.displacement += d

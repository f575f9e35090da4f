"""State of a batch of periodic RVEs in structure-of-arrays form.

A batch holds R RVEs of N spheres each; every array has the RVE index first, so one RVE
alone and the same RVE inside a batch are the same data. Positions are fractional
coordinates `s` (see cell.py); velocities `v` are the *fluctuating* part (the mean-field
velocity L x is added where a relative velocity needs it).

Neighbour lists are half lists with a fixed capacity K per particle: row i holds the
particles j > i closer than r_i + r_j + skin at the last build, each with its image
shift encoded as one byte (27 values, 13 = no shift) and its contact history `ft`: the
tangential force on i [N] and, with rolling resistance, the rolling moment on j [N m]
(HISTORY_ROLLING components; without it the moments take no memory). Capacity is regrown
outside compiled code on overflow.

Clumps (rigid grains of overlapping spheres, dem/clump.py): the spheres are the clumps'
members, and the arrays prefixed `b` hold B bodies per RVE (B = 0: a packing of plain
spheres, every clump array empty). A member's s, v and w are then set from its body every
step (dem/rigid.py): its fluctuating velocity is that of its body's material point,
v'_i = V' + omega' x r_i - D r_i (r_i = R rho_i its lab offset), and its spin the body's
omega' = omega - W. Members keep their body's mass, the mass that meets a collision
(the normal dashpot's m*).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

HISTORY = 3          # components of a contact's history: the tangential force
HISTORY_ROLLING = 6  # ... and the rolling moment (rolling resistance on)

# per-RVE arrays that define the physical state (saved in checkpoints and .h5 files)
STATE_FIELDS = ("h", "s", "v", "w", "rot", "radius", "mass", "inertia", "L", "stress",
                "stress_servo", "step_count", "stiffness", "h0", "nbr_j", "nbr_shift",
                "nbr_count", "ft", "s_ref", "h_ref", "need_rebuild", "ncontact", "unbalanced",
                "kinetic")


@dataclass
class RVEBatch:
    """Arrays of R RVEs x N spheres; K is the neighbour capacity per sphere."""

    h: np.ndarray            # (R,3,3) cell matrix, edge vectors as columns [m]
    s: np.ndarray            # (R,N,3) fractional positions (unwrapped between list builds)
    v: np.ndarray            # (R,N,3) fluctuating velocity [m/s]
    w: np.ndarray            # (R,N,3) angular velocity about the mean-field spin [rad/s]
    rot: np.ndarray          # (R,N) accumulated rolling angle, integral of |w| dt [rad]
    radius: np.ndarray       # (R,N) [m]
    mass: np.ndarray         # (R,N) [kg]
    inertia: np.ndarray      # (R,N) moment of inertia 2/5 m r^2 [kg m^2]
    L: np.ndarray            # (R,3,3) mean-field velocity gradient of the last step [1/s]
    stress: np.ndarray       # (R,3,3) Love-Weber Cauchy stress, tension positive [Pa], of
    #                          the state the last call ended in
    stress_servo: np.ndarray  # (R,3,3) the stress the servo last sampled [Pa]
    step_count: np.ndarray   # (R,) int64 DEM steps taken (the servo samples on it)
    stiffness: np.ndarray    # (R,3,3) affine moduli C_aabb [Pa]: under a servo its last
    #                          sample (normal springs only); else those of the state a call
    #                          ends in, kn, kt and the forces' turning (MPM wave speed;
    #                          kernel.contact_pass)
    h0: np.ndarray           # (R,3,3) reference cell for eps_v = ln(V/V0)
    nbr_j: np.ndarray        # (R,N,K) int32 neighbour index
    nbr_shift: np.ndarray    # (R,N,K) uint8 image shift code
    nbr_count: np.ndarray    # (R,N) int32 entries used in each row
    ft: np.ndarray           # (R,N,K,C) contact history: [:3] tangential force on i [N];
    #                          with rolling resistance (C = 6) [3:] the rolling moment,
    #                          the torque on j (-it on i) [N m]
    s_ref: np.ndarray        # (R,N,3) positions at the last list build
    h_ref: np.ndarray        # (R,3,3) cell at the last list build
    need_rebuild: np.ndarray  # (R,) int32, 1 = build the list before the next step
    # scratch (not state): forces, torques, Cartesian positions, cell-list links
    force: np.ndarray        # (R,N,3)
    torque: np.ndarray       # (R,N,3)
    x: np.ndarray            # (R,N,3)
    link: np.ndarray         # (R,N+1+N) int32: cell-list heads then next pointers
    wrapv: np.ndarray        # (R,N,3) int32 image counts removed at the last wrap
    ncontact: np.ndarray     # (R,) int32 contacts at the last step
    unbalanced: np.ndarray   # (R,) unbalanced-force ratio at the last step
    kinetic: np.ndarray      # (R,) fluctuating kinetic energy at the last step [J]
    # clumps (module docstring; B = 0 and every array empty for plain spheres)
    body: np.ndarray         # (R,N) int32 the body of each member sphere
    rho: np.ndarray          # (R,N,3) member centre in its body's principal frame [m]
    image: np.ndarray        # (R,N,3) s_i - (S_b + h^-1 R rho_i), integers fixed at a build
    off: np.ndarray          # (R,N,3) scratch: R rho_i, the member's lab offset [m]
    bs: np.ndarray           # (R,B,3) body centre of mass, fractional
    bv: np.ndarray           # (R,B,3) its fluctuating velocity V' [m/s]
    bw: np.ndarray           # (R,B,3) its angular velocity about the mean-field spin [rad/s]
    bq: np.ndarray           # (R,B,4) orientation, unit quaternion body -> lab
    bl: np.ndarray           # (R,B,3) angular momentum of the spin bw, I bw [kg m^2/s]
    bm: np.ndarray           # (R,B) mass [kg]
    bj: np.ndarray           # (R,B,3) principal moments of inertia [kg m^2]
    bvol: np.ndarray         # (R,B) solid volume of the union of its spheres [m^3]

    @property
    def clumped(self) -> bool:
        """True if the spheres are members of clumps (bodies)."""
        return self.bm.shape[1] > 0

    @property
    def n_bodies(self) -> int:
        """Bodies per RVE: clumps, or the spheres themselves."""
        return self.bm.shape[1] if self.clumped else self.s.shape[1]

    def solid_volume(self) -> np.ndarray:
        """Solid volume of each RVE's grains, (R,) [m^3] (a clump's members overlap: the
        volume of their union)."""
        if self.clumped:
            return self.bvol.sum(axis=1)
        return (4.0 / 3.0) * np.pi * np.sum(self.radius**3, axis=1)

    @property
    def n_rve(self) -> int:
        return self.s.shape[0]

    @property
    def n_particles(self) -> int:
        return self.s.shape[1]

    @property
    def capacity(self) -> int:
        return self.nbr_j.shape[2]

    def volume(self) -> np.ndarray:
        """Cell volumes det h, (R,) [m^3]."""
        return np.linalg.det(self.h)

    def porosity(self) -> np.ndarray:
        """1 - solid volume / cell volume, (R,)."""
        return 1.0 - self.solid_volume() / self.volume()

    def copy(self) -> RVEBatch:
        return RVEBatch(**{f.name: getattr(self, f.name).copy() for f in fields(self)})

    def take(self, index) -> RVEBatch:
        """A new batch made of the RVEs `index` (list or slice), copied."""
        idx = np.atleast_1d(np.arange(self.n_rve)[index])
        return RVEBatch(**{f.name: getattr(self, f.name)[idx].copy() for f in fields(self)})


def allocate(n_rve: int, n_particles: int, capacity: int = 16,
             history: int = HISTORY, n_bodies: int = 0) -> RVEBatch:
    """Zeroed arrays for a batch; identity cells; `history` components per contact;
    n_bodies clumps per RVE (0: plain spheres)."""
    r, n, k = n_rve, n_particles, capacity
    m = n if n_bodies > 0 else 0  # members have clump arrays only in a clumped batch
    nb = n_bodies
    q0 = np.zeros((r, nb, 4))
    q0[..., 0] = 1.0
    eye = np.broadcast_to(np.eye(3), (r, 3, 3)).copy()
    return RVEBatch(
        h=eye.copy(), s=np.zeros((r, n, 3)), v=np.zeros((r, n, 3)), w=np.zeros((r, n, 3)),
        rot=np.zeros((r, n)), radius=np.zeros((r, n)), mass=np.zeros((r, n)),
        inertia=np.zeros((r, n)), L=np.zeros((r, 3, 3)), stress=np.zeros((r, 3, 3)),
        stress_servo=np.zeros((r, 3, 3)), step_count=np.zeros(r, np.int64),
        stiffness=np.zeros((r, 3, 3)), h0=eye.copy(),
        nbr_j=np.zeros((r, n, k), np.int32), nbr_shift=np.full((r, n, k), 13, np.uint8),
        nbr_count=np.zeros((r, n), np.int32), ft=np.zeros((r, n, k, history)),
        s_ref=np.zeros((r, n, 3)), h_ref=eye.copy(), need_rebuild=np.ones(r, np.int32),
        force=np.zeros((r, n, 3)), torque=np.zeros((r, n, 3)), x=np.zeros((r, n, 3)),
        link=np.zeros((r, 2 * n + 1), np.int32), wrapv=np.zeros((r, n, 3), np.int32),
        ncontact=np.zeros(r, np.int32), unbalanced=np.zeros(r), kinetic=np.zeros(r),
        body=np.zeros((r, m), np.int32), rho=np.zeros((r, m, 3)), image=np.zeros((r, m, 3)),
        off=np.zeros((r, m, 3)), bs=np.zeros((r, nb, 3)), bv=np.zeros((r, nb, 3)),
        bw=np.zeros((r, nb, 3)), bq=q0, bl=np.zeros((r, nb, 3)), bm=np.zeros((r, nb)),
        bj=np.zeros((r, nb, 3)), bvol=np.zeros((r, nb)),
    )


def from_packing(h: np.ndarray, positions: np.ndarray, radii: np.ndarray, density: float,
                 n_copies: int = 1, capacity: int = 16, history: int = HISTORY) -> RVEBatch:
    """A batch of `n_copies` identical RVEs from a packing (cell, centres [m], radii [m]),
    at rest, `history` components per contact."""
    n = len(radii)
    b = allocate(n_copies, n, capacity, history)
    s = np.linalg.solve(h, np.asarray(positions, float).T).T
    s -= np.floor(s)
    m = density * (4.0 / 3.0) * np.pi * radii**3
    _place(b, h, s, radii, m, 0.4 * m * radii**2)
    return b


def _place(b: RVEBatch, h, s, radius, mass, inertia) -> None:
    """Every RVE of b at rest in cell h (also its reference and build cell) with the
    spheres at fractional s."""
    b.h[:] = h
    b.h0[:] = h
    b.h_ref[:] = h
    b.s[:] = s
    b.radius[:] = radius
    b.mass[:] = mass
    b.inertia[:] = inertia


def from_clumps(h: np.ndarray, centres: np.ndarray, quats: np.ndarray, grains: list,
                density: float, n_copies: int = 1, capacity: int = 16,
                history: int = HISTORY) -> RVEBatch:
    """A batch of `n_copies` identical RVEs of B clumps at rest: centres of mass (B,3) [m],
    orientations (B,4) (unit quaternions body -> lab) and one scaled clump.Template per
    body (`grains`, B of them; they may repeat). Members are numbered body by body and
    placed at x = X_b + R(q_b) rho_k; their contact lists are built by the kernel."""
    from grainscale.dem.quaternion import matrix  # noqa: PLC0415 (numba import cost)

    centres = np.asarray(centres, float).reshape(-1, 3)
    quats = np.asarray(quats, float).reshape(-1, 4)
    nb = len(grains)
    if centres.shape[0] != nb or quats.shape[0] != nb:
        raise ValueError(f"{nb} grains for {centres.shape[0]} centres and "
                         f"{quats.shape[0]} orientations")
    n = sum(len(g.radii) for g in grains)
    b = allocate(n_copies, n, capacity, history, n_bodies=nb)
    hinv = np.linalg.inv(h)
    rot = np.empty((3, 3))
    body = np.empty(n, np.int32)
    rho = np.empty((n, 3))
    radius = np.empty(n)
    off = np.empty((n, 3))
    at = 0
    for k, g in enumerate(grains):
        q = quats[k] / np.linalg.norm(quats[k])
        quats[k] = q
        matrix(q, rot)
        m = len(g.radii)
        body[at:at + m] = k
        rho[at:at + m] = g.offsets
        radius[at:at + m] = g.radii
        off[at:at + m] = g.offsets @ rot.T
        at += m
    sb = centres @ hinv.T
    sb -= np.floor(sb)
    s = sb[body] + off @ hinv.T
    bm = density * np.array([g.volume for g in grains])
    bj = density * np.array([g.inertia for g in grains])
    _place(b, h, s, radius, bm[body], bj.min(axis=1)[body])
    b.body[:] = body
    b.rho[:] = rho
    b.off[:] = off
    b.bs[:] = sb
    b.bq[:] = quats
    b.bm[:] = bm
    b.bj[:] = bj
    b.bvol[:] = [g.volume for g in grains]
    return b


def from_members(h: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                 bodies: np.ndarray, density: float, n_copies: int = 1, capacity: int = 16,
                 history: int = HISTORY) -> RVEBatch:
    """A clumped batch from member spheres (centres [m], radii [m]) and the clump of each
    (bodies, ids 0..B-1, as io/packing.read_members gives them): each clump's members
    taken to one periodic image (nearest to its first member's), its mass properties
    those of their union (clump.from_members)."""
    from grainscale.dem import clump  # noqa: PLC0415 (numba import cost)

    centres = np.asarray(centres, float)
    bodies = np.asarray(bodies, np.int64)
    ids = np.unique(bodies)
    if not np.array_equal(ids, np.arange(ids.size)):
        raise ValueError(f"clump ids must be 0..B-1 without gaps; got {ids.size} ids up to "
                         f"{int(ids.max())}")
    hinv = np.linalg.inv(h)
    clumps = []
    for k in ids:
        x = centres[bodies == k]
        f = (x - x[0]) @ hinv.T
        x = x[0] + (f - np.round(f)) @ h.T  # one image
        clumps.append(clump.from_members(x, radii[bodies == k]))
    grains, com, quats = zip(*clumps, strict=True)
    return from_clumps(h, np.array(com), np.array(quats), list(grains), density, n_copies,
                       capacity, history)


def member_positions(b: RVEBatch, r: int = 0) -> np.ndarray:
    """(N,3) member centres [m] of RVE r of a clumped batch, each clump's centre wrapped
    into the cell and its members about it (the exchange format's layout)."""
    from grainscale.dem.quaternion import matrix  # noqa: PLC0415

    h = b.h[r]
    centre = (b.bs[r] - np.floor(b.bs[r])) @ h.T
    rot = np.empty((b.n_bodies, 3, 3))
    for k in range(b.n_bodies):
        matrix(b.bq[r, k], rot[k])
    return centre[b.body[r]] + np.einsum("nab,nb->na", rot[b.body[r]], b.rho[r])


def body_lever(b: RVEBatch) -> np.ndarray:
    """(R,B) the largest distance from a body's centre of mass to its surface,
    max_k |rho_k| + r_k [m] (the lever a contact force turns a clump with)."""
    lever = np.zeros(b.bm.shape)
    reach = np.linalg.norm(b.rho, axis=2) + b.radius
    for r in range(b.n_rve):
        np.maximum.at(lever[r], b.body[r], reach[r])
    return lever


def concatenate(batches: list[RVEBatch]) -> RVEBatch:
    """One batch of all RVEs of `batches` (same N; capacity grown to the largest)."""
    k = max(b.capacity for b in batches)
    batches = [grow_capacity(b.copy(), k) for b in batches]
    return RVEBatch(**{f.name: np.concatenate([getattr(b, f.name) for b in batches])
                       for f in fields(RVEBatch)})


def remove_rves(b: RVEBatch, index) -> tuple[RVEBatch, np.ndarray]:
    """`b` without the RVEs `index`, made in place: the last RVEs that stay are moved
    into the slots of those removed (only they are copied), and the batch returned is a
    view of the first R - k rows of b's arrays (b itself is left with its rows moved).
    Where fewer than half of b's rows would stay, a compact copy is returned instead,
    so that memory follows the batch. Returns (batch, order) with order[i] the index in
    b of the returned batch's RVE i."""
    gone = np.unique(np.asarray(index, np.int64))
    keep = b.n_rve - gone.size
    if keep < 0.5 * b.n_rve:
        order = np.setdiff1d(np.arange(b.n_rve), gone)
        return b.take(order), order
    holes = gone[gone < keep]
    movers = np.setdiff1d(np.arange(keep, b.n_rve), gone)  # as many as holes
    order = np.arange(keep)
    order[holes] = movers
    for f in fields(RVEBatch):
        a = getattr(b, f.name)
        a[holes] = a[movers]
    return RVEBatch(**{f.name: getattr(b, f.name)[:keep] for f in fields(RVEBatch)}), order


GROWTH = 1.5  # spare rows a batch gets when RVEs are appended to it (extend)


def extend(b: RVEBatch, new: list[RVEBatch], storage: RVEBatch | None = None
           ) -> tuple[RVEBatch, RVEBatch]:
    """The RVEs of b followed by those of `new` (same N; capacities grown to the
    largest), as a view of the first rows of a storage batch with spare rows: appending
    again writes into the spare rows while they last (no copy of b), and a full storage
    is replaced by one GROWTH times the rows needed, so that a batch grown one RVE at a
    time is copied O(log) times, not every time. `storage`: the batch b is a view of,
    from the last call (ignored unless b's arrays all lie at its start). Returns
    (batch, storage)."""
    k = max(x.capacity for x in [b, *new])
    grow_capacity(b, k)
    new = [grow_capacity(x.copy(), k) for x in new]
    r0, r1 = b.n_rve, b.n_rve + sum(x.n_rve for x in new)
    names = [f.name for f in fields(RVEBatch)]
    fits = (storage is not None and storage.n_rve >= r1 and storage.capacity == k
            and all(getattr(b, f).base is getattr(storage, f) for f in names))
    if not fits:
        rows = max(r1, int(GROWTH * r1))
        storage = RVEBatch(**{f: np.empty((rows, *getattr(b, f).shape[1:]),
                                          getattr(b, f).dtype) for f in names})
        for f in names:
            getattr(storage, f)[:r0] = getattr(b, f)
    at = r0
    for x in new:
        for f in names:
            getattr(storage, f)[at:at + x.n_rve] = getattr(x, f)
        at += x.n_rve
    return RVEBatch(**{f: getattr(storage, f)[:r1] for f in names}), storage


def grow_capacity(b: RVEBatch, capacity: int) -> RVEBatch:
    """Grow the neighbour capacity of `b` in place to `capacity`; lists and history kept."""
    r, n, k = b.nbr_j.shape
    if capacity <= k:
        return b
    nbr_j = np.zeros((r, n, capacity), np.int32)
    nbr_shift = np.full((r, n, capacity), 13, np.uint8)
    ft = np.zeros((r, n, capacity, b.ft.shape[3]))
    nbr_j[:, :, :k] = b.nbr_j
    nbr_shift[:, :, :k] = b.nbr_shift
    ft[:, :, :k] = b.ft
    b.nbr_j, b.nbr_shift, b.ft = nbr_j, nbr_shift, ft
    return b


def with_history(b: RVEBatch, history: int) -> RVEBatch:
    """`b` with `history` components per contact (HISTORY or HISTORY_ROLLING): a batch
    without rolling moments gets zero moments (a state with no rolling history, as a
    packing generated without rolling resistance has); dropping moments a batch holds is
    refused (ValueError), since its state was in equilibrium with them."""
    c = b.ft.shape[3]
    if c == history:
        return b
    if c > history:
        if np.any(b.ft[..., history:] != 0.0):
            raise ValueError("the batch holds rolling moments: it was made with rolling "
                             "resistance, which this use switches off")
        b.ft = np.ascontiguousarray(b.ft[..., :history])
        return b
    ft = np.zeros((*b.ft.shape[:3], history))
    ft[..., :c] = b.ft
    b.ft = ft
    return b


# the clump arrays that define a clumped batch's state (`off` is scratch): per member
# sphere (axis 1 the spheres') and per body (axis 1 the bodies')
MEMBER_FIELDS = ("body", "rho", "image")
BODY_FIELDS = ("bs", "bv", "bw", "bq", "bl", "bm", "bj", "bvol")
CLUMP_FIELDS = MEMBER_FIELDS + BODY_FIELDS


def state_arrays(b: RVEBatch) -> dict[str, np.ndarray]:
    """The arrays that define the physical state (for HDF5 and checkpoints): those of
    STATE_FIELDS, and CLUMP_FIELDS for a clumped batch."""
    names = STATE_FIELDS + (CLUMP_FIELDS if b.clumped else ())
    return {name: getattr(b, name) for name in names}


# state fields with a per-sphere axis (axis 1) and with a neighbour-slot axis (axis 2)
SPHERE_FIELDS = ("s", "v", "w", "rot", "radius", "mass", "inertia", "nbr_j", "nbr_shift",
                 "nbr_count", "ft", "s_ref")
SLOT_FIELDS = ("nbr_j", "nbr_shift", "ft")
# every RVEBatch array with a per-sphere axis, scratch included (the rest are per RVE)
SPHERE_AXIS_FIELDS = SPHERE_FIELDS + ("force", "torque", "x", "link", "wrapv")


def longest_row(batches: list[RVEBatch]) -> int:
    """The most neighbour entries any sphere of `batches` holds (0 for none)."""
    return max((int(b.nbr_count.max(initial=0)) for b in batches), default=0)


def rve_constants(b: RVEBatch) -> dict[str, np.ndarray]:
    """Per-RVE constants of a batch, (R,) each: mean grain radius [m] (a clump's: its
    reach from its centre, body_lever, half its longest extent: the size that decides
    when a cell is too thin for it), grain mass [kg] and solid volume [m^3] (what
    per-RVE quantities need from the spheres)."""
    size, mass = (body_lever(b), b.bm) if b.clumped else (b.radius, b.mass)
    return {"mean_radius": size.mean(axis=1), "grain_mass": mass.sum(axis=1),
            "solid_volume": b.solid_volume()}


def with_capacity(b: RVEBatch, capacity: int) -> RVEBatch:
    """`b` with exactly `capacity` neighbour slots per sphere, in place: grown
    (grow_capacity), or cut where every row fits (the slots past a row's count are never
    read); ValueError if a row holds more entries than `capacity`."""
    if capacity >= b.capacity:
        return grow_capacity(b, capacity)
    longest = longest_row([b])
    if longest > capacity:
        raise ValueError(f"list capacity {capacity}: a row holds {longest} entries")
    b.nbr_j = np.ascontiguousarray(b.nbr_j[:, :, :capacity])
    b.nbr_shift = np.ascontiguousarray(b.nbr_shift[:, :, :capacity])
    b.ft = np.ascontiguousarray(b.ft[:, :, :capacity])
    return b


def padded(arrays: dict[str, np.ndarray], n: int, k: int,
           n_bodies: int = 0) -> dict[str, np.ndarray]:
    """`state_arrays` of RVEs with up to n spheres (and, clumped, up to n_bodies bodies),
    zero-padded to exactly n spheres, k neighbour slots and n_bodies bodies, so RVEs of
    different sizes fit in one table (checkpoints). The padding is inert: empty neighbour
    rows, spheres of zero radius, bodies of zero mass, cut off on reading. Slots beyond k
    are dropped: k must be at least every row's nbr_count (the slots past a row's count
    are never read)."""
    out = {}
    for name, v in arrays.items():
        if name in SLOT_FIELDS and v.shape[2] > k:
            v = v[:, :, :k]
        shape = list(v.shape)
        if name in SPHERE_FIELDS or name in MEMBER_FIELDS:
            shape[1] = n
        if name in BODY_FIELDS:
            shape[1] = n_bodies
        if name in SLOT_FIELDS:
            shape[2] = k
        if shape == list(v.shape):
            out[name] = v
            continue
        fill = 13 if name == "nbr_shift" else 0  # 13: the image code of no shift
        w = np.full(shape, fill, v.dtype)
        w[tuple(slice(0, m) for m in v.shape)] = v
        out[name] = w
    return out


def unpadded(arrays: dict[str, np.ndarray], n: int,
             n_bodies: int = 0) -> dict[str, np.ndarray]:
    """The first n spheres (and n_bodies bodies) of padded state arrays (RVEs that all
    have n spheres and n_bodies bodies)."""
    def cut(name, v):
        if name in SPHERE_FIELDS or name in MEMBER_FIELDS:
            return v[:, :n]
        return v[:, :n_bodies] if name in BODY_FIELDS else v

    return {name: cut(name, v) for name, v in arrays.items()}


def from_state_arrays(arrays: dict[str, np.ndarray]) -> RVEBatch:
    """Rebuild a batch from `state_arrays` output; scratch is re-allocated (a clumped
    batch's member offsets by the kernel's next call)."""
    r, n, k = arrays["nbr_j"].shape
    n_bodies = arrays["bm"].shape[1] if "bm" in arrays else 0
    b = allocate(r, n, k, n_bodies=n_bodies)
    for name in STATE_FIELDS + (CLUMP_FIELDS if n_bodies else ()):
        setattr(b, name, np.array(arrays[name], dtype=getattr(b, name).dtype))
    return b

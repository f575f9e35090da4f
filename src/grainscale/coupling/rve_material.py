"""The DEM RVE as an MPM material: one periodic assembly per material point (seed §2).

Each MPM step hands every point's full incremental displacement gradient dH (spin
included, seed Eq. 17) to its RVE: the cell is deformed h <- (I + dH) h over a whole
number of DEM steps, and the symmetric part of the homogenised Love-Weber stress (seed
Eq. 11) goes back to the point. The RVEs of all points are one batch, stepped in
parallel over RVEs.

Time integration (docs/coupling.md):
- "dynamic" (default): the RVE lives in real time. The MPM step dt is split into
  n = max(min_substeps, ceil(dt / dt_crit)) equal DEM steps, dt_DEM = dt / n <= dt_crit
  = safety sqrt(m_min/k_max), so the strain rate the grains see is the MPM's.
- "quasi_static": the increment is applied over n = ceil(max|dH| / strain_per_substep)
  DEM steps of dt_crit, independent of the MPM dt (as FEMxDEM codes do): the RVE is
  loaded at a fixed, slow strain per DEM step, whatever the macroscopic rate.
After each increment, cells sheared thin are re-expressed by a compact basis
(dem/lattice.py), so strongly deformed RVEs keep their history instead of being reset.

With device "cuda" the RVEs' state stays on the GPU for the whole run
(dem/device_batch.py): each update sends the increments down and brings the stress,
stiffness, cell and counts up; the rest of the state comes to the host only where it is
read (`state` for checkpoints, `rve` for probes, cell reduction and retiling of the RVEs
concerned). The batch is built there (DeviceBatch.from_library: the library's packings
copied on the device by the assignment), so the host does not hold the RVEs' per-sphere
state, only a lean mirror of their per-RVE arrays; rows are read and written on the
device (`take`, `put`, `remove`), and a checkpoint gathers the state in chunks. Groups
made on the host and uploaded keep a full host mirror: the cells doubled by retiling,
and every group of a run resumed from a checkpoint or rebalanced over ranks (load_state
rebuilds them from the saved arrays).
"""

from __future__ import annotations

import math
import time

import numpy as np

from grainscale.config.case import (
    SLEEP_TOLERANCE_MAX,
    DEMMaterialCfg,
    default_update_tolerance,
)
from grainscale.config.rve import RVEParams
from grainscale.coupling import predictor
from grainscale.dem import engine, homogenise, lattice, retile
from grainscale.dem.generate import contact_params
from grainscale.dem.state import (
    CLUMP_FIELDS,
    SLOT_FIELDS,
    SPHERE_FIELDS,
    STATE_FIELDS,
    RVEBatch,
    concatenate,
    extend,
    from_state_arrays,
    grow_capacity,
    longest_row,
    padded,
    remove_rves,
    rve_constants,
    state_arrays,
    unpadded,
)
from grainscale.io.packing import fit_history
from grainscale.mpm.step import SimulationError


def bulk_density(library: list[RVEBatch]) -> float:
    """Mean grain mass per cell volume of the packings [kg/m^3] (a clump's mass once,
    not its members' each)."""
    return float(np.mean([rve_constants(b)["grain_mass"][0] / b.volume()[0]
                          for b in library]))


def _sym(sigma: np.ndarray) -> np.ndarray:
    """(sigma + sigma^T)/2 of (..., 3, 3) stresses [Pa]."""
    return 0.5 * (sigma + np.swapaxes(sigma, -1, -2))


_DEM = DEMMaterialCfg(type="dem")  # the case file's defaults are the only ones


# list slots a device-built batch gets beyond the library's longest row: under large
# deformation rows grow (the no-slip intrusion to d/R 2, 150-sphere RVEs: from 11-12 in
# the packings to 15 in 3 of 3,851 RVEs, 14 in 33; docs/performance.md), and a row that
# outgrows the lists regrows the whole batch, which a full GPU cannot hold twice
SLOT_MARGIN = 3
CHUNK_BYTES = 256 * 2**20  # a checkpoint gathers a device-built batch this much at a time

# Sleeping RVEs (dynamic, update_tolerance > 0; docs/coupling.md). An RVE is at rest when,
# under compression (p > 0), its grains are near equilibrium, the unbalanced-force ratio
# u (mean |net force| over the mean contact force) at most QUIET_UNBALANCED and u p at most
# max_k M_k tol (the stress its imbalance can still release is below what the tolerance
# resolves), and their fluctuating motion is slow: the inertial number of a shear rate
# v'/d, I_v = v' sqrt(rho_s / p) with v' = sqrt(2 E_k / M) the grains' fluctuation speed,
# at most QUIET_INERTIAL (velocity fluctuations in slow dense flow scale as
# v' ~ gamma_dot d I^(-1/3), so I_v ~ I^(2/3): 0.01 is a flow at I ~ 1e-3; the kinetic
# stress is then below 2e-5 p).
QUIET_UNBALANCED = 0.05
QUIET_INERTIAL = 0.01
# ... or it is loose: every stress component at most LOOSE times the recipe's preparation
# pressure (the material's stress scale). A loose cell (no load-bearing network, its
# porosity above the jammed one) carries next to no stress, and needs a finite compression
# before it carries any: over strains below the tolerance, none.
LOOSE = 0.01
# a waking RVE takes what it owes over at least the time that keeps its inertial number
# max|H_acc| d sqrt(rho_s / p) / T at or below this (the rate-independent regime), at
# most the time it slept (its macroscopic rate), at least one MPM step's; a loose one
# over the time that keeps its collisional (Bagnold) stress rho_s d^2 (max|H_acc| / T)^2
# below LOOSE p_prep: inertial number 1 with p = LOOSE p_prep
WAKE_INERTIAL = 1e-3


def list_capacity(library: list[RVEBatch]) -> int:
    """Neighbour slots per sphere of a batch built on the device: the packings' longest
    row plus SLOT_MARGIN (a row that outgrows it regrows the lists on the device,
    engine.advance); the packings' own capacity where they hold no lists yet."""
    longest = longest_row(library)
    if longest == 0:
        return max(b.capacity for b in library)
    return longest + SLOT_MARGIN


def rve_state_bytes(batch: RVEBatch) -> int:
    """Bytes of one RVE's state (state.state_arrays) in a group like `batch`."""
    return sum(v.itemsize * int(np.prod(v.shape[1:])) for v in state_arrays(batch).values())


def _counts(state: dict[str, np.ndarray]) -> np.ndarray:
    """(P,) spheres of each RVE of a saved state (older states: all the stored count)."""
    s = state["rve_s"]
    return np.asarray(state.get("rve_particles", np.full(len(s), s.shape[1])))


def _bodies(state: dict[str, np.ndarray]) -> np.ndarray:
    """(P,) clumps of each RVE of a saved state (0: plain spheres)."""
    return np.asarray(state.get("rve_bodies", np.zeros(len(state["rve_s"]), np.int64)))


def _state_names(state: dict[str, np.ndarray]) -> tuple[str, ...]:
    """The state.state_arrays names a saved state holds (CLUMP_FIELDS where clumped)."""
    return STATE_FIELDS + (CLUMP_FIELDS if "rve_bm" in state else ())


class RVEMaterial:
    """Batched RVE material with the MPM material interface (mpm/materials/base.py).

    The RVEs are held in groups of equal sphere count (`groups`, with `rows[g]` the
    point index of each RVE of group g): all start in one group, and an RVE whose cell
    has become too thin is doubled (dem/retile.py) and moves to the group of twice its
    spheres. Each group is stepped as one batch.
    """

    def __init__(self, name: str, params: RVEParams, library: list[RVEBatch], n_points: int,
                 assignment_seed: int = _DEM.assignment_seed,
                 mode: str = _DEM.time_integration, min_substeps: int = _DEM.min_substeps,
                 strain_per_substep: float = _DEM.strain_per_substep,
                 local: np.ndarray | None = None, assignment: np.ndarray | None = None,
                 retile_width: float = _DEM.retile_width,
                 retile_max_factor: int = _DEM.retile_max_factor, device: str = "cpu",
                 update_tolerance: float | None = _DEM.update_tolerance,
                 max_deferred_steps: int = _DEM.max_deferred_steps):
        """n_points: points of this material over all ranks; local: the indices (into
        them) of the points this process holds (default: all). The packing of each point
        is drawn for all points with the seed, so it does not depend on the ranks, or
        given for all points by `assignment` (indices into library).
        retile_width: cells narrower than this many mean grain diameters are doubled
        (0: never), up to retile_max_factor times the packing's spheres. The defaults
        are those of a case file's "dem" material (config.case.DEMMaterialCfg).
        device: where `update` steps the RVEs, "cpu" or "cuda" (solver.device).
        update_tolerance, max_deferred_steps: adaptive updates (quasi_static RVEs) and
        sleeping RVEs (dynamic ones); 0: every RVE every step; None: strain_per_substep
        for quasi_static, else 0; see `update`."""
        if mode not in ("dynamic", "quasi_static"):
            raise ValueError(f"mode = {mode!r}: must be 'dynamic' or 'quasi_static'")
        if update_tolerance is None:  # the case file's default
            update_tolerance = default_update_tolerance(mode, strain_per_substep)
        if mode == "dynamic" and not 0 <= update_tolerance <= SLEEP_TOLERANCE_MAX:
            raise ValueError(f"update_tolerance = {update_tolerance} with mode 'dynamic': "
                             f"valid 0 to {SLEEP_TOLERANCE_MAX:g} (docs/coupling.md)")
        if mode == "quasi_static" and not 0 <= update_tolerance <= strain_per_substep:
            raise ValueError(f"update_tolerance = {update_tolerance}: valid 0 to "
                             f"strain_per_substep = {strain_per_substep} (docs/coupling.md)")
        if max_deferred_steps < 1:
            raise ValueError(f"max_deferred_steps = {max_deferred_steps}: valid >= 1")
        self.update_tolerance = float(update_tolerance)
        self.max_deferred_steps = int(max_deferred_steps)
        engine.check_device(device)
        self.device = device
        self._dev: dict[int, object] = {}  # id(group) -> its DeviceBatch (device "cuda")
        self._moved_before = 0  # bytes moved by device batches since dropped
        self.name = name
        self.params = params
        self.mode = mode
        self.min_substeps = int(min_substeps)
        self.strain_per_substep = float(strain_per_substep)
        self.retile_width = float(retile_width)
        self.max_particles = int(retile_max_factor) * max(b.n_particles for b in library)
        self.cp = contact_params(params)
        if assignment is None:
            rng = np.random.default_rng(assignment_seed)
            assignment = rng.integers(len(library), size=n_points)
        self.assignment = np.asarray(assignment)
        self.local = local  # for error messages: the material's point numbers
        if local is not None:
            self.assignment = self.assignment[local]
            n_points = len(local)
        self.n_points = n_points
        self._none = library[0].take(np.zeros(0, np.int64))  # the shape of "no RVE"
        self.groups: list[RVEBatch] = []
        self.rows: list[np.ndarray] = []
        self._storage: dict[int, RVEBatch] = {}  # sphere count -> the rows its group views
        # the contact history's width: rolling moments where the law has them
        library = [fit_history(b, params, f"materials.{name}: a packing of its library")
                   for b in library]
        if n_points and device == "cuda":
            from grainscale.dem.device_batch import DeviceBatch

            dev = DeviceBatch.from_library(library, self.assignment, list_capacity(library))
            self.groups = [dev.host]
            self._dev[id(dev.host)] = dev
            self.rows = [np.arange(n_points)]
        elif n_points:
            self.groups = [concatenate([library[k] for k in self.assignment])]
            self.rows = [np.arange(n_points)]
        self.density = bulk_density(library)
        self.dt_crit = min(engine.critical_dt(b, self.cp, params.numerics.timestep_safety)
                           for b in library)
        self.theta_prev = np.zeros(n_points)
        self.spin_rate = np.zeros(n_points)
        # adaptive updates: each RVE's increment since its last DEM update, H_acc with
        # I + H_acc = prod (I + dH) (kept as H_acc, not the product, so that small
        # increments keep their digits; 0: nothing owed), the MPM steps and the time [s]
        # it has been deferred
        self.H_acc = np.zeros((n_points, 3, 3))
        self.deferred = np.zeros(n_points, np.int64)
        self.t_acc = np.zeros(n_points)
        # per point: the DEM updates its RVE took and their DEM steps, since the run
        # began (where the DEM work goes; history's dem_steps_per_rve)
        self.updates = np.zeros(n_points, np.int64)
        self.dem_steps = np.zeros(n_points, np.int64)
        self.rve_updates = 0  # sum over MPM steps of the RVEs stepped
        self.substeps = 0  # DEM steps of the last update (largest over RVEs)
        self.seconds = 0.0  # wall time spent in DEM updates
        self.rve_steps = 0  # sum over RVEs of DEM steps taken
        self.particle_steps = 0  # sum over RVEs of DEM steps x spheres
        self.retiled = 0  # cells doubled so far on this process
        # per RVE, particle-steps plus contact-steps (the end-of-increment pass
        # included) since the last rebalancing: the measured work that decides the load
        # balance over ranks
        self.work = np.zeros(n_points)
        for b in self.groups:
            engine.refresh(self._device(b), self.cp)
        if n_points:
            self.theta_prev = self._mean_rotation()

    @property
    def n_rve(self) -> int:
        return self.n_points

    # ------------------------------------------------------------- device residency
    def _device(self, batch: RVEBatch):
        """The DeviceBatch of group `batch` (uploaded on first use), or the batch itself
        on the CPU."""
        if self.device != "cuda":
            return batch
        from grainscale.dem.device_batch import DeviceBatch

        dev = self._dev.get(id(batch))
        if dev is None or dev.host is not batch:
            dev = self._dev[id(batch)] = DeviceBatch(batch)
        return dev

    def _lean(self, batch: RVEBatch):
        """The DeviceBatch of a group built on the device (lean host mirror), else None."""
        dev = self._dev.get(id(batch))
        return dev if dev is not None and dev.host is batch and dev.lean else None

    def _constant(self, batch: RVEBatch, key: str) -> np.ndarray:
        """(R,) state.rve_constants[key] of a group (from the device batch if lean)."""
        dev = self._lean(batch)
        return dev.constants[key] if dev is not None else rve_constants(batch)[key]

    def _sync(self) -> None:
        """Bring the full state of every group uploaded from the host back to it (device
        "cuda"; no-op on the CPU); groups built on the device stay there."""
        for dev in self._dev.values():
            if not dev.lean:
                dev.pull()

    def _forget_devices(self) -> None:
        """Drop the device copies of groups that are gone (after retiling or loading);
        the current groups are uploaded again by their next update."""
        kept = {id(b): self._dev[id(b)] for b in self.groups
                if id(b) in self._dev and self._dev[id(b)].host is b}
        every = {id(d): d for d in self._dev.values()}  # a batch may sit under two keys
        kept_ids = {id(d) for d in kept.values()}
        self._moved_before += sum(d.moved for i, d in every.items() if i not in kept_ids)
        self._dev = kept

    def device_bytes(self) -> int:
        """Bytes of RVE state resident on the GPU (0 on the CPU)."""
        return sum(d.device_bytes() for d in self._dev.values())

    def bytes_moved(self) -> int:
        """Bytes copied between host and GPU so far (0 on the CPU), by the groups there
        now and those dropped before."""
        return self._moved_before + sum(d.moved for d in self._dev.values())

    @property
    def batch(self) -> RVEBatch | None:
        """All RVEs as one batch, in point order, while they have one size (scripts); a
        batch built on the GPU comes as a host copy (changing it changes nothing)."""
        if not self.groups:
            return None
        self._sync()
        if len(self.groups) > 1:
            raise ValueError(f"material {self.name!r}: RVEs of {len(self.groups)} sizes "
                             "(cells were retiled); use .groups")
        dev = self._lean(self.groups[0])
        return dev.take(np.arange(dev.n_rve)) if dev is not None else self.groups[0]

    def rve(self, point: int) -> RVEBatch:
        """A copy of the RVE of `point` (an index into this process's points of the
        material), as a batch of one, found in whichever group it is now (retiling
        moves an RVE to the group of its new sphere count)."""
        for b, rows in zip(self.groups, self.rows, strict=True):
            hit = np.flatnonzero(rows == point)
            if hit.size:
                if id(b) in self._dev:
                    return self._dev[id(b)].take(hit)
                return b.take(hit)
        raise IndexError(f"material {self.name!r}: no RVE for point {point} here")

    def particle_counts(self) -> np.ndarray:
        """(P,) spheres of each point's RVE."""
        return self._per_point(lambda b: np.full(b.n_rve, b.n_particles))

    def _per_point(self, f) -> np.ndarray:
        """f(group) (R_g, ...) of every group, scattered into point order (P, ...)."""
        parts = [np.asarray(f(b)) for b in self.groups]
        out = np.empty((self.n_points, *parts[0].shape[1:]), parts[0].dtype)
        for rows, part in zip(self.rows, parts, strict=True):
            out[rows] = part
        return out

    # ------------------------------------------------------------------ interface
    def update(self, dH: np.ndarray, dt: float, stress: np.ndarray) -> None:
        """Deform each RVE by its dH over the step dt [s]; stress <- sym(sigma) [Pa].

        sigma = (1/V) sum_c d (x) f is the RVE's Love-Weber stress (kept as it is in the
        batch); its skew part (the net contact torque over V, non-zero while grain spins
        accelerate) belongs to no Cauchy stress, and the MPM's nodal force
        f_a = -V sigma_ab dS/dx_b would take it transposed, so the MPM gets the symmetric
        part. The stress and the batch's `stiffness` are those of the state the increment
        reached (kernel.py item 8; wave_speed).

        Adaptive updates (update_tolerance > 0): the increments are composed,
        I + H_acc <- (I + dH)(I + H_acc), and an RVE is stepped only once max |H_acc|
        reaches the tolerance or it has been deferred max_deferred_steps MPM steps; it
        then takes the whole H_acc as one increment (the cell ends exactly at
        (I + H_acc) h, as if it had followed every step). Meanwhile its stress is
        predicted from its last update, R [sym(sigma) + C_aff : (U - I)] R^T with
        I + H_acc = R U and C_aff the affine moduli (coupling/predictor.py): objective,
        with an error of the order of the affine modulus times the tolerance that does
        not accumulate (docs/coupling.md).
        - quasi_static RVEs: the increment over ceil(max |H_acc| / strain_per_substep)
          DEM steps of dt_crit;
        - dynamic RVEs (sleeping): only an RVE at rest or loose waits (`_quiet`: its
          last update left its grains near equilibrium and slow, or its stress below
          LOOSE p_prep); any other is stepped every step. A waking RVE that slept takes
          H_acc over whole DEM steps of this step's dt_DEM lasting T = max(dt, min(t_acc,
          max|H_acc| d sqrt(rho_s / p) / WAKE_INERTIAL)) (`_waking_steps`; a loose one's
          limit its collisional stress): its grains see the rate-independent regime's
          rate or slower, or at most the macroscopic rate (T = t_acc, the slept time
          caught up). The slept time is otherwise frozen: the grains' fluctuating motion
          resumes where it stood.
        """
        if dH.shape != (self.n_points, 3, 3):
            raise ValueError(f"dH of shape {dH.shape}: one (3, 3) increment per point of "
                             f"material {self.name!r}, ({self.n_points}, 3, 3)")
        if not self.groups:
            return
        t0 = time.perf_counter()
        # increments owed under a tolerance that a resume turned off (--allow-changed)
        # are composed with this one and taken now: every RVE is then due
        adaptive = self.update_tolerance > 0 or bool(self.t_acc.any())
        if adaptive:
            slept = self.deferred > 0
            # (I + dH)(I + H) = I + dH + H + dH H
            self.H_acc = dH + self.H_acc + np.einsum("pab,pbc->pac", dH, self.H_acc)
            self.t_acc += dt
            inc = self.H_acc
            due = ((np.abs(inc).max(axis=(1, 2)) >= self.update_tolerance)
                   | (self.deferred + 1 >= self.max_deferred_steps))
            if self.mode == "dynamic":
                due |= ~self._per_point(self._quiet)
        else:
            inc = dH
        most = 0
        for batch, rows in zip(self.groups, self.rows, strict=True):
            if self.mode == "dynamic":
                n = max(self.min_substeps, math.ceil(dt / self.dt_crit - 1e-9))
                nsteps = np.full(batch.n_rve, n, np.int64)
                dt_dem = dt / n
                if adaptive:
                    woke = np.flatnonzero(due[rows] & slept[rows])
                    if woke.size:
                        nsteps[woke] = self._waking_steps(batch, rows, woke, n, dt_dem)
            else:
                size = np.abs(inc[rows]).max(axis=(1, 2))
                nsteps = np.maximum(self.min_substeps,
                                    np.ceil(size / self.strain_per_substep)).astype(np.int64)
                dt_dem = self.dt_crit
            if adaptive:
                stepped = due[rows]
                nsteps[~stepped] = 0
                wait = np.flatnonzero(~stepped)
                if wait.size:
                    stress[rows[wait]] = self._predicted(batch, rows, wait)
                if wait.size == batch.n_rve:  # the group waits: no kernel call at all
                    continue
            try:
                ctrl = engine.increment_control(batch, inc[rows], np.maximum(nsteps, 1),
                                                dt_dem)
                target = self._device(batch)
                engine.advance(target, nsteps, dt_dem, self.cp, ctrl, device=self.device)
            except engine.RVEError as err:
                point = int(rows[err.rve])
                point = point if self.local is None else int(self.local[point])
                raise SimulationError(
                    f"material {self.name!r}, its point {point}: {err} (the run stops; "
                    "history and checkpoints so far are intact)") from None
            self._reduce_cells(batch, target)
            if adaptive:
                stress[rows[stepped]] = _sym(batch.stress[stepped])
            else:
                stress[rows] = _sym(batch.stress)
            most = max(most, int(nsteps.max()))
            taken = int(nsteps.sum())
            self.rve_steps += taken
            self.particle_steps += taken * batch.n_particles
            self.dem_steps[rows] += nsteps
            self.updates[rows] += nsteps > 0
            # particle- and contact-steps, and the end-of-increment evaluation of an RVE
            # that stepped (one more pass over its contacts, kernel.py item 8)
            self.work[rows] += (nsteps * (batch.n_particles + batch.ncontact)
                                + (nsteps > 0) * batch.ncontact)
        self._retile()
        theta = self._mean_rotation(due if adaptive else None)
        if adaptive:  # the spin rate of an RVE over the time since its last update
            self.spin_rate[due] = (theta[due] - self.theta_prev[due]) / self.t_acc[due]
            self.theta_prev[due] = theta[due]
            self.H_acc[due] = 0.0
            self.t_acc[due] = 0.0
            self.deferred[due] = 0
            self.deferred[~due] += 1
            self.rve_updates += int(due.sum())
        else:
            self.spin_rate = (theta - self.theta_prev) / dt
            self.theta_prev = theta
            self.rve_updates += self.n_points
        self.substeps = most
        self.seconds += time.perf_counter() - t0

    def _quiet(self, batch: RVEBatch) -> np.ndarray:
        """(R,) the RVEs of a group at rest, from the state their last update reached:
        p > 0, unbalanced-force ratio u <= QUIET_UNBALANCED with u p <= max_k M_k tol, and
        inertial number of the fluctuating motion sqrt(2 E_k rho_s / (M p)) <=
        QUIET_INERTIAL (the comment at QUIET_UNBALANCED)."""
        p = -np.trace(batch.stress, axis1=1, axis2=2) / 3.0
        mass = self._constant(batch, "grain_mass")
        m_k = np.diagonal(batch.stiffness, axis1=1, axis2=2).max(axis=1)
        quiet = ((p > 0) & (batch.unbalanced <= QUIET_UNBALANCED)
                 & (batch.unbalanced * p <= m_k * self.update_tolerance))
        i_v = np.sqrt(2.0 * batch.kinetic * self.params.density / (mass * np.where(quiet, p, 1.0)))
        return (quiet & (i_v <= QUIET_INERTIAL)) | self._loose(batch)

    def _loose(self, batch: RVEBatch) -> np.ndarray:
        """(R,) the RVEs of a group whose every stress component is at most LOOSE times
        the recipe's preparation pressure (the comment at LOOSE)."""
        scale = LOOSE * self.params.preparation.pressure
        return np.abs(batch.stress).max(axis=(1, 2)) <= scale

    def _waking_steps(self, batch: RVEBatch, rows: np.ndarray, woke: np.ndarray, n: int,
                      dt_dem: float) -> np.ndarray:
        """DEM steps of dt_dem over which the dynamic RVEs `woke` of a group (which slept:
        at rest or loose) take what they owe: T = max(dt, min(t_acc, max|H_acc| d
        sqrt(rho_s / p) / I)) (`update`), d the mean grain diameter, p the RVE's mean
        stress at its last update and I = WAKE_INERTIAL, or for a loose RVE p = LOOSE
        p_prep and I = 1 (the comment at WAKE_INERTIAL); n is one MPM step's."""
        owed = np.abs(self.H_acc[rows[woke]]).max(axis=(1, 2))
        p = -np.trace(batch.stress[woke], axis1=1, axis2=2) / 3.0
        d = 2.0 * self._constant(batch, "mean_radius")[woke]
        loose = self._loose(batch)[woke]
        p = np.where(loose, LOOSE * self.params.preparation.pressure, p)
        limit = np.where(loose, 1.0, WAKE_INERTIAL)
        t_rate = np.where(p > 0, owed * d * np.sqrt(self.params.density / np.where(
            p > 0, p, 1.0)) / limit, np.inf)
        t_slept = self.t_acc[rows[woke]]
        steps = np.ceil(np.minimum(t_rate, t_slept) / dt_dem - 1e-9)
        return np.maximum(steps, n).astype(np.int64)

    def _predicted(self, batch: RVEBatch, rows: np.ndarray, which: np.ndarray) -> np.ndarray:
        """(k,3,3) predicted stresses [Pa] of a group's waiting RVEs `which` (their points
        rows[which]): coupling/predictor.py."""
        return predictor.predicted_stress(batch.stress[which], batch.stiffness[which],
                                          self.H_acc[rows[which]], self.cp.kt_ratio)

    def _reduce_cells(self, batch: RVEBatch, target) -> None:
        """lattice.reduce_cells of a group; on the GPU only the RVEs to reduce make the
        round trip (their cells, current on the host after each update, say which)."""
        if target is batch:
            lattice.reduce_cells(batch)
            return
        todo = np.flatnonzero(lattice.needs_reduction(batch.h, lattice.REDUCE_TOL))
        if todo.size:
            part = target.take(todo)
            lattice.reduce_cells(part)
            target.put(todo, part)

    def _mean_rotation(self, due: np.ndarray | None = None) -> np.ndarray:
        """(P,) homogenise.mean_rotation of each point's RVE, on the GPU where it lives;
        with `due` (P,) bool on the CPU, of those RVEs only (the others' entries are
        theta_prev: a waiting RVE has not turned)."""
        if self.device == "cuda":
            return self._per_point(lambda b: self._device(b).mean_rotation())
        if due is None:
            return self._per_point(homogenise.mean_rotation)
        theta = self.theta_prev.copy()
        for b, rows in zip(self.groups, self.rows, strict=True):
            sel = np.flatnonzero(due[rows])
            theta[rows[sel]] = b.rot[sel].mean(axis=1)
        return theta

    def _retile(self) -> None:
        """Double every cell narrower than retile_width mean diameters (dem/retile.py)."""
        if self.retile_width <= 0:
            return
        if self.device == "cuda":  # the cells are current on the host, the rest is not
            if not any(self._thin(b, retile.widths(b.h)).any() for b in self.groups):
                return
            self._sync()  # the groups uploaded from the host; those built there: below
        # by sphere count: the groups as they stay, and the cells doubled into each
        kept: dict[int, tuple[RVEBatch, np.ndarray]] = {}
        doubled: dict[int, list[tuple[RVEBatch, int]]] = {}
        for batch, rows in zip(self.groups, self.rows, strict=True):
            n = batch.n_particles
            w = retile.widths(batch.h)
            thin = self._thin(batch, w)
            if 2 * n > self.max_particles or not thin.any():
                kept[n] = (batch, rows)
                continue
            idx = np.flatnonzero(thin)
            dev = self._lean(batch)
            cells = dev.take(idx) if dev is not None else batch.take(idx)
            for i, r in enumerate(idx):
                doubled.setdefault(2 * n, []).append(
                    (retile.double_cell(cells, i, int(np.argmin(w[r]))), int(rows[r])))
                self.retiled += 1
            if idx.size < batch.n_rve:  # the rest stays where it is: no whole-group copy
                if dev is not None:  # rows removed on the device, the batch stays there
                    order = dev.remove(idx)
                    rest = dev.host
                    self._dev[id(rest)] = dev
                else:
                    rest, order = remove_rves(batch, idx)
                kept[n] = (rest, rows[order])
        if not doubled:
            return
        self.groups, self.rows = [], []
        for n in sorted(set(kept) | set(doubled)):
            new = doubled.get(n, [])
            if n in kept:
                batch, rows = kept[n]
            else:
                (batch, first), new = new[0], new[1:]
                rows = np.array([first])
            if new:  # appended into the group's spare rows where it has them
                batch, self._storage[n] = extend(batch, [b for b, _ in new],
                                                 self._storage.get(n))
                rows = np.concatenate([rows, [r for _, r in new]])
            self.groups.append(batch)
            self.rows.append(rows)
        # keep a storage only while its group still lies in it (memory follows the RVEs)
        self._storage = {b.n_particles: self._storage[b.n_particles] for b in self.groups
                         if b.n_particles in self._storage
                         and b.s.base is self._storage[b.n_particles].s}
        self._forget_devices()

    def _thin(self, batch: RVEBatch, widths: np.ndarray) -> np.ndarray:
        """(R,) cells of a group narrower than retile_width mean grain diameters, from
        their perpendicular widths (R,3) (retile.widths)."""
        return widths.min(axis=1) < (self.retile_width * 2.0
                                     * self._constant(batch, "mean_radius"))

    def initial_stress(self) -> np.ndarray:
        """(P,3,3) sym(sigma) of the prepared RVEs' Love-Weber stress [Pa] (see update)."""
        return self._per_point(lambda b: _sym(b.stress))

    def wave_speed(self) -> float:
        """Estimate of the RVEs' largest wave speed, sqrt(max_k M_k / rho) of each [m/s].

        M_k [Pa] (the diagonal of the batch's `stiffness`) bounds the modulus of an
        increment taken in one DEM step along axis k: the affine constrained modulus of
        the contacts, kn and kt, plus their forces' turning (kernel.contact_pass),
        evaluated at the end of the RVE's last update (docs/coupling.md). Over the RVE's
        own bulk density rho [kg/m^3]; a maximum over RVEs, so it does not depend on how
        RVEs are split over ranks.

        An estimate, not a bound: waves along the axes only. The largest eigenvalue of
        the same affine law's acoustic tensor over all directions is 0.4 % above max_k M_k
        for the stored isotropic packing and 16 % for a compression fabric turned 45 deg
        (speed +0.2 %, +7.8 %); over any fabric at most 9 / (1 + 2 kt/kn) times (speed
        x1.86 at kt/kn = 0.8), which the default cfl 0.5 absorbs for kt/kn > 0.625. No
        useful bound can be read from the stored C_aabb: fabrics with the same six
        moduli differ 7/3 in it (tests/coupling/test_wave_speed.py).
        """
        speed = 0.0
        for b in self.groups:
            c = np.diagonal(b.stiffness, axis1=1, axis2=2).max(axis=1)
            rho = self._constant(b, "grain_mass") / b.volume()
            speed = max(speed, float(np.sqrt(c / rho).max()))
        return speed

    def state(self) -> dict[str, np.ndarray]:
        """Per point: the RVE's full state, padded to the largest sphere count here and
        to the longest neighbour row in use (`rve_particles` holds each RVE's own sphere
        count, `rve_capacity` its list capacity, restored on loading; clumped RVEs are
        padded to the most clumps too, `rve_bodies` their own count), and the
        material's per-point arrays."""
        capacity = np.zeros(self.n_points, np.int64)
        self._sync()
        if self.groups:
            n = max(b.n_particles for b in self.groups)
            nb = max(b.bm.shape[1] for b in self.groups)  # clumps (0: spheres)
            # capacities hold room for the rows to grow (list_capacity, overflows):
            # tables cut to the rows' longest count are smaller
            k = max(max(self._longest_row(b) for b in self.groups), 1)
            arrays = {}
            for b, rows in zip(self.groups, self.rows, strict=True):
                for at, part in self._chunks(b):
                    for name, v in padded(state_arrays(part), n, k, nb).items():
                        if name not in arrays:
                            arrays[name] = np.empty((self.n_points, *v.shape[1:]), v.dtype)
                        arrays[name][rows[at]] = v
                capacity[rows] = b.capacity
            counts = self.particle_counts()
        else:
            arrays = state_arrays(self._none)
            counts = np.zeros(0, np.int64)
        out = {f"rve_{k}": v for k, v in arrays.items()}
        out["rve_particles"] = counts
        if "bm" in arrays:  # clumped: each RVE's clump count
            out["rve_bodies"] = (self._per_point(lambda b: np.full(b.n_rve, b.bm.shape[1]))
                                 if self.groups else np.zeros(0, np.int64))
        out["rve_capacity"] = capacity
        out["theta_prev"] = self.theta_prev.copy()  # copies: updated in place later
        out["spin_rate"] = self.spin_rate.copy()
        out["assignment"] = self.assignment
        out["work"] = self.work
        out["H_acc"] = self.H_acc.copy()
        out["deferred"] = self.deferred.copy()
        out["t_acc"] = self.t_acc.copy()
        out["updates"] = self.updates.copy()
        out["dem_steps"] = self.dem_steps.copy()
        return out

    def _longest_row(self, batch: RVEBatch) -> int:
        """The most neighbour entries a sphere of a group holds."""
        dev = self._lean(batch)
        if dev is None:
            return longest_row([batch])
        return int(dev.pull_field("nbr_count").max(initial=0))

    def _chunks(self, batch: RVEBatch):
        """(rows, batch of those rows) covering a group: the group itself in one piece,
        or, built on the device, host copies of CHUNK_BYTES of state at a time."""
        dev = self._lean(batch)
        if dev is None:
            yield slice(None), batch
            return
        step = max(1, CHUNK_BYTES // max(rve_state_bytes(batch), 1))
        for start in range(0, batch.n_rve, step):
            at = np.arange(start, min(start + step, batch.n_rve))
            yield at, dev.take(at)

    def checkpoint_bytes(self) -> int:
        """Bytes of the RVE state table a checkpoint of this process builds on the host
        (`state`: every RVE padded to the largest sphere count, at the largest list
        capacity, which bounds the longest row it is cut to), plus one chunk in flight."""
        if not self.groups:
            return 0
        widest = max(self.groups, key=lambda b: (b.n_particles, b.capacity))
        n = max(b.n_particles for b in self.groups)
        k = max(b.capacity for b in self.groups)
        per_sphere = sum(getattr(widest, f).itemsize * int(np.prod(getattr(widest, f).shape[2:]))
                         for f in SPHERE_FIELDS if f not in SLOT_FIELDS)
        per_slot = sum(getattr(widest, f).itemsize * int(np.prod(getattr(widest, f).shape[3:]))
                       for f in SLOT_FIELDS)
        per_rve = sum(getattr(widest, f).itemsize * int(np.prod(getattr(widest, f).shape[1:]))
                      for f in state_arrays(widest) if f not in SPHERE_FIELDS)
        chunk = CHUNK_BYTES if any(self._lean(b) is not None for b in self.groups) else 0
        return self.n_points * (per_rve + n * (per_sphere + k * per_slot)) + chunk

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        arrays = {k: np.asarray(state[f"rve_{k}"]) for k in _state_names(state)}
        counts = _counts(state)
        bodies = _bodies(state)
        self.n_points = len(counts)
        self.groups, self.rows = [], []
        self._storage = {}
        capacity = state.get("rve_capacity")  # absent in checkpoints before it
        for n, nb in sorted(set(zip(counts.tolist(), bodies.tolist(), strict=True))):
            rows = np.flatnonzero((counts == n) & (bodies == nb))
            every = len(rows) == self.n_points  # one group: no copy of the whole state
            b = from_state_arrays(unpadded({k: v if every else v[rows]
                                            for k, v in arrays.items()}, n, nb))
            if capacity is not None:  # the same capacity as saved: the run continues bitwise
                grow_capacity(b, int(np.max(capacity[rows])))
            self.groups.append(b)
            self.rows.append(rows)
        self.theta_prev = np.asarray(state["theta_prev"], float).copy()
        self.assignment = np.asarray(state["assignment"]).copy()
        n = len(self.theta_prev)
        self.spin_rate = np.asarray(state.get("spin_rate", np.zeros(n)), float).copy()
        self.work = np.asarray(state.get("work", np.zeros(n)), float).copy()
        # absent in checkpoints before adaptive updates: nothing deferred
        self.H_acc = np.asarray(state.get("H_acc", np.zeros((n, 3, 3))), float).copy()
        self.deferred = np.asarray(state.get("deferred", np.zeros(n)), np.int64).copy()
        self.t_acc = np.asarray(state.get("t_acc", np.zeros(n)), float).copy()
        # absent in checkpoints before sleeping RVEs: counted from the resume
        self.updates = np.asarray(state.get("updates", np.zeros(n)), np.int64).copy()
        self.dem_steps = np.asarray(state.get("dem_steps", np.zeros(n)), np.int64).copy()
        self._forget_devices()
        # no refresh: the saved stress and moduli are already those of the saved state

    def point_fields(self) -> dict[str, np.ndarray]:
        """Per-point RVE quantities for VTK frames and history: porosity, coordination,
        mean accumulated rotation [rad] and its rate [rad/s] (seed Eq. 15, Fig. 15), the
        RVE's own eps_v, its sphere count (which grows when its cell is retiled), the
        DEM steps it has taken since its packing was generated, and the DEM updates
        and DEM steps it has taken since the run began (where the DEM work goes: their
        difference between two frames; adaptive updates and sleeping RVEs skip some)."""
        if not self.groups:
            return {}
        for batch in self.groups if self.device == "cuda" else ():  # a kernel counter
            dev = self._dev.get(id(batch))
            if dev is not None and dev.host is batch:
                dev.pull_field("step_count")
        return {
            "porosity": self._per_point(
                lambda b: 1.0 - self._constant(b, "solid_volume") / b.volume()),
            "coordination": self._per_point(homogenise.coordination),
            "mean_rotation": self.theta_prev.copy(),  # the last update's (or loaded)
            "rotation_rate": self.spin_rate.copy(),
            "rve_eps_v": self._per_point(homogenise.volumetric_strain),
            "rve_particles": self.particle_counts().astype(float),
            "rve_steps": self._per_point(lambda b: b.step_count).astype(float),
            "rve_updates": self.updates.astype(float),
            "rve_dem_steps": self.dem_steps.astype(float),
        }

    @staticmethod
    def merge_states(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """One state from the states of several sets of points (checkpoint parts written
        by different ranks), in order; sphere counts and list capacities may differ."""
        if len(parts) == 1:  # one rank wrote it: no copy (a resume's memory peak)
            return parts[0]
        n = max(p["rve_s"].shape[1] for p in parts)
        k = max(p["rve_nbr_j"].shape[2] for p in parts)
        names = _state_names(parts[0])
        nb = max(p["rve_bm"].shape[1] for p in parts) if "bm" in names else 0
        padded_parts = [padded({f: p[f"rve_{f}"] for f in names}, n, k, nb) for p in parts]
        out = {f"rve_{f}": np.concatenate([q[f] for q in padded_parts]) for f in names}
        out["rve_particles"] = np.concatenate([_counts(p) for p in parts])
        if nb:
            out["rve_bodies"] = np.concatenate([_bodies(p) for p in parts])
        for key in ("theta_prev", "spin_rate", "assignment", "work", "rve_capacity", "H_acc",
                    "deferred", "t_acc", "updates", "dem_steps"):
            if all(key in p for p in parts):
                out[key] = np.concatenate([p[key] for p in parts])
        return out

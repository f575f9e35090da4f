"""RVE batches whose state lives on the GPU for a whole run (solver.device = "cuda").

A `DeviceBatch` holds the device copy of an `RVEBatch`'s state (the arrays of
cuda_kernel.STATE_ARGS) and its host batch, `host`. `engine.advance` on a DeviceBatch runs
the kernel on the device arrays; per call only the step counts and the controls go down
and the small per-RVE results come up:

    down: nsteps, status and out (64 B), e_step and l_mean (72 B each); the other
          controls only when not all zero (an MPM increment has none)
    up:   status (8 B), out (48 B: contacts, unbalanced ratio, kinetic energy, ...),
          h, stress and stiffness (72 B each), the non-finite flag (4 B)

so after a call `host.h`, `host.stress`, `host.stiffness`, `host.ncontact`,
`host.unbalanced` and `host.kinetic` are current and every other host array is stale.
Whatever needs the rest reads it explicitly: `pull` (all of it, into the host batch) or
`take` (some rows, as a new batch), and writes it back with `push` or `put`; a capacity
overflow widens the lists on the device (`grow`). `moved` counts the bytes that
crossed, both ways.

A batch built on the device (`from_library`: copies of a few packings placed there by a
per-point assignment) never has its per-sphere state on the host: its `host` is *lean*,
holding the per-RVE arrays (cell, stress, moduli, counters: ~540 B an RVE) and, for every
per-sphere array, a read-only placeholder of the right shape and no memory (NaN; -1, or
the largest value of an unsigned type, for integers), so that a read that forgot the
device shows as NaN or an error instead of stale numbers. Its rows are read and written
through `take` and `put` (gathered and scattered on the device, so only the rows asked
for cross), `remove` drops rows on the device, `grow` widens the neighbour lists there,
and the constants that per-RVE quantities need (mean radius, grain mass, solid volume)
are kept per RVE.

A clumped batch keeps its clump arrays (cuda_kernel.CLUMP_ARGS and the bodies' volumes)
and the members of each body (cuda_rigid.member_lists) on the device too, moved row by
row with the state; in a lean batch they are placeholders on the host, as the
per-sphere arrays.
"""

from __future__ import annotations

import numpy as np
from numba import cuda, float64

from grainscale.dem import cuda_kernel, cuda_rigid
from grainscale.dem.state import (
    CLUMP_FIELDS,
    SPHERE_AXIS_FIELDS,
    RVEBatch,
    allocate,
    concatenate,
    grow_capacity,
    rve_constants,
    with_capacity,
)

STATE_ARGS = cuda_kernel.STATE_ARGS
CONTROL_ARGS = cuda_kernel.CONTROL_ARGS
# a clumped batch's further device arrays: its clump arrays (cuda_kernel.CLUMP_ARGS) and
# the members of each body (cuda_rigid.member_lists), row by row as the state
CLUMP_ARGS = cuda_kernel.CLUMP_ARGS
LISTS = ("first", "members")
KEPT = CLUMP_ARGS + ("bvol",)  # and the bodies' volumes, which the kernel does not read
# held on the device only in a lean batch, as the per-sphere arrays (the bodies' arrays
# are per body: tens of kB an RVE)
DEVICE_ONLY = SPHERE_AXIS_FIELDS + CLUMP_FIELDS + ("off",)
# never changed on the device: not copied back by `pull`
UNCHANGED = cuda_kernel.READ_ONLY + cuda_kernel.CLUMP_READ_ONLY + ("bvol",) + LISTS
UP_EACH_CALL = ("h", "stress", "stiffness")  # host copies kept current by every call
ALWAYS_SENT = ("e_step", "l_mean")  # the controls of an increment; others when non-zero
_REDUCE = 128  # threads of the per-RVE reductions below
_COPY = 128  # threads of the row and slot copies below


@cuda.jit
def _copy_rows(src, src_rows, dst, dst_rows):
    """dst[dst_rows[i], :] = src[src_rows[i], :] for every i (2-D views of state arrays:
    a gather, a scatter or a move of rows within one array). One block per i."""
    i = cuda.blockIdx.x
    a = src_rows[i]
    b = dst_rows[i]
    for k in range(cuda.threadIdx.x, src.shape[1], cuda.blockDim.x):
        dst[b, k] = src[a, k]


@cuda.jit
def _copy_slots(src, dst, fill):
    """dst[m, k, c] = src[m, k, c] for the K slots src has, `fill` for the slots beyond
    (views (rows, slots, components) of a neighbour array, dst the wider one). One block
    per m."""
    m = cuda.blockIdx.x
    k_src = src.shape[1]
    per = dst.shape[1] * dst.shape[2]
    for q in range(cuda.threadIdx.x, per, cuda.blockDim.x):
        k = q // dst.shape[2]
        c = q % dst.shape[2]
        if k < k_src:
            dst[m, k, c] = src[m, k, c]
        else:
            dst[m, k, c] = fill


def _rows2d(a):
    """A (R, everything else) view of a C-contiguous device array."""
    size = 1
    for d in a.shape[1:]:
        size *= d
    return a.reshape(a.shape[0], size)


def _placeholder(shape: tuple, dtype) -> np.ndarray:
    """A read-only array of `shape` that takes no memory: NaN (integers: -1, unsigned
    ones their largest value)."""
    dtype = np.dtype(dtype)
    fill = np.nan if dtype.kind == "f" else np.iinfo(dtype).max if dtype.kind == "u" else -1
    return np.broadcast_to(np.array(fill, dtype), shape)


def lean_copy(full: RVEBatch, rows: np.ndarray) -> RVEBatch:
    """The rows `rows` of `full` as a lean host batch: its per-RVE arrays copied, the
    per-sphere ones placeholders (module docstring)."""
    rows = np.asarray(rows, np.int64)
    out = {}
    for name in RVEBatch.__dataclass_fields__:
        a = getattr(full, name)
        if name in DEVICE_ONLY:
            out[name] = _placeholder((len(rows), *a.shape[1:]), a.dtype)
        else:
            out[name] = a[rows].copy()
    return RVEBatch(**out)


@cuda.jit
def _not_finite_rows(h, stress, s, v, w, flag):
    """flag[r] = 1 if RVE r's cell, stress, positions, velocities or spins hold a NaN or
    an infinity (x - x != 0 only for those; the device code is not fast-math), else 0.
    One block per RVE."""
    r = cuda.blockIdx.x
    t = cuda.threadIdx.x
    bad = False
    if t < 9:
        a = h[r, t // 3, t % 3]
        b = stress[r, t // 3, t % 3]
        bad = (a - a != 0.0) or (b - b != 0.0)
    for i in range(t, s.shape[1], cuda.blockDim.x):
        for k in range(3):
            a = s[r, i, k]
            b = v[r, i, k]
            c = w[r, i, k]
            if a - a != 0.0 or b - b != 0.0 or c - c != 0.0:
                bad = True
    if t == 0:
        flag[r] = 0
    cuda.syncthreads()
    if bad:
        flag[r] = 1  # every writer writes the same value


@cuda.jit
def _row_means(a, out):
    """out[r] = mean over i of a[r, i], summed in a fixed order (per-thread partial sums
    over i = t, t + T, ..., then the T partials in thread order): bitwise reproducible.
    One block of _REDUCE threads per RVE."""
    r = cuda.blockIdx.x
    t = cuda.threadIdx.x
    part = cuda.shared.array(_REDUCE, float64)
    acc = 0.0
    n = a.shape[1]
    for i in range(t, n, _REDUCE):
        acc += a[r, i]
    part[t] = acc
    cuda.syncthreads()
    if t == 0:
        total = 0.0
        for k in range(_REDUCE):
            total += part[k]
        out[r] = total / n


def _sources(b: RVEBatch) -> dict[str, np.ndarray]:
    """The host arrays a batch keeps on the device, by name: STATE_ARGS, and for clumps
    KEPT and the member lists (made here from `body`)."""
    out = {name: getattr(b, name) for name in STATE_ARGS}
    if b.clumped:
        out.update({name: getattr(b, name) for name in KEPT})
        out.update(zip(LISTS, cuda_rigid.member_lists(b.body, b.bm.shape[1]), strict=True))
    return out


class DeviceBatch:
    """The state of `host` (an RVEBatch) on the current GPU, kept there between calls."""

    def __init__(self, host: RVEBatch, arrays: dict | None = None,
                 constants: dict | None = None):
        """Upload `host` (a full batch), or adopt device `arrays` (`names`) of which
        `host` is the lean mirror, with its per-RVE `constants` (from_library)."""
        self.host = host
        # the device arrays: the state, and a clumped batch's clumps and member lists
        self.names = STATE_ARGS + ((*KEPT, *LISTS) if host.clumped else ())
        self.moved = 0  # bytes copied between host and device, both ways
        self.arrays: dict[str, object] = {}
        self._zeros: dict[tuple, object] = {}  # device zeros standing for unsent controls
        self.lean = arrays is not None
        if self.lean:
            self.arrays = dict(arrays)
            self.constants = constants
        else:
            self.push()
            self.constants = rve_constants(host)

    @classmethod
    def from_library(cls, library: list[RVEBatch], assignment,
                     capacity: int | None = None) -> DeviceBatch:
        """A batch of len(assignment) RVEs, RVE r a copy of the packing
        library[assignment[r]], built on the device: the packings go down once and are
        copied there, and the host keeps a lean mirror (module docstring). `capacity`:
        neighbour slots per sphere (default the packings' largest); it may be below
        theirs where every row fits (state.with_capacity)."""
        assignment = np.ascontiguousarray(assignment, np.int64)
        k = capacity if capacity is not None else max(b.capacity for b in library)
        stack = concatenate([with_capacity(b.copy(), k) for b in library])
        r = len(assignment)
        host = lean_copy(stack, assignment)
        d_from = cuda.to_device(assignment)
        d_to = cuda.to_device(np.arange(r, dtype=np.int64))
        arrays = {}
        sources = _sources(stack)
        for name, src in sources.items():
            if name not in DEVICE_ONLY and name not in LISTS:
                arrays[name] = cuda.to_device(getattr(host, name))
                continue
            arrays[name] = cuda.device_array((r, *src.shape[1:]), src.dtype)
            if r:
                _copy_rows[r, _COPY](_rows2d(cuda.to_device(src)), d_from,
                                     _rows2d(arrays[name]), d_to)
        dev = cls(host, arrays, {key: v[assignment] for key, v in rve_constants(stack).items()})
        dev.moved = sum(a.nbytes for a in sources.values()) + sum(
            getattr(host, n).nbytes for n in sources if n not in DEVICE_ONLY + LISTS)
        return dev

    @property
    def n_rve(self) -> int:
        return self.host.n_rve

    @property
    def n_particles(self) -> int:
        return self.host.n_particles

    def device_bytes(self) -> int:
        """Bytes of the resident state on the device (the kernel's per-block scratch
        aside, cuda_kernel._scratch)."""
        return int(sum(d.nbytes for d in self.arrays.values()))

    # -------------------------------------------------------------- host <-> device
    def push(self, rows=None) -> None:
        """Copy the host state to the device: all of it (allocating the device arrays
        anew, so a capacity regrown on the host is taken), or the RVEs `rows`. A lean
        batch has no host state to push: `put`."""
        if self.lean:
            raise ValueError("a batch built on the device has no host state to push; "
                             "write rows with put")
        sources = _sources(self.host)
        if rows is None:
            for name, a in sources.items():
                if not a.flags.c_contiguous:
                    raise ValueError(f"RVE state array {name!r} is not C-contiguous")
                self.arrays[name] = cuda.to_device(a)
                self.moved += a.nbytes
            return
        for r in np.atleast_1d(rows):  # slices r:r+1 (an index of a 1-D array is a value)
            for name, a in sources.items():
                a = a[r:r + 1]
                self.arrays[name][r:r + 1].copy_to_device(np.ascontiguousarray(a))
                self.moved += a.nbytes

    def pull(self, rows=None) -> RVEBatch:
        """Copy the device state to the host batch (all RVEs, or `rows`); returns it.
        The per-sphere masses and radii never change on the device: not copied. A lean
        batch's rows are read with `take` (its host has no room for them)."""
        if self.lean:
            raise ValueError("a batch built on the device keeps its state there; read "
                             "rows with take")
        names = [n for n in self.names if n not in UNCHANGED]
        if rows is None:
            for name in names:
                self.arrays[name].copy_to_host(getattr(self.host, name))
                self.moved += getattr(self.host, name).nbytes
            return self.host
        for r in np.atleast_1d(rows):
            for name in names:
                row = self.arrays[name][r:r + 1].copy_to_host()
                getattr(self.host, name)[r:r + 1] = row
                self.moved += row.nbytes
        return self.host

    def take(self, rows) -> RVEBatch:
        """A host copy of the RVEs `rows` (full state, gathered on the device, so only
        they cross; the per-RVE arrays the device does not hold, h0 and the counts, from
        the host, where they are current)."""
        rows = np.atleast_1d(np.asarray(rows, np.int64))
        k = len(rows)
        out = allocate(k, self.n_particles, self.host.capacity, self.host.ft.shape[3],
                       self.host.bm.shape[1])
        if k == 0:
            return out
        d_rows = cuda.to_device(rows)
        d_at = cuda.to_device(np.arange(k, dtype=np.int64))
        for name in self.names:
            if name in LISTS:  # made from `body` again wherever needed
                continue
            src = self.arrays[name]
            tmp = cuda.device_array((k, *src.shape[1:]), src.dtype)
            _copy_rows[k, _COPY](_rows2d(src), d_rows, _rows2d(tmp), d_at)
            tmp.copy_to_host(getattr(out, name))
            self.moved += tmp.nbytes
        for name in RVEBatch.__dataclass_fields__:  # per RVE, kept on the host only
            if name not in self.names and name not in DEVICE_ONLY:
                getattr(out, name)[:] = getattr(self.host, name)[rows]
        return out

    def put(self, rows, batch: RVEBatch) -> None:
        """Write `batch` (as many RVEs as `rows`, this batch's sphere count and capacity)
        into the RVEs `rows`, on the device (scattered there) and in the host mirror."""
        rows = np.atleast_1d(np.asarray(rows, np.int64))
        if batch.n_rve != len(rows):
            raise ValueError(f"put: {batch.n_rve} RVEs for {len(rows)} rows")
        if len(rows) == 0:
            return
        d_rows = cuda.to_device(rows)
        d_at = cuda.to_device(np.arange(len(rows), dtype=np.int64))
        for name, a in _sources(batch).items():
            a = np.ascontiguousarray(a)
            _copy_rows[len(rows), _COPY](_rows2d(cuda.to_device(a)), d_at,
                                         _rows2d(self.arrays[name]), d_rows)
            self.moved += a.nbytes
        for name in RVEBatch.__dataclass_fields__:
            if not (self.lean and name in DEVICE_ONLY):
                getattr(self.host, name)[rows] = getattr(batch, name)
        for key, v in rve_constants(batch).items():
            self.constants[key][rows] = v

    def remove(self, rows) -> np.ndarray:
        """Drop the RVEs `rows`, on the device and in the host (state.remove_rves'
        scheme: the last RVEs that stay move into the holes; the arrays become views of
        their first rows, so the device memory is kept). Returns `order`, order[i] the
        former index of RVE i."""
        gone = np.unique(np.asarray(rows, np.int64))
        keep = self.n_rve - gone.size
        holes = gone[gone < keep]
        movers = np.setdiff1d(np.arange(keep, self.n_rve), gone)
        order = np.arange(keep)
        order[holes] = movers
        if holes.size:
            d_from = cuda.to_device(movers)
            d_to = cuda.to_device(holes)
            for name in self.names:
                a = _rows2d(self.arrays[name])
                _copy_rows[holes.size, _COPY](a, d_from, a, d_to)
        self.arrays = {name: a[:keep] for name, a in self.arrays.items()}
        self.host = lean_copy(self.host, order) if self.lean else self.host.take(order)
        self.constants = {key: v[order] for key, v in self.constants.items()}
        self._zeros = {}
        return order

    def grow(self, capacity: int) -> None:
        """Widen the neighbour lists to `capacity` slots on the device (lists and
        history kept; the new slots empty), one array at a time, so that the extra
        device memory at any moment is one new array; the host mirror follows."""
        k = self.host.capacity
        if capacity <= k:
            return
        for name, fill in (("nbr_j", 0), ("nbr_shift", 13), ("ft", 0)):
            old = self.arrays[name]
            r, n = old.shape[:2]
            c = old.shape[3] if old.ndim == 4 else 1
            shape = (r, n, capacity, *old.shape[3:])
            try:
                new = cuda.device_array(shape, old.dtype)
            except cuda.cudadrv.driver.CudaAPIError as err:
                raise MemoryError(
                    f"widening the neighbour lists from {k} to {capacity} slots (a row "
                    f"outgrew them) needs {np.prod(shape) * old.dtype.itemsize / 1e9:.2f} "
                    f"GB more on the GPU for {name!r}, which it does not have ({err}); "
                    "run fewer RVEs per GPU") from None
            if r * n:
                _copy_slots[r * n, _COPY](old.reshape(r * n, k, c),
                                          new.reshape(r * n, capacity, c), fill)
            self.arrays[name] = new
            del old
        if self.lean:  # the same host object: its holders (a material's groups) keep it
            for name in ("nbr_j", "nbr_shift", "ft"):
                a = getattr(self.host, name)
                setattr(self.host, name,
                        _placeholder((*a.shape[:2], capacity, *a.shape[3:]), a.dtype))
        else:
            grow_capacity(self.host, capacity)

    def pull_field(self, name: str) -> np.ndarray:
        """Copy one state array (a STATE_ARGS name, e.g. the kernel's step_count) from
        the device to the host; returns it: the host batch's array, or, for a per-sphere
        array of a lean batch, a new one."""
        d = self.arrays[name]
        if self.lean and name in DEVICE_ONLY:
            a = d.copy_to_host()
        else:
            a = getattr(self.host, name)
            d.copy_to_host(a)
        self.moved += a.nbytes
        return a

    def copy_field(self, src: str, dst: str) -> None:
        """State array dst <- src on the device and in the host mirror (per-RVE arrays
        of one shape, e.g. the servo's sampled stress from the stress)."""
        self.arrays[dst].copy_to_device(self.arrays[src])
        getattr(self.host, dst)[:] = getattr(self.host, src)

    # ------------------------------------------------------------------ one pass
    def _control(self, ctl, name: str):
        a = np.ascontiguousarray(getattr(ctl, name))
        if name in ALWAYS_SENT or a.any():
            self.moved += a.nbytes
            return cuda.to_device(a)
        key = (name, a.shape, a.dtype.str)
        if key not in self._zeros:
            self._zeros[key] = cuda.to_device(a)
        return self._zeros[key]

    def step(self, nsteps, law, ctl, status: np.ndarray, out: np.ndarray) -> None:
        """One kernel pass (engine.advance's loop body): nsteps (R,) int64, kernel
        ContactLaw and Controls, status (R,) and out (R,6) written on the host, with
        UP_EACH_CALL into `host`."""
        nsteps = np.ascontiguousarray(nsteps, np.int64)
        d_nsteps = cuda.to_device(nsteps)
        dctl = [self._control(ctl, name) for name in CONTROL_ARGS]
        d_status = cuda.to_device(status)  # out keeps what the kernel does not write
        d_out = cuda.to_device(out)
        self.moved += nsteps.nbytes + status.nbytes + out.nbytes
        dcl = (tuple(self.arrays[n] for n in (*CLUMP_ARGS, *LISTS)) if self.host.clumped
               else None)
        cuda_kernel.launch(d_nsteps, law, [self.arrays[n] for n in STATE_ARGS], dctl,
                           ctl.dt, ctl.servo_gain, d_status, d_out, dcl=dcl)
        d_status.copy_to_host(status)
        d_out.copy_to_host(out)
        self.moved += status.nbytes + out.nbytes
        for name in UP_EACH_CALL:
            self.arrays[name].copy_to_host(getattr(self.host, name))
            self.moved += getattr(self.host, name).nbytes

    def not_finite(self) -> np.ndarray:
        """(R,) True where an RVE's cell, stress, positions, velocities or spins hold a
        NaN or an infinity (engine.not_finite, evaluated on the device)."""
        if self.n_rve == 0:
            return np.zeros(0, np.bool_)
        flag = cuda.device_array(self.n_rve, np.int32)
        a = self.arrays
        _not_finite_rows[self.n_rve, _REDUCE](a["h"], a["stress"], a["s"], a["v"], a["w"],
                                              flag)
        host = flag.copy_to_host()
        self.moved += host.nbytes
        return host != 0

    def mean_rotation(self) -> np.ndarray:
        """homogenise.mean_rotation on the device: (R,) mean accumulated rolling angle
        [rad] (seed Eq. 15); equal to the host's at round-off (another summation order)."""
        if self.n_rve == 0:
            return np.zeros(0)
        d = cuda.device_array(self.n_rve, np.float64)
        _row_means[self.n_rve, _REDUCE](self.arrays["rot"], d)
        host = d.copy_to_host()
        self.moved += host.nbytes
        return host


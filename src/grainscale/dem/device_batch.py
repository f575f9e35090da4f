"""RVE batches whose state lives on the GPU for a whole run (solver.device = "cuda").

A `DeviceBatch` holds the device copy of an `RVEBatch`'s state (the arrays of
cuda_kernel.STATE_ARGS) and its host batch, `host`. `engine.advance` on a DeviceBatch runs
the kernel on the device arrays; per call only the step counts and the controls go down
and the small per-RVE results come up:

    down: nsteps, status and out (56 B), e_step and l_mean (72 B each); the other
          controls only when not all zero (an MPM increment has none)
    up:   status (8 B), out (40 B: contacts, unbalanced ratio, kinetic energy, ...),
          h, stress and stiffness (72 B each), the non-finite flag (4 B)

so after a call `host.h`, `host.stress`, `host.stiffness`, `host.ncontact`,
`host.unbalanced` and `host.kinetic` are current and every other host array is stale.
Whatever needs the rest (a checkpoint, a probe frame, cell reduction, retiling, a
capacity regrowth) calls `pull` first, explicitly, and `push` after changing the host
state. `moved` counts the bytes that crossed, both ways.
"""

from __future__ import annotations

import numpy as np
from numba import cuda, float64

from grainscale.dem import cuda_kernel
from grainscale.dem.state import RVEBatch

STATE_ARGS = cuda_kernel.STATE_ARGS
CONTROL_ARGS = cuda_kernel.CONTROL_ARGS
UP_EACH_CALL = ("h", "stress", "stiffness")  # host copies kept current by every call
ALWAYS_SENT = ("e_step", "l_mean")  # the controls of an increment; others when non-zero
_REDUCE = 128  # threads of the per-RVE reductions below


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


class DeviceBatch:
    """The state of `host` (an RVEBatch) on the current GPU, kept there between calls."""

    def __init__(self, host: RVEBatch):
        self.host = host
        self.moved = 0  # bytes copied between host and device, both ways
        self.arrays: dict[str, object] = {}
        self._zeros: dict[tuple, object] = {}  # device zeros standing for unsent controls
        self.push()

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
        anew, so a capacity regrown on the host is taken), or the RVEs `rows`."""
        if rows is None:
            for name in STATE_ARGS:
                a = getattr(self.host, name)
                if not a.flags.c_contiguous:
                    raise ValueError(f"RVE state array {name!r} is not C-contiguous")
                self.arrays[name] = cuda.to_device(a)
                self.moved += a.nbytes
            return
        for r in np.atleast_1d(rows):  # slices r:r+1 (an index of a 1-D array is a value)
            for name in STATE_ARGS:
                a = getattr(self.host, name)[r:r + 1]
                self.arrays[name][r:r + 1].copy_to_device(np.ascontiguousarray(a))
                self.moved += a.nbytes

    def pull(self, rows=None) -> RVEBatch:
        """Copy the device state to the host batch (all RVEs, or `rows`); returns it.
        The per-sphere masses and radii never change on the device: not copied."""
        names = [n for n in STATE_ARGS if n not in cuda_kernel.READ_ONLY]
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

    def pull_field(self, name: str) -> np.ndarray:
        """Copy one state array (a STATE_ARGS name, e.g. the kernel's step_count) from
        the device into the host batch; returns the host array."""
        a = getattr(self.host, name)
        self.arrays[name].copy_to_host(a)
        self.moved += a.nbytes
        return a

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
        ContactLaw and Controls, status (R,) and out (R,5) written on the host, with
        UP_EACH_CALL into `host`."""
        nsteps = np.ascontiguousarray(nsteps, np.int64)
        d_nsteps = cuda.to_device(nsteps)
        dctl = [self._control(ctl, name) for name in CONTROL_ARGS]
        d_status = cuda.to_device(status)  # out keeps what the kernel does not write
        d_out = cuda.to_device(out)
        self.moved += nsteps.nbytes + status.nbytes + out.nbytes
        cuda_kernel.launch(d_nsteps, law, [self.arrays[n] for n in STATE_ARGS], dctl,
                           ctl.dt, ctl.servo_gain, d_status, d_out)
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

"""Driving the batched DEM kernel from Python: parameters, cell control, time step.

`advance` is the one entry point for every use of the DEM (element tests, generation,
the MPM material): it runs the compiled kernel, regrows neighbour capacity when a list
overflows and retries, and turns kernel status codes into clear errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from grainscale.config.base import ConfigError
from grainscale.config.rve import Numerics
from grainscale.dem import hertz
from grainscale.dem.kernel import (
    OUT_WIDTH,
    Clumps,
    ContactLaw,
    Controls,
    RveState,
    advance_batch,
)
from grainscale.dem.neighbours import Status
from grainscale.dem.state import (
    HISTORY,
    HISTORY_ROLLING,
    RVEBatch,
    body_lever,
    grow_capacity,
    with_history,
)


class RVEError(RuntimeError):
    """An RVE cannot go on (cell too thin for its spheres, motion not finite); carries
    the index of the RVE in its batch."""

    def __init__(self, rve: int, message: str):
        super().__init__(message)
        self.rve = rve


@dataclass(frozen=True)
class ContactParams:
    """Contact law and damping: the linear law (seed Eq. 7-10) or Hertz-Mindlin
    (dem/hertz.py), with Coulomb friction and, optionally, rolling resistance."""

    young: float            # E [Pa]; linear: kn = E r*; Hertz-Mindlin: the grains' modulus
    stiffness_ratio: float  # kt / kn (linear; Hertz-Mindlin: from poisson)
    friction: float         # mu = tan(phi_interparticle)
    damping: float          # Cundall local non-viscous damping coefficient [0, 1); [rve]
    skin: float = 1e-3      # Verlet skin [m]
    restitution: float = 1.0  # normal coefficient of restitution e, (0, 1]; 1: elastic
    rolling_stiffness: float = 0.0  # alpha_r in k_r = alpha_r kt r_i r_j; 0: no rolling law
    rolling_friction: float = 0.0   # eta_r in |M_r| <= eta_r min(r_i, r_j) f_n
    contact_law: str = "linear"     # or "hertz_mindlin"
    poisson: float = 0.0            # nu (Hertz-Mindlin)
    max_overlap: float = 0.01       # Hertz-Mindlin: largest delta / R* the step is set for

    @property
    def hertz(self) -> bool:
        return self.contact_law == "hertz_mindlin"

    @property
    def history(self) -> int:
        """Components of a contact's history this law keeps (state.HISTORY*)."""
        return HISTORY_ROLLING if self.rolling_stiffness > 0.0 else HISTORY

    @property
    def kt_ratio(self) -> float:
        """kt / kn of the law: the given ratio (linear), 2 (1 - nu) / (2 - nu) (Hertz)."""
        return hertz.stiffness_ratio(self.poisson) if self.hertz else self.stiffness_ratio

    @property
    def hertz_kn(self) -> float:
        """2 E* [Pa], the tangent normal stiffness per contact radius (Hertz-Mindlin);
        0 for the linear law (the kernels' switch)."""
        return 2.0 * hertz.effective_modulus(self.young, self.poisson) if self.hertz else 0.0

    @property
    def gamma(self) -> float:
        """Damping ratio of the normal dashpot c_n = 2 gamma sqrt(m* kn) that restitutes
        e: -ln e / sqrt(pi^2 + ln^2 e) for a linear spring, hertz.TSUJI = sqrt(5/6) times
        that for a Hertzian one (kn its tangent stiffness); 0 for e = 1."""
        le = math.log(self.restitution)
        gamma = -le / math.sqrt(math.pi**2 + le * le)
        return hertz.TSUJI * gamma if self.hertz else gamma


@dataclass
class Control:
    """How the cell moves during a call: fixed hdot plus a velocity gradient with servos.

    h_new = e_step h + dt (hdot_fixed + L h), where L = l_ctrl except on the components with
    servo_mask = 1 (upper triangle read; a shear servo moves L_ab = L_ba), which follow a
    proportional servo to servo_target (Cauchy, tension positive, Pa): per step the
    strain change is servo_gain x (stress error) / (affine stiffness), clipped to
    max_rate [1/s]. e_step is an exact per-step map (identity unless an MPM increment
    is applied) and l_mean its velocity gradient log(e_step)/dt, used for contact
    velocities.
    """

    hdot_fixed: np.ndarray    # (R,3,3) [m/s]
    l_ctrl: np.ndarray        # (R,3,3) [1/s]
    servo_mask: np.ndarray    # (R,3,3) int32
    servo_target: np.ndarray  # (R,3,3) [Pa]
    servo_gain: float = 0.05
    max_rate: np.ndarray | None = None  # (R,) [1/s]
    e_step: np.ndarray | None = None    # (R,3,3) [-], default identity
    l_mean: np.ndarray | None = None    # (R,3,3) [1/s], default zero


def rate_control(n_rve: int, l_ctrl=None, servo: dict | None = None,
                 max_rate: float = 1.0, gain: float = 0.05) -> Control:
    """Velocity-gradient control with servos {component: target stress [Pa]}.

    A component is an axis (0, 1, 2) for a normal stress or a pair (a, b) for a shear
    stress; targets are Cauchy, tension positive.
    """
    lc = np.zeros((n_rve, 3, 3)) if l_ctrl is None else np.broadcast_to(
        np.asarray(l_ctrl, float), (n_rve, 3, 3)).copy()
    mask = np.zeros((n_rve, 3, 3), np.int32)
    target = np.zeros((n_rve, 3, 3))
    for comp, value in (servo or {}).items():
        a, b = sorted((comp, comp) if isinstance(comp, int) else comp)
        mask[:, a, b] = 1
        target[:, a, b] = value
        lc[:, a, b] = lc[:, b, a] = 0.0
    return Control(np.zeros((n_rve, 3, 3)), lc, mask, target, gain,
                   np.full(n_rve, float(max_rate)))


def _logm_near_identity(a: np.ndarray) -> np.ndarray:
    """log(I + a) for a batch (R,3,3) of small a by its power series [-]; RVEError names
    the first RVE whose |a| is too large for it to converge, or not finite."""
    norms = np.linalg.norm(a, axis=(1, 2))
    bad = np.flatnonzero(~(norms < 0.5))  # NaN counts as bad
    if bad.size:
        r = int(bad[0])
        raise RVEError(r, f"displacement-gradient increment too large: |dH| = "
                          f"{norms[r]:.3g} (must be < 0.5; take smaller MPM steps)")
    norm = norms.max(initial=0.0)
    out = np.zeros_like(a)
    term = np.broadcast_to(np.eye(3), a.shape).copy()
    for k in range(1, 64):
        term = term @ a
        out += ((-1) ** (k + 1) / k) * term
        if norm**k / k < 1e-18:
            break
    return out


def _expm_small(x: np.ndarray) -> np.ndarray:
    """exp(x) for a batch (R,3,3) of small x by its Taylor series [-]."""
    out = np.broadcast_to(np.eye(3), x.shape).copy()
    term = out.copy()
    for k in range(1, 32):
        term = term @ x / k
        out += term
        if np.abs(term).max(initial=0.0) < 1e-20:
            break
    return out


def increment_control(batch: RVEBatch, dH: np.ndarray, nsteps, dt: float) -> Control:
    """Deform each cell by h <- (I + dH) h over nsteps steps of dt, at a constant L.

    Each step maps h to E h with E = exp(log(I + dH)/n), so after n steps h is exactly
    (I + dH) h_0 and every intermediate cell lies on the constant-velocity-gradient path
    L = log(I + dH)/(n dt): a rotation stays a rotation at every step (no spurious
    stretch, objectivity). dH (R,3,3), dH[a,b] = du_a/dx_b; nsteps one count or per RVE.
    Contacts see the path's velocity gradient L = log(E)/dt exactly.
    """
    r = batch.n_rve
    dH = np.broadcast_to(np.asarray(dH, float), (r, 3, 3))
    n = np.broadcast_to(np.asarray(nsteps, float), (r,))
    log_step = _logm_near_identity(dH) / n[:, None, None]
    zero = np.zeros((r, 3, 3))
    return Control(zero, zero.copy(), np.zeros((r, 3, 3), np.int32), zero.copy(), 0.0,
                   np.zeros(r), e_step=_expm_small(log_step), l_mean=log_step / dt)


def contact_law(params: ContactParams) -> ContactLaw:
    """The kernels' ContactLaw of a ContactParams."""
    return ContactLaw(float(params.young), float(params.kt_ratio),
                      float(params.friction), float(params.gamma), float(params.damping),
                      float(params.skin), float(params.rolling_stiffness),
                      float(params.rolling_friction), float(params.hertz_kn))


def rve_arrays(batch: RVEBatch) -> RveState:
    """The kernels' RveState of a batch: its arrays, not copies."""
    return RveState._make(getattr(batch, name) for name in RveState._fields)


def clump_arrays(batch: RVEBatch) -> Clumps | None:
    """The kernels' Clumps of a clumped batch (its arrays, not copies); None for plain
    spheres."""
    if not batch.clumped:
        return None
    return Clumps._make(getattr(batch, name) for name in Clumps._fields)


def critical_dt(batch: RVEBatch, params: ContactParams,
                safety: float = Numerics().timestep_safety) -> float:
    """safety x sqrt(m_min / k_max) [s], k_max the stiffest possible contact: E r_max
    (linear, kn = E r* <= E r_max), or the Hertzian tangent stiffness 2 E* sqrt(R* delta)
    at the largest overlap the law admits, delta = max_overlap R*, R* <= r_max / 2:
    E* r_max sqrt(max_overlap) (a larger overlap stops the run: `advance`). Divided by
    sqrt(1 + alpha_r r_max / r_min) with rolling resistance.

    kt <= kn in both laws (Hertz-Mindlin: kt/kn = 2 (1 - nu)/(2 - nu)), which the safety
    factor was chosen for. The rotation of grain i about an axis in a contact plane is
    held by the tangential spring, kt l_i^2 ~ kt r_i^2, and the rolling spring, alpha_r kt
    r_i r_j: against its inertia 0.4 m_i r_i^2 the rolling spring raises the squared
    frequency of that mode by the factor 1 + alpha_r r_j / r_i <= 1 + alpha_r r_max /
    r_min, so the step shrinks by its square root (alpha_r = 0: unchanged).

    A clump (state.RVEBatch.clumped) is held by its contacts in translation, k/M, and in
    rotation, k l^2/J_a, with l the largest lever from its centre to its surface
    (state.body_lever): its mass in the bound is min(M, J_min/l^2) (for a two-sphere
    grain of aspect 2, 0.35 M, the rotation)."""
    if params.hertz:
        k_max = 0.5 * params.hertz_kn * batch.radius.max() * math.sqrt(params.max_overlap)
    else:
        k_max = params.young * batch.radius.max()
    if batch.clumped:
        m_min = float(np.minimum(batch.bm, batch.bj.min(axis=2) / body_lever(batch)**2).min())
    else:
        m_min = float(batch.mass.min())
    dt = safety * math.sqrt(m_min / k_max)
    if params.rolling_stiffness > 0.0:
        spread = float(batch.radius.max() / batch.radius.min())
        dt /= math.sqrt(1.0 + params.rolling_stiffness * spread)
    return dt


DEVICES = ("cpu", "cuda")  # the values of `device` (case file: solver.device)


class DeviceError(ConfigError):
    """The DEM device asked for (solver.device, --device) is unknown or not available."""


def check_device(device: str) -> None:
    """Raise DeviceError unless `device` is one of DEVICES and can run here."""
    if device not in DEVICES:
        raise DeviceError(f"solver.device = {device!r}: unknown; valid values: "
                          f"{', '.join(map(repr, DEVICES))}")
    if device == "cuda":
        try:
            from grainscale.dem import cuda_kernel
        except ImportError as err:
            raise DeviceError(f"solver.device = 'cuda': numba.cuda cannot be imported "
                              f"({err}); valid values: 'cpu', or 'cuda' with an NVIDIA GPU "
                              "and the `cuda` extra (pip install grainscale[cuda])") from None
        if not cuda_kernel.is_available():
            raise DeviceError("solver.device = 'cuda': no usable CUDA GPU here "
                              "(numba.cuda.is_available() is False); valid values: 'cpu', "
                              "or 'cuda' on a machine with an NVIDIA GPU, its driver and "
                              "the `cuda` extra (pip install grainscale[cuda])")


def advance(batch, nsteps, dt: float, params: ContactParams,
            control: Control, device: str = "cpu"):
    """Advance every RVE by nsteps (int or (R,) array) steps of dt, in place; then each
    RVE that stepped has the stress, moduli and contact count of the state it reached
    (kernel.py, item 8). nsteps = -1: no step, only that evaluation (refresh).

    device "cpu" runs kernel.advance_batch (numba threads over RVEs), "cuda"
    cuda_kernel.advance_batch (one GPU block per RVE; a host batch goes to the device
    and back once per pass of the loop below, i.e. once per call unless a list
    overflows): the same physics, agreeing at round-off (cuda_kernel's docstring).

    `batch` may also be a device_batch.DeviceBatch, whose state stays on the GPU (device
    is then "cuda" whatever is passed): only the step counts, controls and per-RVE
    results cross, and a capacity overflow widens the lists on the device.

    A host batch whose contact history lacks the rolling moments that `params` needs
    gets zero moments (state.with_history)."""
    resident = not isinstance(batch, RVEBatch)
    host = batch.host if resident else batch
    if host.ft.shape[3] != params.history:
        if resident:
            raise ValueError(f"the device batch keeps {host.ft.shape[3]} history components "
                             f"a contact, this contact law {params.history}")
        with_history(host, params.history)  # zero moments, or refused if it holds some
    clumps = clump_arrays(host) if not resident else None
    if resident:
        step_batch = None
    elif device == "cpu":
        step_batch = advance_batch
    else:
        check_device(device)
        from grainscale.dem import cuda_kernel

        step_batch = cuda_kernel.advance_batch
    remaining = np.broadcast_to(np.asarray(nsteps, np.int64), (host.n_rve,)).copy()
    if np.any(remaining < -1):
        raise ValueError(f"nsteps = {int(remaining.min())}: must be >= -1")
    owed = remaining != 0  # the end-of-increment evaluation is still to be done
    status = np.zeros(host.n_rve, np.int64)
    out = np.zeros((host.n_rve, OUT_WIDTH))
    r = host.n_rve
    max_rate = control.max_rate if control.max_rate is not None else np.zeros(r)
    e_step = control.e_step if control.e_step is not None else np.broadcast_to(
        np.eye(3), (r, 3, 3)).copy()
    l_mean = control.l_mean if control.l_mean is not None else np.zeros((r, 3, 3))
    law = contact_law(params)
    ctl = Controls(float(dt), e_step, l_mean, control.hdot_fixed, control.l_ctrl,
                   control.servo_mask, control.servo_target, float(control.servo_gain),
                   max_rate)
    while owed.any():
        # the state is read afresh each pass: a capacity regrowth replaces its arrays.
        # An RVE whose steps are done but whose evaluation a list overflow stopped is
        # called with -1; one owing nothing with 0 (it keeps its outputs)
        call = np.where(remaining > 0, remaining, np.where(owed, -1, 0))
        if resident:
            batch.step(call, law, ctl, status, out)
        elif clumps is not None:
            step_batch(call, law, rve_arrays(batch), ctl, status, out, cl=clumps)
        else:
            step_batch(call, law, rve_arrays(batch), ctl, status, out)
        done = out[:, 4].astype(np.int64)
        remaining -= done
        ended = owed & (remaining <= 0) & (status == Status.OK)
        host.ncontact[ended] = out[ended, 0]
        host.unbalanced[ended] = out[ended, 1]
        host.kinetic[ended] = out[ended, 2]
        owed &= ~ended
        _check(batch, status, out)
    if params.hertz and np.any(out[:, 5] > params.max_overlap):
        r = int(np.argmax(out[:, 5]))
        raise RVEError(r,
            f"RVE {r}: a Hertzian overlap reached delta/R* = {out[r, 5]:.3g}, above "
            f"rve.numerics.max_overlap = {params.max_overlap:g}, the largest the time step "
            f"was set for (engine.critical_dt); valid: max_overlap above it (a smaller "
            f"step), or stiffer grains (young_modulus) for this stress")
    return batch


@njit(cache=True)
def _any_not_finite(a):
    """True if a holds a NaN or an infinity: x - x is 0 for finite x only.

    No fastmath here, on purpose: under it LLVM may take x - x as 0 (as it may fold an
    isfinite away), which is why the fastmath kernels do not test finiteness themselves.
    The comparisons are independent and or-ed, so the loop vectorises without it."""
    bad = False
    flat = a.reshape(-1)
    for k in range(flat.size):
        x = flat[k]
        bad |= x - x != 0.0
    return bad


@njit(cache=True)
def _not_finite_rows(h, stress, s, v, w, out):
    for r in range(h.shape[0]):
        out[r] = (_any_not_finite(h[r]) | _any_not_finite(stress[r]) | _any_not_finite(s[r])
                  | _any_not_finite(v[r]) | _any_not_finite(w[r]))


def not_finite(batch: RVEBatch) -> np.ndarray:
    """(R,) True where an RVE's cell, positions, velocities, spins or stress hold a NaN or
    an infinity.

    Checked after the kernels return, outside them: the kernels are fastmath, under which
    LLVM may assume that no value is NaN or infinite and fold a test away. A NaN anywhere
    in an RVE reaches these arrays within a step through its contacts (a rattler's spin
    aside). About 1 us per call for a 150-sphere RVE, whose every DEM step takes ~14 us.
    """
    out = np.empty(batch.n_rve, np.bool_)
    _not_finite_rows(batch.h, batch.stress, batch.s, batch.v, batch.w, out)
    return out


def _check(batch, status: np.ndarray, out: np.ndarray) -> None:
    """Errors of a kernel pass, and a capacity regrowth on overflow; `batch` an RVEBatch
    or a DeviceBatch (checked and regrown on the device)."""
    resident = not isinstance(batch, RVEBatch)
    bad = (batch.not_finite() if resident else not_finite(batch)) | (
        status == Status.NOT_FINITE)
    if np.any(bad):
        r = int(np.argmax(bad))
        raise RVEError(r,
            f"RVE {r}: motion became non-finite (time step too large for the stiffness?)")
    if np.any(status == Status.OVERFLOW):
        need = int(out[status == Status.OVERFLOW, 3].max())
        capacity = max(need + 4, int(1.5 * (batch.host.capacity if resident
                                            else batch.capacity)))
        if resident:  # widened on the device (a batch built there has no host copy)
            batch.grow(capacity)
        else:
            grow_capacity(batch, capacity)
    if np.any(status == Status.TOO_THIN):
        r = int(np.argmax(status == Status.TOO_THIN))
        raise RVEError(r,
            f"RVE {r}: periodic cell too thin for its spheres (a perpendicular width is "
            f"below 2 x (2 r_max + skin)); it is too small or too distorted for this "
            f"deformation; use more particles")


def refresh(batch, params: ContactParams):
    """Evaluate forces, stress, moduli and contacts of the current configuration (no
    motion, the tangential history left as it is): the end-of-increment evaluation of
    `advance` alone, so refreshing a state that `advance` left changes nothing.
    `batch`: an RVEBatch, or a DeviceBatch (evaluated on the GPU)."""
    advance(batch, -1, 0.0, params, rate_control(batch.n_rve))
    if isinstance(batch, RVEBatch):
        batch.stress_servo[:] = batch.stress
    else:
        batch.copy_field("stress", "stress_servo")
    return batch

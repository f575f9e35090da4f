"""The batched DEM step: contact forces, Love-Weber stress, integration, cell motion.

One compiled call advances R RVEs by their own number of steps, `prange` over RVEs; the
work of one RVE never touches another's arrays, so an RVE alone and the same RVE inside
a batch follow the same arithmetic. Nothing is allocated per step.

Per step of one RVE (dt fixed), in the order the code runs:
1. neighbour list: rebuilt first if the last step's check (7) flagged it.
2. cell control: h_new = E h + dt (hdot_fixed + L_c h), with E a fixed step map (the
   MPM increment: exp(log(I + dH)/n)) and L_c = L_ctrl except that each servo-controlled
   component is replaced by
   L_kk = g (sigma*_kk - sigma_kk) / (C_kk dt) on the diagonal and, for a shear pair,
   L_ab = L_ba = g (sigma*_ab - sym sigma_ab) / (2 C_ab dt) (clipped to +-max_rate),
   where C_ab = (1/V) sum kn |d|^2 n_a^2 n_b^2 is the affine stiffness of the last step;
   the mean-field velocity gradient is L = L_mean + (hdot_fixed + L_c h) h^-1, where
   L_mean = log(E)/dt is the exact rate of the step map (skew for a rotation).
3. contacts over the half list, in the current cell h (seed Eq. 7-10): kn = E r*,
   r* = 2 ri rj/(ri + rj), kt = ratio kn; f_n = kn delta; tangential force history
   rotated with the contact frame, incremented by kt v_t dt and capped at mu f_n. The
   relative velocity includes the mean-field term D d across periodic images (D = sym L:
   the mean field carries a pair rigidly with its spin W = skew L, which only turns the
   contact frame), and particle spins w are fluctuations about W; a rigidly rotating
   cell therefore makes no slip at any contact (objectivity).
4. in the same pass over the contacts, on servo samples and on the last step of a call:
   Love-Weber stress sigma = (1/V) sum_c d (x) f (seed Eq. 11), with f the force on the
   first particle and d = x_j - x_i, so compression is negative (tension positive), minus
   the kinetic stress (1/V) sum m v' (x) v' of the fluctuating velocities v', and
   the affine stiffness C_ab. Without a servo, `stiffness` holds the last step's C (the
   MPM's wave speed reads it).
5. h <- h_new, and h_new^-1 for 6.
6. leapfrog with Cundall's local non-viscous damping on the fluctuating motion and the
   pseudo-force of the co-moving frame (SLLOD): v += dt (F - alpha |F| sign v)/m
   - dt L v, rotation without it (spins are about W); s += h_new^-1 v dt;
   accumulated rotation += |w| dt.
7. list check: flag a rebuild (done at 1 of the next step) when
   2 max|u'| + |h h_ref^-1 - I|_F cutoff >= skin (u' = h (s - s_ref) the fluctuating
   displacement since the build, bounded by sqrt(|h|_1 |h|_inf) |s - s_ref|): no pair
   can then have entered the cutoff unseen.

The kernels take their arguments as three named tuples: `RveState` (the arrays of the
RVEs, state and scratch), `ContactLaw` (the constants of the contact law, damping and
skin) and `Controls` (the time step and the cell control of a call). The batch kernel
gets them with a leading RVE axis and hands each RVE its slices (`rve_state`,
`rve_controls`).

Finiteness is not tested here: fastmath lets LLVM assume that no value is NaN or
infinite, so such a test may be folded away (an `isfinite` of the kinetic energy was,
with numba 0.68). engine.not_finite checks every RVE after each call instead, in a
compiled loop without fastmath. The kernels use numba's numpy error model: under fastmath
a NaN divisor may compare equal to zero, and the Python model would then raise
ZeroDivisionError inside the parallel loop (a bare SystemError, naming no RVE) instead of
letting the NaN through to that check.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from grainscale.dem.neighbours import Status, build, image_table
from grainscale.linalg3 import det3, inv3

SERVO_EVERY = 4  # steps between stress samples of a servo


class RveState(NamedTuple):
    """The arrays of the RVEs the kernels read and write, named as in state.RVEBatch (see
    there for units). In a batch every array has the RVE index first; `rve_state` slices
    one RVE out, with step_count and need_rebuild as views of length 1 so that the
    kernel's writes reach the batch."""

    h: np.ndarray             # cell matrix, edge vectors as columns
    s: np.ndarray             # fractional positions
    v: np.ndarray             # fluctuating velocities
    w: np.ndarray             # angular velocities about the mean-field spin
    rot: np.ndarray           # accumulated rolling angles
    radius: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    L: np.ndarray             # mean-field velocity gradient of the last step
    stress: np.ndarray        # Love-Weber stress (last step of a call)
    stress_servo: np.ndarray  # the stress the servo last sampled
    stiffness: np.ndarray     # affine stiffness C_ab
    step_count: np.ndarray    # steps taken
    nbr_j: np.ndarray         # neighbour list: index, image shift code, row lengths
    nbr_shift: np.ndarray
    nbr_count: np.ndarray
    ft: np.ndarray            # tangential force history
    s_ref: np.ndarray         # positions and cell at the last list build
    h_ref: np.ndarray
    need_rebuild: np.ndarray  # 1: build the list before the next step
    force: np.ndarray         # scratch: forces, torques, Cartesian positions, cell-list
    torque: np.ndarray        # links, image counts of the last wrap
    x: np.ndarray
    link: np.ndarray
    wrapv: np.ndarray


class ContactLaw(NamedTuple):
    """Constants of the contact law (seed Eq. 7-10), the damping and the Verlet skin; the
    same for every RVE of a batch (engine.ContactParams)."""

    young: float     # E [Pa]; kn = E r*
    kt_ratio: float  # kt / kn
    friction: float  # mu
    gamma: float     # damping ratio of the normal dashpot (0: elastic)
    damping: float   # Cundall local non-viscous damping coefficient
    skin: float      # Verlet skin [m]


class Controls(NamedTuple):
    """Time step and cell control of a call (engine.Control, resolved). In a batch the
    arrays have the RVE index first and max_rate is (R,); `rve_controls` slices one RVE
    out (max_rate then a float)."""

    dt: float                 # [s]
    e_step: np.ndarray        # (3,3) per-step map of the cell [-]
    l_mean: np.ndarray        # (3,3) its velocity gradient log(e_step)/dt [1/s]
    hdot_fixed: np.ndarray    # (3,3) [m/s]
    l_ctrl: np.ndarray        # (3,3) [1/s]
    servo_mask: np.ndarray    # (3,3) int32, upper triangle read
    servo_target: np.ndarray  # (3,3) [Pa]
    servo_gain: float
    max_rate: float           # [1/s]


@njit(cache=True, inline="always")
def rve_state(st, r):
    """The RveState of RVE r of a batch's RveState (views, nothing copied)."""
    return RveState(st.h[r], st.s[r], st.v[r], st.w[r], st.rot[r], st.radius[r], st.mass[r],
                    st.inertia[r], st.L[r], st.stress[r], st.stress_servo[r],
                    st.stiffness[r], st.step_count[r:r + 1], st.nbr_j[r], st.nbr_shift[r],
                    st.nbr_count[r], st.ft[r], st.s_ref[r], st.h_ref[r],
                    st.need_rebuild[r:r + 1], st.force[r], st.torque[r], st.x[r],
                    st.link[r], st.wrapv[r])


@njit(cache=True, inline="always")
def rve_controls(ctl, r):
    """The Controls of RVE r of a batch's Controls."""
    return Controls(ctl.dt, ctl.e_step[r], ctl.l_mean[r], ctl.hdot_fixed[r], ctl.l_ctrl[r],
                    ctl.servo_mask[r], ctl.servo_target[r], ctl.servo_gain, ctl.max_rate[r])


@njit(cache=True, inline="always")
def _sgn(a):
    """1 where a != 0, else 0: damping acts only on moving degrees of freedom."""
    return 1.0 if a != 0.0 else 0.0


@njit(cache=True, fastmath=True, error_model="numpy")
def contact_pass(dt, law, st, table, stress_out, stiff_out, homogenise):
    """Contact forces and torques of one RVE (RveState st, ContactLaw law) at its current
    configuration; table is (27,3) scratch for the image shifts.

    Normal force f_n = kn delta - c_n v_n (linear spring-dashpot; v_n > 0 separating),
    c_n = 2 gamma sqrt(m* kn), m* = mi mj/(mi + mj), gamma the damping ratio of the
    restitution coefficient (0: elastic). The dashpot is not clipped, so an isolated
    collision returns exactly e; the Coulomb cap uses max(f_n, 0).

    Updates the tangential history by dt (dt = 0 only re-projects it), fills force and
    torque (N) and, if `homogenise`, stress_out (3x3, Pa) and stiff_out (3x3 affine
    stiffness C_ab, Pa); skipping them saves a third of the work per contact. Returns
    (number of contacts, sum of normal contact forces [N]).
    """
    young, kt_ratio, friction, gamma = law.young, law.kt_ratio, law.friction, law.gamma
    h, s, v, w, radius, mass, L = st.h, st.s, st.v, st.w, st.radius, st.mass, st.L
    nbr_j, nbr_shift, nbr_count, ft = st.nbr_j, st.nbr_shift, st.nbr_count, st.ft
    force, torque, x = st.force, st.torque, st.x
    n = s.shape[0]
    for i in range(n):
        for d in range(3):
            x[i, d] = h[d, 0] * s[i, 0] + h[d, 1] * s[i, 1] + h[d, 2] * s[i, 2]
            force[i, d] = 0.0
            torque[i, d] = 0.0
    image_table(h, table)
    # mean-field spin (axial vector of the skew part of L) turns the contact frames
    sp0 = 0.5 * (L[2, 1] - L[1, 2])
    sp1 = 0.5 * (L[0, 2] - L[2, 0])
    sp2 = 0.5 * (L[1, 0] - L[0, 1])
    D00 = L[0, 0]
    D11 = L[1, 1]
    D22 = L[2, 2]
    D01 = 0.5 * (L[0, 1] + L[1, 0])
    D02 = 0.5 * (L[0, 2] + L[2, 0])
    D12 = 0.5 * (L[1, 2] + L[2, 1])
    sxx = sxy = sxz = syx = syy = syz = szx = szy = szz = 0.0
    c00 = c11 = c22 = c01 = c02 = c12 = 0.0
    ncontact = 0
    fsum = 0.0
    for i in range(n):
        xi0 = x[i, 0]
        xi1 = x[i, 1]
        xi2 = x[i, 2]
        ri = radius[i]
        fi0 = fi1 = fi2 = 0.0
        ti0 = ti1 = ti2 = 0.0
        for k in range(nbr_count[i]):
            j = nbr_j[i, k]
            t = nbr_shift[i, k]
            d0 = x[j, 0] - xi0 + table[t, 0]
            d1 = x[j, 1] - xi1 + table[t, 1]
            d2 = x[j, 2] - xi2 + table[t, 2]
            rj = radius[j]
            rr = ri + rj
            dist2 = d0 * d0 + d1 * d1 + d2 * d2
            if dist2 >= rr * rr:
                ft[i, k, 0] = 0.0
                ft[i, k, 1] = 0.0
                ft[i, k, 2] = 0.0
                continue
            dist = math.sqrt(dist2)
            inv2 = 1.0 / (dist * rr)  # one division serves 1/dist and 1/rr
            inv = inv2 * rr
            n0 = d0 * inv
            n1 = d1 * inv
            n2 = d2 * inv
            kn = young * 2.0 * ri * rj * dist * inv2
            fn = kn * (rr - dist)
            # relative velocity of j's surface w.r.t. i's at the contact point. The mean
            # field moves the pair rigidly with its spin W, so only its strain rate D
            # enters (a spinning cell makes no slip); particle spins w are fluctuations
            # about W.
            # lever arms to the contact point in the middle of the overlap: a pair
            # turning rigidly (li + lj = |d|) then makes no slip
            half = 0.5 * (rr - dist)
            li = ri - half
            lj = rj - half
            wa0 = li * w[i, 0] + lj * w[j, 0]
            wa1 = li * w[i, 1] + lj * w[j, 1]
            wa2 = li * w[i, 2] + lj * w[j, 2]
            vr0 = v[j, 0] - v[i, 0] + D00 * d0 + D01 * d1 + D02 * d2 - (wa1 * n2 - wa2 * n1)
            vr1 = v[j, 1] - v[i, 1] + D01 * d0 + D11 * d1 + D12 * d2 - (wa2 * n0 - wa0 * n2)
            vr2 = v[j, 2] - v[i, 2] + D02 * d0 + D12 * d1 + D22 * d2 - (wa0 * n1 - wa1 * n0)
            vn = vr0 * n0 + vr1 * n1 + vr2 * n2
            if gamma > 0.0:
                mst = mass[i] * mass[j] / (mass[i] + mass[j])
                fn -= 2.0 * gamma * math.sqrt(mst * kn) * vn
            # history: turn with the contact frame (mean-field spin plus the particles'
            # twist about n, to first order in dt), then drop its normal component
            f0 = ft[i, k, 0]
            f1 = ft[i, k, 1]
            f2 = ft[i, k, 2]
            tw = 0.5 * ((w[i, 0] + w[j, 0]) * n0 + (w[i, 1] + w[j, 1]) * n1
                        + (w[i, 2] + w[j, 2]) * n2)
            o0 = (sp0 + tw * n0) * dt
            o1 = (sp1 + tw * n1) * dt
            o2 = (sp2 + tw * n2) * dt
            g0 = f0 + o1 * f2 - o2 * f1
            g1 = f1 + o2 * f0 - o0 * f2
            g2 = f2 + o0 * f1 - o1 * f0
            gn = g0 * n0 + g1 * n1 + g2 * n2
            f0 = g0 - gn * n0
            f1 = g1 - gn * n1
            f2 = g2 - gn * n2
            kt = kt_ratio * kn
            f0 += kt * (vr0 - vn * n0) * dt
            f1 += kt * (vr1 - vn * n1) * dt
            f2 += kt * (vr2 - vn * n2) * dt
            cap = friction * max(fn, 0.0)
            fm2 = f0 * f0 + f1 * f1 + f2 * f2
            if fm2 > cap * cap:
                sc = cap / math.sqrt(fm2)
                f0 *= sc
                f1 *= sc
                f2 *= sc
            ft[i, k, 0] = f0
            ft[i, k, 1] = f1
            ft[i, k, 2] = f2
            # total force on i
            F0 = f0 - fn * n0
            F1 = f1 - fn * n1
            F2 = f2 - fn * n2
            fi0 += F0
            fi1 += F1
            fi2 += F2
            force[j, 0] -= F0
            force[j, 1] -= F1
            force[j, 2] -= F2
            # torques: only the tangential part has a lever arm (li n on i, lj n on j)
            tq0 = n1 * f2 - n2 * f1
            tq1 = n2 * f0 - n0 * f2
            tq2 = n0 * f1 - n1 * f0
            ti0 += li * tq0
            ti1 += li * tq1
            ti2 += li * tq2
            torque[j, 0] += lj * tq0
            torque[j, 1] += lj * tq1
            torque[j, 2] += lj * tq2
            ncontact += 1
            fsum += fn
            if not homogenise:
                continue
            sxx += d0 * F0
            sxy += d0 * F1
            sxz += d0 * F2
            syx += d1 * F0
            syy += d1 * F1
            syz += d1 * F2
            szx += d2 * F0
            szy += d2 * F1
            szz += d2 * F2
            q0 = dist * n0 * n0
            q1 = dist * n1 * n1
            q2 = dist * n2 * n2
            c00 += kn * q0 * q0
            c11 += kn * q1 * q1
            c22 += kn * q2 * q2
            c01 += kn * q0 * q1
            c02 += kn * q0 * q2
            c12 += kn * q1 * q2
        force[i, 0] += fi0
        force[i, 1] += fi1
        force[i, 2] += fi2
        torque[i, 0] += ti0
        torque[i, 1] += ti1
        torque[i, 2] += ti2
    if not homogenise:
        return ncontact, fsum
    # kinetic (Reynolds) stress of the fluctuating motion, -(1/V) sum m v' (x) v': the
    # momentum the grains carry across any plane, a pressure in dilute or fast flow
    for i in range(n):
        mi = mass[i]
        u0 = v[i, 0]
        u1 = v[i, 1]
        u2 = v[i, 2]
        sxx -= mi * u0 * u0
        sxy -= mi * u0 * u1
        sxz -= mi * u0 * u2
        syx -= mi * u1 * u0
        syy -= mi * u1 * u1
        syz -= mi * u1 * u2
        szx -= mi * u2 * u0
        szy -= mi * u2 * u1
        szz -= mi * u2 * u2
    iv = 1.0 / det3(h)
    stress_out[0, 0] = sxx * iv
    stress_out[0, 1] = sxy * iv
    stress_out[0, 2] = sxz * iv
    stress_out[1, 0] = syx * iv
    stress_out[1, 1] = syy * iv
    stress_out[1, 2] = syz * iv
    stress_out[2, 0] = szx * iv
    stress_out[2, 1] = szy * iv
    stress_out[2, 2] = szz * iv
    stiff_out[0, 0] = c00 * iv
    stiff_out[1, 1] = c11 * iv
    stiff_out[2, 2] = c22 * iv
    stiff_out[0, 1] = stiff_out[1, 0] = c01 * iv
    stiff_out[0, 2] = stiff_out[2, 0] = c02 * iv
    stiff_out[1, 2] = stiff_out[2, 1] = c12 * iv
    return ncontact, fsum


@njit(cache=True, fastmath=True, error_model="numpy")
def advance_rve(nsteps, law, st, ctl, out):
    """Advance one RVE (RveState st, ContactLaw law, Controls ctl) by `nsteps` steps of
    ctl.dt [s]; see the module docstring.

    `out` (5,) receives: contacts, unbalanced-force ratio, kinetic energy [J], the row
    length a list build asked for, steps done. Returns a status code (0 = ok).
    """
    dt, damping, skin = ctl.dt, law.damping, law.skin
    h, s, v, w, rot, L = st.h, st.s, st.v, st.w, st.rot, st.L
    radius, mass, inertia = st.radius, st.mass, st.inertia
    stress, stress_servo, stiffness = st.stress, st.stress_servo, st.stiffness
    force, torque = st.force, st.torque
    step_count, need_rebuild, s_ref, h_ref = st.step_count, st.need_rebuild, st.s_ref, st.h_ref
    servo_mask, servo_target, max_rate = ctl.servo_mask, ctl.servo_target, ctl.max_rate
    hdot_fixed, e_step, l_mean = ctl.hdot_fixed, ctl.e_step, ctl.l_mean
    n = s.shape[0]
    table = np.empty((27, 3))
    hdot = np.empty((3, 3))
    hinv = np.empty((3, 3))
    hnew = np.empty((3, 3))
    stiff_scratch = np.empty((3, 3))
    inv_m = np.empty(n)
    inv_i = np.empty(n)
    for i in range(n):
        inv_m[i] = dt / mass[i]
        inv_i[i] = dt / inertia[i]
    lc = np.empty((3, 3))
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, radius[i])
    cutoff = 2.0 * rmax + skin
    status = Status.OK
    done = 0
    ncontact = 0
    fsum = 0.0
    servo_on = False
    for a in range(3):
        for b in range(3):
            if servo_mask[a, b] != 0:
                servo_on = True
    for _step in range(nsteps):
        # 1. neighbour list, if the last step's check (7) asked for it
        if need_rebuild[0] != 0:
            code, needed = build(h, s, radius, st.nbr_j, st.nbr_shift, st.nbr_count, st.ft,
                                 s_ref, h_ref, st.link, st.wrapv, st.x, skin)
            out[3] = needed
            if code != Status.OK:
                status = code
                break
            need_rebuild[0] = 0
        # 2. cell control: h_new, and L from the current cell's inverse
        for a in range(3):
            for b in range(3):
                lc[a, b] = ctl.l_ctrl[a, b]
        for a in range(3):
            for b in range(a, 3):
                if servo_mask[a, b] == 0:
                    continue
                err = servo_target[a, b] - 0.5 * (stress_servo[a, b] + stress_servo[b, a])
                c = stiffness[a, b] if a == b else 2.0 * stiffness[a, b]
                if c > 0.0:
                    rate = ctl.servo_gain * err / (c * dt)
                else:  # no contacts yet: move at the largest rate toward the target
                    rate = max_rate if err > 0.0 else -max_rate
                rate = min(max(rate, -max_rate), max_rate)
                lc[a, b] = rate
                lc[b, a] = rate
        for a in range(3):
            for b in range(3):
                hdot[a, b] = hdot_fixed[a, b] + lc[a, 0] * h[0, b] + lc[a, 1] * h[1, b] \
                    + lc[a, 2] * h[2, b]
                hnew[a, b] = e_step[a, 0] * h[0, b] + e_step[a, 1] * h[1, b] \
                    + e_step[a, 2] * h[2, b] + dt * hdot[a, b]
        inv3(h, hinv)
        for a in range(3):
            for b in range(3):
                L[a, b] = l_mean[a, b] + hdot[a, 0] * hinv[0, b] + hdot[a, 1] * hinv[1, b] \
                    + hdot[a, 2] * hinv[2, b]
        # 3-4. contacts, and the stress the caller needs (last step) or the servo reads.
        # The servo samples its own copy every SERVO_EVERY steps of the RVE's life (a
        # delay far shorter than the stress response, tens of steps) and keeps L in
        # between; counting on the RVE's steps, not the call's, makes a run independent
        # of how it is cut into calls
        last = _step == nsteps - 1
        sample = servo_on and step_count[0] % SERVO_EVERY == 0
        sig_out = stress_servo if sample else stress
        # the stiffness is the servo's sample under servo control; otherwise that of the
        # last step, so the caller (the MPM's wave speed) sees the current contacts. The
        # last step homogenises anyway: the write costs nothing
        report = sample or (last and not servo_on)
        stiff_out = stiffness if report else stiff_scratch
        ncontact, fsum = contact_pass(dt, law, st, table, sig_out, stiff_out, sample or last)
        if sample and last:
            stress[:, :] = stress_servo
        step_count[0] += 1
        # 5. new cell, its inverse for the position update
        for a in range(3):
            for b in range(3):
                h[a, b] = hnew[a, b]
        inv3(h, hinv)
        # 6. integration (damping opposes the fluctuating velocity, seed's YADE style)
        umax2 = 0.0
        fres = 0.0
        ekin = 0.0
        for i in range(n):
            im = inv_m[i]
            ii = inv_i[i]
            f0 = force[i, 0]
            f1 = force[i, 1]
            f2 = force[i, 2]
            t0 = torque[i, 0]
            t1 = torque[i, 1]
            t2 = torque[i, 2]
            if last:
                fres += math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
            # the pseudo-force -m L v' of the co-moving frame (SLLOD): a grain that
            # feels no force keeps its lab-frame velocity while the cell deforms
            lv0 = dt * (L[0, 0] * v[i, 0] + L[0, 1] * v[i, 1] + L[0, 2] * v[i, 2])
            lv1 = dt * (L[1, 0] * v[i, 0] + L[1, 1] * v[i, 1] + L[1, 2] * v[i, 2])
            lv2 = dt * (L[2, 0] * v[i, 0] + L[2, 1] * v[i, 1] + L[2, 2] * v[i, 2])
            v[i, 0] += im * (f0 - damping * math.copysign(f0, v[i, 0]) * _sgn(v[i, 0])) - lv0
            v[i, 1] += im * (f1 - damping * math.copysign(f1, v[i, 1]) * _sgn(v[i, 1])) - lv1
            v[i, 2] += im * (f2 - damping * math.copysign(f2, v[i, 2]) * _sgn(v[i, 2])) - lv2
            w[i, 0] += ii * (t0 - damping * math.copysign(t0, w[i, 0]) * _sgn(w[i, 0]))
            w[i, 1] += ii * (t1 - damping * math.copysign(t1, w[i, 1]) * _sgn(w[i, 1]))
            w[i, 2] += ii * (t2 - damping * math.copysign(t2, w[i, 2]) * _sgn(w[i, 2]))
            v0 = v[i, 0] * dt
            v1 = v[i, 1] * dt
            v2 = v[i, 2] * dt
            s[i, 0] += hinv[0, 0] * v0 + hinv[0, 1] * v1 + hinv[0, 2] * v2
            s[i, 1] += hinv[1, 0] * v0 + hinv[1, 1] * v1 + hinv[1, 2] * v2
            s[i, 2] += hinv[2, 0] * v0 + hinv[2, 1] * v1 + hinv[2, 2] * v2
            w2 = w[i, 0] * w[i, 0] + w[i, 1] * w[i, 1] + w[i, 2] * w[i, 2]
            rot[i] += math.sqrt(w2) * dt
            if last:
                vv = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]
                ekin += 0.5 * (mass[i] * vv + inertia[i] * w2)
            e0 = s[i, 0] - s_ref[i, 0]
            e1 = s[i, 1] - s_ref[i, 1]
            e2 = s[i, 2] - s_ref[i, 2]
            umax2 = max(umax2, e0 * e0 + e1 * e1 + e2 * e2)
        # 7. is the list still complete? |h ds| <= |h|_2 |ds| and
        # |h|_2 <= sqrt(|h|_1 |h|_inf) bound the fluctuating displacement cheaply
        n1 = max(abs(h[0, 0]) + abs(h[1, 0]) + abs(h[2, 0]),
                 abs(h[0, 1]) + abs(h[1, 1]) + abs(h[2, 1]),
                 abs(h[0, 2]) + abs(h[1, 2]) + abs(h[2, 2]))
        ninf = max(abs(h[0, 0]) + abs(h[0, 1]) + abs(h[0, 2]),
                   abs(h[1, 0]) + abs(h[1, 1]) + abs(h[1, 2]),
                   abs(h[2, 0]) + abs(h[2, 1]) + abs(h[2, 2]))
        umax2 *= n1 * ninf
        inv3(h_ref, hinv)
        e2sum = 0.0
        for a in range(3):
            for b in range(3):
                m = h[a, 0] * hinv[0, b] + h[a, 1] * hinv[1, b] + h[a, 2] * hinv[2, b]
                if a == b:
                    m -= 1.0
                e2sum += m * m
        if 2.0 * math.sqrt(umax2) + math.sqrt(e2sum) * cutoff >= skin:
            need_rebuild[0] = 1
        done += 1
        if last:
            out[1] = (fres / n) / (fsum / ncontact) if ncontact > 0 else 0.0
            out[2] = ekin
    out[0] = ncontact
    out[4] = done
    return status


@njit(cache=True, parallel=True)
def advance_batch(nsteps, law, st, ctl, status, out):
    """Advance every RVE r of a batch by nsteps[r] steps, in parallel over RVEs.

    st and ctl hold the batch's arrays (RVE index first); status (R,) receives each RVE's
    status code and out (R,5) its outputs (see advance_rve).
    """
    for r in prange(st.s.shape[0]):
        status[r] = advance_rve(nsteps[r], law, rve_state(st, r), rve_controls(ctl, r), out[r])

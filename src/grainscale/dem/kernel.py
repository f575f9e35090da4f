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
   where C_ab = (1/V) sum kn |d|^2 n_a^2 n_b^2 is the normal springs' affine stiffness
   of the servo's last sample (4);
   the mean-field velocity gradient is L = L_mean + (hdot_fixed + L_c h) h^-1, where
   L_mean = log(E)/dt is the exact rate of the step map (skew for a rotation).
3. contacts over the half list, in the current cell h (seed Eq. 7-10): kn = E r*,
   r* = 2 ri rj/(ri + rj), kt = ratio kn; f_n = kn delta (Hertz-Mindlin, law.hertz_kn
   > 0: kn = 2 E* a the tangent stiffness, a = sqrt(R* delta), f_n = (2/3) kn delta,
   kt = ratio kn with ratio = 2 (1 - nu)/(2 - nu); dem/hertz.py); tangential force history
   rotated with the contact frame, incremented by kt v_t dt and capped at mu f_n. The
   relative velocity includes the mean-field term D d across periodic images (D = sym L:
   the mean field carries a pair rigidly with its spin W = skew L, which only turns the
   contact frame), and particle spins w are fluctuations about W; a rigidly rotating
   cell therefore makes no slip at any contact (objectivity). With rolling resistance
   (ContactLaw.rolling_stiffness > 0; ft then has 6 components a slot) a moment M,
   turned and kept in the contact plane as the tangential force, is incremented by
   -k_r (w_j - w_i)_bend dt, k_r = alpha_r kt r_i r_j, and capped at eta_r min(r_i, r_j)
   max(f_n, 0); it acts as M on j and -M on i (docs/dem.md).
4. in the same pass over the contacts, on servo samples: Love-Weber stress
   sigma = (1/V) sum_c d (x) f (seed Eq. 11), with f the force on the first particle and
   d = x_j - x_i, so compression is negative (tension positive), minus the kinetic
   stress (1/V) sum m v' (x) v' of the fluctuating velocities v', and the normal
   springs' affine stiffness C_ab (the servo's).
5. h <- h_new, and h_new^-1 for 6.
6. leapfrog with Cundall's local non-viscous damping on the fluctuating motion and the
   pseudo-force of the co-moving frame (SLLOD): v += dt (F - alpha |F| sign v)/m
   - dt L v, rotation without it (spins are about W); s += h_new^-1 v dt;
   accumulated rotation += |w| dt.
7. list check: flag a rebuild (done at 1 of the next step) when
   2 max|u'| + |h h_ref^-1 - I|_F cutoff >= skin (u' = h (s - s_ref) the fluctuating
   displacement since the build, bounded by sqrt(|h|_1 |h|_inf) |s - s_ref|, and
   cutoff = 2 r_max + skin). Until then no unlisted pair touches: it had |d_ref| >=
   c_ij = r_i + r_j + skin at the build (neighbours.py) and now d = F d_ref + h (ds_j -
   ds_i) with F = h h_ref^-1, so, as |F - I|_2 <= |F - I|_F < skin/cutoff < 1 until
   then, |d| >= (1 - |F - I|_F) c_ij - 2 max|u'| >= c_ij - (|F - I|_F cutoff +
   2 max|u'|) > r_i + r_j, since c_ij <= cutoff.
8. after the call's last step: the stress of 4 and the affine moduli of the whole contact
   law (kn and kt; contact_pass) of the state the steps reached, by a force evaluation
   that leaves the tangential history as it is (list rebuilt first if 7 asked for it).
   This is what the caller reads: the stress at the end of the increment, not one DEM
   step before it (a lagging stress feeds energy into the MPM, docs/coupling.md).

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
from numba import get_num_threads, literally, njit, prange

from grainscale.dem import rigid
from grainscale.dem.neighbours import Status, build, image_table
from grainscale.linalg3 import det3, inv3

# unsigned offsets into flat (3n,) views: numba then emits no negative-index wrap-around,
# which is what keeps LLVM from vectorising the particle loops (docs/performance.md)
U1 = np.uintp(1)
U2 = np.uintp(2)
U3 = np.uintp(3)
# fast-math flags of the vectorised per-particle loops: no reassociation and no FMA
# contraction, so that their vector body and scalar remainder round alike and a
# particle's result does not depend on where the array's alignment puts it (MPI ranks
# and batches allocate differently)
ELEMENTWISE = {"nnan", "ninf", "nsz", "arcp", "afn"}
SERVO_EVERY = 4  # steps between stress samples of a servo
OUT_WIDTH = 6  # a call's outputs per RVE (`out`, _advance_rve's docstring)


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
    stress: np.ndarray        # Love-Weber stress of the state a call ends in
    stress_servo: np.ndarray  # the stress the servo last sampled
    stiffness: np.ndarray     # affine moduli C_aabb (servo: the normal springs')
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


class Clumps(NamedTuple):
    """The clump arrays of the RVEs (state.RVEBatch's body .. bj; empty for plain
    spheres), sliced per RVE by `rve_clumps`; dem/rigid.py steps them."""

    body: np.ndarray   # member -> body
    rho: np.ndarray    # member offsets in the body frame
    image: np.ndarray  # member image offsets
    off: np.ndarray    # member lab offsets R rho (scratch)
    bs: np.ndarray     # body centres (fractional)
    bv: np.ndarray     # fluctuating velocities
    bw: np.ndarray     # spins about the mean-field spin
    bq: np.ndarray     # orientations
    bl: np.ndarray     # lab angular momenta
    bm: np.ndarray     # masses
    bj: np.ndarray     # principal moments


class ContactLaw(NamedTuple):
    """Constants of the contact law (seed Eq. 7-10), the damping and the Verlet skin; the
    same for every RVE of a batch (engine.ContactParams)."""

    young: float     # E [Pa]; kn = E r*
    kt_ratio: float  # kt / kn
    friction: float  # mu
    gamma: float     # damping ratio of the normal dashpot (0: elastic)
    damping: float   # Cundall local non-viscous damping coefficient
    skin: float      # Verlet skin [m]
    rolling_stiffness: float  # alpha_r: k_r = alpha_r kt r_i r_j [N m/rad]; 0: off
    rolling_friction: float   # eta_r: |M_r| <= eta_r min(r_i, r_j) max(f_n, 0)
    hertz_kn: float  # 2 E* [Pa]: Hertz-Mindlin, kn = 2 E* a (dem/hertz.py); 0: linear


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
def rve_clumps(cl, r):
    """The Clumps of RVE r of a batch's Clumps (views)."""
    return Clumps(cl.body[r], cl.rho[r], cl.image[r], cl.off[r], cl.bs[r], cl.bv[r],
                  cl.bw[r], cl.bq[r], cl.bl[r], cl.bm[r], cl.bj[r])


@njit(cache=True, inline="always")
def rve_controls(ctl, r):
    """The Controls of RVE r of a batch's Controls."""
    return Controls(ctl.dt, ctl.e_step[r], ctl.l_mean[r], ctl.hdot_fixed[r], ctl.l_ctrl[r],
                    ctl.servo_mask[r], ctl.servo_target[r], ctl.servo_gain, ctl.max_rate[r])


@njit(cache=True, inline="always")
def _sgn(a):
    """1 where a != 0, else 0: damping acts only on moving degrees of freedom."""
    return 1.0 if a != 0.0 else 0.0


@njit(cache=True, fastmath=ELEMENTWISE, error_model="numpy")
def _positions(h, s, x, force, torque):
    """x = h s (Cartesian positions [m]); force and torque zeroed."""
    h00, h01, h02 = h[0, 0], h[0, 1], h[0, 2]
    h10, h11, h12 = h[1, 0], h[1, 1], h[1, 2]
    h20, h21, h22 = h[2, 0], h[2, 1], h[2, 2]
    n = s.shape[0]
    sf = s.reshape(3 * n)
    xf = x.reshape(3 * n)
    ff = force.reshape(3 * n)
    tf = torque.reshape(3 * n)
    for i in range(n):
        a = U3 * np.uintp(i)
        s0 = sf[a]
        s1 = sf[a + U1]
        s2 = sf[a + U2]
        xf[a] = h00 * s0 + h01 * s1 + h02 * s2
        xf[a + U1] = h10 * s0 + h11 * s1 + h12 * s2
        xf[a + U2] = h20 * s0 + h21 * s1 + h22 * s2
    for a in range(3 * n):
        ff[a] = 0.0
        tf[a] = 0.0


@njit(cache=True, fastmath=True, error_model="numpy")
def contact_pass(dt, law, st, cl, hw, hertz, table, stress_out, stiff_out, homogenise,
                 commit=True, full_moduli=False):
    """Contact forces and torques of one RVE (RveState st, ContactLaw law) at its current
    configuration; cl its Clumps when the spheres are clump members, None for plain
    spheres (a None is a type: the clump code is not compiled into the spheres' variant);
    hw the history's components a slot (st.ft.shape[2]: 3, or 6 with rolling resistance)
    and hertz (1: Hertz-Mindlin, law.hertz_kn > 0; 0: linear) given as constants; table
    is (27,3) scratch for the image shifts.

    For clumps the stress and moduli take the branch vector between the bodies' centres
    of mass, b = d - r_j + r_i (r the members' lab offsets, cl.off), and the kinetic
    stress the bodies' motion: the Love-Weber sum follows from each body's equilibrium,
    sum over its contacts of (x_c - X) (x) f = 0 in moments, with X any point fixed to the
    body; a member centre is not one (the forces between members of a clump, which hold
    it together, are not in the sum), the centre of mass is, and it is the point whose
    momentum the kinetic stress carries (docs/dem.md).

    Normal force f_n = kn delta - c_n v_n (linear spring-dashpot; v_n > 0 separating),
    c_n = 2 gamma sqrt(m* kn), m* = mi mj/(mi + mj), gamma the damping ratio of the
    restitution coefficient (0: elastic); with law.hertz_kn = 2 E* > 0 (Hertz-Mindlin)
    kn = 2 E* sqrt(R* delta) is the tangent stiffness and the elastic part (2/3) kn delta.
    The dashpot is not clipped, so an isolated collision returns exactly e; the Coulomb
    cap uses max(f_n, 0).

    Updates the tangential history by dt if `commit` (else the history is only read: with
    dt = 0 it is then the read-only force evaluation of the current state, projected onto
    the current contact planes and capped, as the next step would see it), fills force
    and torque (N) and, if `homogenise`, stress_out (3x3, Pa) and stiff_out (3x3, Pa);
    skipping them saves a third of the work per contact. stiff_out holds the affine
    moduli C_aabb of the contacts: with `full_moduli` those of the whole contact law,
    (1/V) sum |d|^2 [kn n_a^2 n_b^2 + kt (delta_ab n_a^2 - n_a^2 n_b^2)], the diagonal
    plus (1/V) sum |d| n_a^2 (|f_n| + |f_t|), a bound of the forces' turning with the
    contact frame under an axial strain (|d| n_a^2 [f_n (1 - n_a^2) + |f_t| |n_a|]; the
    change of d and of V cancel): a diagonal entry is then an upper bound of the modulus
    of an increment taken in one step along that axis, which the MPM's wave speed reads
    (tests/dem/test_end_of_increment.py). Without, the normal springs' alone,
    (1/V) sum kn |d|^2 n_a^2 n_b^2 (the servo's C_ab).
    Returns (number of contacts, sum of normal contact forces [N], the largest overlap
    delta/R* (Hertz-Mindlin; 0 for the linear law)).
    """
    young, kt_ratio, friction, gamma = law.young, law.kt_ratio, law.friction, law.gamma
    alpha_r, eta_r, hz = law.rolling_stiffness, law.rolling_friction, law.hertz_kn
    literally(hw)  # a compile-time constant: a width read at run time cost 10 % a step
    literally(hertz)  # as a run-time test, the linear law's branch cost it 1 % a step
    rolling = hw == 6  # without it the moment's code is not compiled in
    h, s, v, w, radius, mass, L = st.h, st.s, st.v, st.w, st.radius, st.mass, st.L
    nbr_j, nbr_shift, nbr_count, ft = st.nbr_j, st.nbr_shift, st.nbr_count, st.ft
    force, torque, x = st.force, st.torque, st.x
    n = s.shape[0]
    _positions(h, s, x, force, torque)
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
    omax = 0.0
    xf = x.reshape(3 * n)
    vf = v.reshape(3 * n)
    wf = w.reshape(3 * n)
    ff = force.reshape(3 * n)
    tf = torque.reshape(3 * n)
    kcap = ft.shape[1]
    ftf = ft.reshape(hw * n * kcap)
    if cl is not None:
        offf = cl.off.reshape(3 * n)
    kt_mod = kt_ratio if full_moduli else 0.0  # kt/kn in the moduli
    geo = 1.0 if full_moduli else 0.0  # the turning of the contact forces
    tab = table.reshape(81)
    for i in range(n):
        xi0 = x[i, 0]
        xi1 = x[i, 1]
        xi2 = x[i, 2]
        ri = radius[i]
        i3 = U3 * np.uintp(i)
        rowk = np.uintp(hw) * np.uintp(kcap) * np.uintp(i)
        fi0 = fi1 = fi2 = 0.0
        ti0 = ti1 = ti2 = 0.0
        for k in range(nbr_count[i]):
            j = np.uintp(nbr_j[i, k])  # unsigned: no negative-index wraparound
            t = nbr_shift[i, k]
            j3 = U3 * j
            t3 = U3 * np.uintp(t)
            q = rowk + np.uintp(hw) * np.uintp(k)
            d0 = xf[j3] - xi0 + tab[t3]
            d1 = xf[j3 + U1] - xi1 + tab[t3 + U1]
            d2 = xf[j3 + U2] - xi2 + tab[t3 + U2]
            rj = radius[j]
            rr = ri + rj
            dist2 = d0 * d0 + d1 * d1 + d2 * d2
            if dist2 >= rr * rr:
                if commit:
                    for c in range(hw):
                        ftf[q + np.uintp(c)] = 0.0
                continue
            dist = math.sqrt(dist2)
            inv2 = 1.0 / (dist * rr)  # one division serves 1/dist and 1/rr
            inv = inv2 * rr
            n0 = d0 * inv
            n1 = d1 * inv
            n2 = d2 * inv
            if hertz == 1:  # Hertz: kn the tangent stiffness 2 E* a, a = sqrt(R* delta)
                ovl = (rr - dist) * rr / (ri * rj)  # delta / R*
                kn = hz * ri * rj * dist * inv2 * math.sqrt(ovl)
                fn = (2.0 / 3.0) * kn * (rr - dist)
                omax = max(omax, ovl)
            else:
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
            wa0 = li * wf[i3] + lj * wf[j3]
            wa1 = li * wf[i3 + U1] + lj * wf[j3 + U1]
            wa2 = li * wf[i3 + U2] + lj * wf[j3 + U2]
            vr0 = vf[j3] - vf[i3] + D00 * d0 + D01 * d1 + D02 * d2 - (wa1 * n2 - wa2 * n1)
            vr1 = vf[j3 + U1] - vf[i3 + U1] + D01 * d0 + D11 * d1 + D12 * d2 - (wa2 * n0 - wa0 * n2)
            vr2 = vf[j3 + U2] - vf[i3 + U2] + D02 * d0 + D12 * d1 + D22 * d2 - (wa0 * n1 - wa1 * n0)
            vn = vr0 * n0 + vr1 * n1 + vr2 * n2
            if gamma > 0.0:
                mst = mass[i] * mass[j] / (mass[i] + mass[j])
                fn -= 2.0 * gamma * math.sqrt(mst * kn) * vn
            # history: turn with the contact frame (mean-field spin plus the particles'
            # twist about n, to first order in dt), then drop its normal component
            f0 = ftf[q]
            f1 = ftf[q + U1]
            f2 = ftf[q + U2]
            tw = 0.5 * ((wf[i3] + wf[j3]) * n0 + (wf[i3 + U1] + wf[j3 + U1]) * n1
                        + (wf[i3 + U2] + wf[j3 + U2]) * n2)
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
            if commit:
                ftf[q] = f0
                ftf[q + U1] = f1
                ftf[q + U2] = f2
            # total force on i
            F0 = f0 - fn * n0
            F1 = f1 - fn * n1
            F2 = f2 - fn * n2
            fi0 += F0
            fi1 += F1
            fi2 += F2
            ff[j3] -= F0
            ff[j3 + U1] -= F1
            ff[j3 + U2] -= F2
            # torques: only the tangential part has a lever arm (li n on i, lj n on j)
            tq0 = n1 * f2 - n2 * f1
            tq1 = n2 * f0 - n0 * f2
            tq2 = n0 * f1 - n1 * f0
            ti0 += li * tq0
            ti1 += li * tq1
            ti2 += li * tq2
            if rolling:
                # rolling moment (YADE's CohesionMoment law, incremental form): turned
                # with the contact frame as the tangential force, kept in its plane,
                # then M -= k_r (w_j - w_i)_bend dt, capped at eta_r min(r) f_n; the
                # torque M on j and -M on i (no force: the stress is unchanged in form)
                r3 = q + U3
                m0 = ftf[r3]
                m1 = ftf[r3 + U1]
                m2 = ftf[r3 + U2]
                g0 = m0 + o1 * m2 - o2 * m1
                g1 = m1 + o2 * m0 - o0 * m2
                g2 = m2 + o0 * m1 - o1 * m0
                gn = g0 * n0 + g1 * n1 + g2 * n2
                a0 = wf[j3] - wf[i3]
                a1 = wf[j3 + U1] - wf[i3 + U1]
                a2 = wf[j3 + U2] - wf[i3 + U2]
                an = a0 * n0 + a1 * n1 + a2 * n2
                kr = alpha_r * kt * ri * rj
                m0 = g0 - gn * n0 - kr * (a0 - an * n0) * dt
                m1 = g1 - gn * n1 - kr * (a1 - an * n1) * dt
                m2 = g2 - gn * n2 - kr * (a2 - an * n2) * dt
                cap_m = eta_r * min(ri, rj) * max(fn, 0.0)
                mm2 = m0 * m0 + m1 * m1 + m2 * m2
                if mm2 > cap_m * cap_m:
                    sc = cap_m / math.sqrt(mm2)
                    m0 *= sc
                    m1 *= sc
                    m2 *= sc
                if commit:
                    ftf[r3] = m0
                    ftf[r3 + U1] = m1
                    ftf[r3 + U2] = m2
                ti0 -= m0
                ti1 -= m1
                ti2 -= m2
                tf[j3] += lj * tq0 + m0
                tf[j3 + U1] += lj * tq1 + m1
                tf[j3 + U2] += lj * tq2 + m2
            else:  # the same expressions as before rolling existed: bitwise results
                tf[j3] += lj * tq0
                tf[j3 + U1] += lj * tq1
                tf[j3 + U2] += lj * tq2
            ncontact += 1
            fsum += abs(fn)  # a dashpot pulls as contacts part: keep a magnitude
            if not homogenise:
                continue
            if cl is not None:  # branch between the bodies' centres; moduli with it
                e0 = d0 - offf[j3] + offf[i3]
                e1 = d1 - offf[j3 + U1] + offf[i3 + U1]
                e2 = d2 - offf[j3 + U2] + offf[i3 + U2]
                sxx += e0 * F0
                sxy += e0 * F1
                sxz += e0 * F2
                syx += e1 * F0
                syy += e1 * F1
                syz += e1 * F2
                szx += e2 * F0
                szy += e2 * F1
                szz += e2 * F2
                q0 = e0 * n0
                q1 = e1 * n1
                q2 = e2 * n2
                kq = kt_mod * kn
                fa = geo * (abs(fn) + math.sqrt(f0 * f0 + f1 * f1 + f2 * f2))
                c00 += kn * q0 * q0 + kq * (e0 * e0 - q0 * q0) + abs(q0) * fa
                c11 += kn * q1 * q1 + kq * (e1 * e1 - q1 * q1) + abs(q1) * fa
                c22 += kn * q2 * q2 + kq * (e2 * e2 - q2 * q2) + abs(q2) * fa
                c01 += (kn - kq) * q0 * q1
                c02 += (kn - kq) * q0 * q2
                c12 += (kn - kq) * q1 * q2
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
            # kt |d|^2 n_a^2 (1 - n_a^2) = kt q_a (dist - q_a); 0 unless full_moduli
            kq = kt_mod * kn
            fa = geo * (abs(fn) + math.sqrt(f0 * f0 + f1 * f1 + f2 * f2))
            c00 += kn * q0 * q0 + kq * q0 * (dist - q0) + q0 * fa
            c11 += kn * q1 * q1 + kq * q1 * (dist - q1) + q1 * fa
            c22 += kn * q2 * q2 + kq * q2 * (dist - q2) + q2 * fa
            c01 += (kn - kq) * q0 * q1
            c02 += (kn - kq) * q0 * q2
            c12 += (kn - kq) * q1 * q2
        force[i, 0] += fi0
        force[i, 1] += fi1
        force[i, 2] += fi2
        torque[i, 0] += ti0
        torque[i, 1] += ti1
        torque[i, 2] += ti2
    if not homogenise:
        return ncontact, fsum, omax
    # kinetic (Reynolds) stress of the fluctuating motion, -(1/V) sum m v' (x) v': the
    # momentum the grains carry across any plane, a pressure in dilute or fast flow
    # (clumps: their centres of mass')
    if cl is not None:
        kin_m = cl.bm
        kin_v = cl.bv
    else:
        kin_m = mass
        kin_v = v
    for i in range(kin_m.shape[0]):
        mi = kin_m[i]
        u0 = kin_v[i, 0]
        u1 = kin_v[i, 1]
        u2 = kin_v[i, 2]
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
    return ncontact, fsum, omax


@njit(cache=True, fastmath=ELEMENTWISE, error_model="numpy")
def _translate(v, s, s_ref, force, inv_m, L, hinv, dt, damping):
    """Translational step of every particle, in place: v += dt (F - damping |F| sign v)/m
    - dt L v (inv_m holds dt/m; the last term is the pseudo-force -m L v of the co-moving
    frame, SLLOD: a grain that feels no force keeps its lab-frame velocity while the cell
    deforms), then s += h^-1 v dt. Returns max |s - s_ref|^2 (fractional displacement
    since the last list build, for the list check)."""
    L00, L01, L02 = L[0, 0], L[0, 1], L[0, 2]
    L10, L11, L12 = L[1, 0], L[1, 1], L[1, 2]
    L20, L21, L22 = L[2, 0], L[2, 1], L[2, 2]
    h00, h01, h02 = hinv[0, 0], hinv[0, 1], hinv[0, 2]
    h10, h11, h12 = hinv[1, 0], hinv[1, 1], hinv[1, 2]
    h20, h21, h22 = hinv[2, 0], hinv[2, 1], hinv[2, 2]
    n = v.shape[0]
    vf = v.reshape(3 * n)
    sf = s.reshape(3 * n)
    rf = s_ref.reshape(3 * n)
    ff = force.reshape(3 * n)
    umax2 = 0.0
    for i in range(n):
        a = U3 * np.uintp(i)
        im = inv_m[i]
        f0 = ff[a]
        f1 = ff[a + U1]
        f2 = ff[a + U2]
        u0 = vf[a]
        u1 = vf[a + U1]
        u2 = vf[a + U2]
        lv0 = dt * (L00 * u0 + L01 * u1 + L02 * u2)
        lv1 = dt * (L10 * u0 + L11 * u1 + L12 * u2)
        lv2 = dt * (L20 * u0 + L21 * u1 + L22 * u2)
        u0 += im * (f0 - damping * math.copysign(f0, u0) * _sgn(u0)) - lv0
        u1 += im * (f1 - damping * math.copysign(f1, u1) * _sgn(u1)) - lv1
        u2 += im * (f2 - damping * math.copysign(f2, u2) * _sgn(u2)) - lv2
        vf[a] = u0
        vf[a + U1] = u1
        vf[a + U2] = u2
        v0 = u0 * dt
        v1 = u1 * dt
        v2 = u2 * dt
        s0 = sf[a] + (h00 * v0 + h01 * v1 + h02 * v2)
        s1 = sf[a + U1] + (h10 * v0 + h11 * v1 + h12 * v2)
        s2 = sf[a + U2] + (h20 * v0 + h21 * v1 + h22 * v2)
        sf[a] = s0
        sf[a + U1] = s1
        sf[a + U2] = s2
    for i in range(n):
        a = U3 * np.uintp(i)
        e0 = sf[a] - rf[a]
        e1 = sf[a + U1] - rf[a + U1]
        e2 = sf[a + U2] - rf[a + U2]
        umax2 = max(umax2, e0 * e0 + e1 * e1 + e2 * e2)
    return umax2


@njit(cache=True, fastmath=ELEMENTWISE, error_model="numpy")
def _rotate(w, rot, torque, inv_i, dt, damping):
    """Rotational step, in place: w += dt (T - damping |T| sign w)/I (inv_i holds dt/I);
    rot += |w| dt, the accumulated rotation angle [rad]."""
    n = w.shape[0]
    wf = w.reshape(3 * n)
    tf = torque.reshape(3 * n)
    for i in range(n):
        a = U3 * np.uintp(i)
        ii = inv_i[i]
        t0 = tf[a]
        t1 = tf[a + U1]
        t2 = tf[a + U2]
        a0 = wf[a]
        a1 = wf[a + U1]
        a2 = wf[a + U2]
        a0 += ii * (t0 - damping * math.copysign(t0, a0) * _sgn(a0))
        a1 += ii * (t1 - damping * math.copysign(t1, a1) * _sgn(a1))
        a2 += ii * (t2 - damping * math.copysign(t2, a2) * _sgn(a2))
        wf[a] = a0
        wf[a + U1] = a1
        wf[a + U2] = a2
        rot[i] += math.sqrt(a0 * a0 + a1 * a1 + a2 * a2) * dt


@njit(cache=True, fastmath={"nnan", "ninf", "nsz", "arcp", "contract", "afn"},
      error_model="numpy")
def _residuals(force, v, w, mass, inertia):
    """Sum of |F| [N] and the kinetic energy [J], in particle order (no reassociation:
    the sums are the same whatever the vector width)."""
    fres = 0.0
    ekin = 0.0
    for i in range(v.shape[0]):
        f0 = force[i, 0]
        f1 = force[i, 1]
        f2 = force[i, 2]
        fres += math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        w2 = w[i, 0] * w[i, 0] + w[i, 1] * w[i, 1] + w[i, 2] * w[i, 2]
        vv = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]
        ekin += 0.5 * (mass[i] * vv + inertia[i] * w2)
    return fres, ekin


@njit(cache=True, fastmath=True, error_model="numpy")
def _advance_rve(nsteps, law, st, cl, ctl, out, hw, hertz):
    """Advance one RVE (RveState st, ContactLaw law, Controls ctl) by `nsteps` steps of
    ctl.dt [s]; see the module docstring.

    `cl` is the RVE's Clumps when its spheres are clump members, stepped as rigid bodies
    by dem/rigid.py instead of 6, or None for plain spheres (whose variant then holds no
    clump code); `hw` is the history's width (literal 3 or 6) and `hertz` the law
    (literal 1: Hertz-Mindlin, 0: linear). `out` (6,) receives:
    contacts, unbalanced-force ratio, kinetic energy [J], the row
    length a list build asked for, steps done, the largest overlap delta/R* (Hertz-Mindlin;
    0 for the linear law). Returns a status code (0 = ok). After the
    steps (and with nsteps = -1 alone: no step) the stress, the moduli (unless a servo
    runs), contact count, unbalanced-force ratio and kinetic energy are those of the
    state reached (item 8).
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
    if cl is not None:
        nb = cl.bm.shape[0]
        bforce = np.empty((nb, 3))
        btorque = np.empty((nb, 3))
        rmat = np.empty((nb, 3, 3))
        work = np.empty((4, 4))
        rigid.orient(cl.body, cl.rho, cl.bq, cl.off, rmat)
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
    umax2 = 0.0
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
            if cl is not None:
                rigid.after_build(h, s, cl.body, cl.rho, cl.image, cl.off, cl.bs, cl.bq,
                                  st.nbr_j, st.nbr_shift, st.nbr_count, st.ft, rmat)
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
        # 3-4. contacts, and the stress the servo reads. The servo samples its own copy
        # every SERVO_EVERY steps of the RVE's life (a delay far shorter than the stress
        # response, tens of steps) and keeps L in between; counting on the RVE's steps,
        # not the call's, makes a run independent of how it is cut into calls. The
        # caller's stress is evaluated after the loop, at the end of the increment (8)
        sample = servo_on and step_count[0] % SERVO_EVERY == 0
        if sample:  # two specialisations: the hot one keeps no stress sums live
            ncontact, fsum, _ = contact_pass(dt, law, st, cl, hw, hertz, table, stress_servo,
                                             stiffness, True)
        else:
            ncontact, fsum, _ = contact_pass(dt, law, st, cl, hw, hertz, table, stress_servo,
                                             stiff_scratch, False)
        step_count[0] += 1
        # 5. new cell, its inverse for the position update
        for a in range(3):
            for b in range(3):
                h[a, b] = hnew[a, b]
        inv3(h, hinv)
        # 6. integration, in loops LLVM can vectorise over particles (few arrays each)
        if cl is not None:
            umax2 = rigid.advance(cl, s, v, w, rot, s_ref, force, torque, L, hinv, dt,
                                  damping, bforce, btorque, rmat, work)
        else:
            umax2 = _translate(v, s, s_ref, force, inv_m, L, hinv, dt, damping)
            _rotate(w, rot, torque, inv_i, dt, damping)
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
    # 8. end of the increment: the stress, moduli and contact count the caller reads are
    # those of the state the loop leaves (after the last position update), by a
    # read-only force evaluation; the list is completed first if 7 flagged it (the next
    # step would build the same list from the same state)
    if status == Status.OK and nsteps != 0:
        if need_rebuild[0] != 0:
            code, needed = build(h, s, radius, st.nbr_j, st.nbr_shift, st.nbr_count, st.ft,
                                 s_ref, h_ref, st.link, st.wrapv, st.x, skin)
            out[3] = needed
            status = code
            if code == Status.OK:
                need_rebuild[0] = 0
                if cl is not None:
                    rigid.after_build(h, s, cl.body, cl.rho, cl.image, cl.off, cl.bs,
                                      cl.bq, st.nbr_j, st.nbr_shift, st.nbr_count, st.ft,
                                      rmat)
        if status == Status.OK:
            stiff_out = stiff_scratch if servo_on else stiffness
            ncontact, fsum, omax = contact_pass(0.0, law, st, cl, hw, hertz, table, stress,
                                                stiff_out, True, False, not servo_on)
            grains = n
            if cl is not None:  # per body: a member's force is not a grain's
                rigid.reduce(cl.body, cl.off, force, torque, bforce, btorque)
                fres, ekin = rigid.residuals(cl, bforce, rmat)
                grains = nb
            else:
                fres, ekin = _residuals(force, v, w, mass, inertia)
            out[1] = (fres / grains) / (fsum / ncontact) if ncontact > 0 else 0.0
            out[2] = ekin
            out[5] = omax
    out[0] = ncontact
    out[4] = done
    return status


def advance_batch(nsteps, law, st, ctl, status, out, cl=None):
    """Advance every RVE r of a batch by nsteps[r] steps, in parallel over RVEs.

    st and ctl hold the batch's arrays (RVE index first); status (R,) receives each RVE's
    status code and out (R,OUT_WIDTH) its outputs (see _advance_rve); cl the batch's
    Clumps when its spheres are clump members (None: plain spheres).

    Load balance: the RVEs' costs (proportional to nsteps) can differ by orders of
    magnitude, and the costly ones sit together (quasi-static RVEs near an intruder are
    neighbouring points), where prange's equal blocks would leave threads idle. Each
    thread takes one contiguous range of RVEs, the ranges cut so that their step counts
    are equal (`split_by_cost`): balanced within one RVE's cost, and each thread walks
    its own stretch of memory (dealing the RVEs to the threads in turn balances as well,
    but ran at 0.91 of two threads' throughput on a batch larger than the caches,
    docs/performance.md). Each RVE is advanced alone, so the results do not depend on
    which thread takes it.
    """
    nthr = max(1, min(get_num_threads(), st.s.shape[0]))
    rolling = st.ft.shape[3] == 6
    bounds = split_by_cost(nsteps, nthr)
    if cl is not None:
        _advance_split_clumps(nsteps, law, st, cl, ctl, status, out, bounds,
                              6 if rolling else 3, 1 if law.hertz_kn > 0.0 else 0)
        return
    if law.hertz_kn > 0.0:
        split = _advance_split_hertz_rolling if rolling else _advance_split_hertz
    else:
        split = _advance_split_rolling if rolling else _advance_split
    split(nsteps, law, st, ctl, status, out, bounds)


@njit(cache=True)
def split_by_cost(nsteps, nthr):
    """Bounds (nthr + 1,) of nthr contiguous ranges of RVEs whose costs, nsteps + 1 each
    (an RVE that takes no step still costs a call), are as equal as the cuts allow: cut
    t lies at the prefix sum nearest to t/nthr of the total."""
    nrve = nsteps.shape[0]
    prefix = np.zeros(nrve + 1, np.int64)
    for r in range(nrve):
        prefix[r + 1] = prefix[r] + nsteps[r] + 1
    bounds = np.empty(nthr + 1, np.int64)
    bounds[0] = 0
    bounds[nthr] = nrve
    for t in range(1, nthr):
        target = prefix[nrve] * t / nthr
        r = np.searchsorted(prefix, target)
        if r > 0 and target - prefix[r - 1] < prefix[r] - target:
            r -= 1
        bounds[t] = max(bounds[t - 1], min(r, nrve))
    return bounds


# advance_batch's loop, one function per variant (history width, contact law), so that
# compiling one never compiles another (each would add the kernels' cold compile): lane
# t advances RVEs bounds[t] .. bounds[t + 1] - 1
@njit(cache=True, parallel=True)
def _advance_split(nsteps, law, st, ctl, status, out, bounds):
    """The linear law without rolling resistance."""
    for t in prange(bounds.shape[0] - 1):
        for r in range(bounds[t], bounds[t + 1]):
            status[r] = _advance_rve(nsteps[r], law, rve_state(st, r), None,
                                     rve_controls(ctl, r), out[r], 3, 0)


@njit(cache=True, parallel=True)
def _advance_split_rolling(nsteps, law, st, ctl, status, out, bounds):
    """The linear law with rolling resistance (6 history components a slot)."""
    for t in prange(bounds.shape[0] - 1):
        for r in range(bounds[t], bounds[t + 1]):
            status[r] = _advance_rve(nsteps[r], law, rve_state(st, r), None,
                                     rve_controls(ctl, r), out[r], 6, 0)


@njit(cache=True, parallel=True)
def _advance_split_hertz(nsteps, law, st, ctl, status, out, bounds):
    """Hertz-Mindlin without rolling resistance."""
    for t in prange(bounds.shape[0] - 1):
        for r in range(bounds[t], bounds[t + 1]):
            status[r] = _advance_rve(nsteps[r], law, rve_state(st, r), None,
                                     rve_controls(ctl, r), out[r], 3, 1)


@njit(cache=True, parallel=True)
def _advance_split_hertz_rolling(nsteps, law, st, ctl, status, out, bounds):
    """Hertz-Mindlin with rolling resistance."""
    for t in prange(bounds.shape[0] - 1):
        for r in range(bounds[t], bounds[t + 1]):
            status[r] = _advance_rve(nsteps[r], law, rve_state(st, r), None,
                                     rve_controls(ctl, r), out[r], 6, 1)


@njit(cache=True, parallel=True)
def _advance_split_clumps(nsteps, law, st, cl, ctl, status, out, bounds, hw, hertz):
    """Clumps, with either law and history width (constants: one compile per use)."""
    literally(hw)
    literally(hertz)
    for t in prange(bounds.shape[0] - 1):
        for r in range(bounds[t], bounds[t + 1]):
            status[r] = _advance_rve(nsteps[r], law, rve_state(st, r), rve_clumps(cl, r),
                                     rve_controls(ctl, r), out[r], hw, hertz)


@njit(cache=True)
def advance_rve(nsteps, law, st, ctl, out):
    """_advance_rve of a plain-sphere RVE with the history's width and the contact law as
    constants (for callers that schedule RVEs themselves: benchmarks/)."""
    hw = 6 if st.ft.shape[2] == 6 else 3
    if law.hertz_kn > 0.0:
        if hw == 6:
            return _advance_rve(nsteps, law, st, None, ctl, out, 6, 1)
        return _advance_rve(nsteps, law, st, None, ctl, out, 3, 1)
    if hw == 6:
        return _advance_rve(nsteps, law, st, None, ctl, out, 6, 0)
    return _advance_rve(nsteps, law, st, None, ctl, out, 3, 0)

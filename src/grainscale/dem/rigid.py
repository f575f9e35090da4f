"""The rigid-body step of clumps: member forces to bodies, bodies advanced, members placed.

A clump's member spheres take part in contacts as spheres (kernel.contact_pass); their
forces F_i and torques T_i (about the member centre) act on the body:

    F_b = sum_i F_i,    T_b = sum_i (T_i + r_i x F_i),    r_i = R(q_b) rho_i,

the member's lab offset from the body's centre of mass. Per step, in the co-moving frame
of the cell as the spheres are (kernel.py, 6):

- translation: V' += dt (F_b - alpha |F_b| sign V')/M - dt L V' (Cundall's local damping,
  the SLLOD pseudo-force), S += h^-1 V' dt;
- rotation: as the spheres' spins, a clump's is a fluctuation w = omega - W about the
  mean field's spin W, and it carries the angular momentum of that fluctuation, Pi = I w
  (lab frame, I = R diag(J) R^T): Pi += dt T_b', T_b' = T_b - alpha |T_b| sign(w)
  (Cundall's damping of the fluctuation); q turns with W + w, w = R J^-1 R^T Pi at the
  midpoints of Omelyan's implicit scheme (quaternion.step: torque-free, Pi is kept
  exactly and the energy without drift). A grain at rest in the co-moving frame (Pi = 0)
  turns with the cell's spin, as a sphere with w = 0 does; with W = 0, Pi is the lab
  angular momentum;
- members: s_i = S + h^-1 r_i + image_i, v'_i = V' + w x r_i - D r_i, w_i = w.

The member velocity is the rigid motion minus the mean field at the member: the lab
velocity L X + V' + omega x r_i less L (X + r_i), with L = D + W and W r = W x r. The
contact pass then sees the true relative velocity of the touching surfaces (its D d term
restores the mean field's strain across the pair). With a single-sphere template the
step is the spheres' leapfrog up to round-off (tests/dem/test_clump_kernel.py).

`image_i` (integers) keeps a member on the periodic image its list entries were built
for; it is fixed after each list build (`after_build`), which also drops the pairs of
members of one body from the list (no contacts inside a clump) and wraps the centres.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from grainscale.dem.quaternion import matrix, step
from grainscale.linalg3 import inv3


@njit(cache=True, inline="always")
def _sgn(a):
    """1 where a != 0, else 0 (as kernel._sgn: damping acts on moving freedoms only)."""
    return 1.0 if a != 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def after_build(h, s, body, rho, image, off, bs, bq, nbr_j, nbr_shift, nbr_count, ft, rmat):
    """After a list build of a clumped RVE: drop the pairs of members of one body (their
    history slots zeroed), wrap the body centres into [0, 1), and fix each member's
    image and lab offset from the wrapped positions the build left. rmat (B,3,3) receives
    the bodies' rotations."""
    n = s.shape[0]
    hw = ft.shape[2]
    for i in range(n):
        m = nbr_count[i]
        c = 0
        for k in range(m):
            j = nbr_j[i, k]
            if body[j] == body[i]:
                continue
            if c != k:
                nbr_j[i, c] = j
                nbr_shift[i, c] = nbr_shift[i, k]
                for a in range(hw):
                    ft[i, c, a] = ft[i, k, a]
            c += 1
        for k in range(c, m):
            for a in range(hw):
                ft[i, k, a] = 0.0
        nbr_count[i] = c
    for b in range(bs.shape[0]):
        for a in range(3):
            bs[b, a] -= math.floor(bs[b, a])
    orient(body, rho, bq, off, rmat)
    hinv = np.empty((3, 3))
    inv3(h, hinv)
    for i in range(n):
        b = body[i]
        for a in range(3):
            f = hinv[a, 0] * off[i, 0] + hinv[a, 1] * off[i, 1] + hinv[a, 2] * off[i, 2]
            image[i, a] = round(s[i, a] - bs[b, a] - f)


@njit(cache=True, error_model="numpy")
def orient(body, rho, bq, off, rmat):
    """rmat (B,3,3) = R(q_b) and the members' lab offsets off_i = R(q_b) rho_i [m]."""
    for b in range(bq.shape[0]):
        matrix(bq[b], rmat[b])
    for i in range(body.shape[0]):
        b = body[i]
        for a in range(3):
            off[i, a] = rmat[b, a, 0] * rho[i, 0] + rmat[b, a, 1] * rho[i, 1] \
                + rmat[b, a, 2] * rho[i, 2]


@njit(cache=True, error_model="numpy")
def reduce(body, off, force, torque, bforce, btorque):
    """Resultant force [N] and torque about the centre of mass [N m] of each body from
    its members' (module docstring)."""
    bforce[:] = 0.0
    btorque[:] = 0.0
    for i in range(body.shape[0]):
        b = body[i]
        f0, f1, f2 = force[i, 0], force[i, 1], force[i, 2]
        r0, r1, r2 = off[i, 0], off[i, 1], off[i, 2]
        bforce[b, 0] += f0
        bforce[b, 1] += f1
        bforce[b, 2] += f2
        btorque[b, 0] += torque[i, 0] + r1 * f2 - r2 * f1
        btorque[b, 1] += torque[i, 1] + r2 * f0 - r0 * f2
        btorque[b, 2] += torque[i, 2] + r0 * f1 - r1 * f0


@njit(cache=True, error_model="numpy")
def advance(cl, s, v, w, rot, s_ref, force, torque, L, hinv, dt, damping, bforce, btorque,
            rmat, work):
    """One step of every body of a clumped RVE and the placement of its members (module
    docstring), in place; hinv is the new cell's inverse. bforce, btorque (B,3) scratch,
    rmat (B,3,3) receives the new rotations, work (4,4) scratch. Returns max |s - s_ref|^2
    over the members (the list check's fractional displacement)."""
    body, rho, image, off = cl.body, cl.rho, cl.image, cl.off
    bs, bv, bw, bq, bl, bm, bj = cl.bs, cl.bv, cl.bw, cl.bq, cl.bl, cl.bm, cl.bj
    reduce(body, off, force, torque, bforce, btorque)
    W0 = 0.5 * (L[2, 1] - L[1, 2])
    W1 = 0.5 * (L[0, 2] - L[2, 0])
    W2 = 0.5 * (L[1, 0] - L[0, 1])
    omega = work[0, :3]
    ln = work[1, :3]
    half = work[2]
    new = work[3]
    for b in range(bm.shape[0]):
        im = dt / bm[b]
        u0, u1, u2 = bv[b, 0], bv[b, 1], bv[b, 2]
        f0, f1, f2 = bforce[b, 0], bforce[b, 1], bforce[b, 2]
        lv0 = dt * (L[0, 0] * u0 + L[0, 1] * u1 + L[0, 2] * u2)
        lv1 = dt * (L[1, 0] * u0 + L[1, 1] * u1 + L[1, 2] * u2)
        lv2 = dt * (L[2, 0] * u0 + L[2, 1] * u1 + L[2, 2] * u2)
        u0 += im * (f0 - damping * math.copysign(f0, u0) * _sgn(u0)) - lv0
        u1 += im * (f1 - damping * math.copysign(f1, u1) * _sgn(u1)) - lv1
        u2 += im * (f2 - damping * math.copysign(f2, u2) * _sgn(u2)) - lv2
        bv[b, 0] = u0
        bv[b, 1] = u1
        bv[b, 2] = u2
        v0 = u0 * dt
        v1 = u1 * dt
        v2 = u2 * dt
        bs[b, 0] += hinv[0, 0] * v0 + hinv[0, 1] * v1 + hinv[0, 2] * v2
        bs[b, 1] += hinv[1, 0] * v0 + hinv[1, 1] * v1 + hinv[1, 2] * v2
        bs[b, 2] += hinv[2, 0] * v0 + hinv[2, 1] * v1 + hinv[2, 2] * v2
        a0, a1, a2 = bw[b, 0], bw[b, 1], bw[b, 2]
        t0, t1, t2 = btorque[b, 0], btorque[b, 1], btorque[b, 2]
        t0 -= damping * math.copysign(t0, a0) * _sgn(a0)
        t1 -= damping * math.copysign(t1, a1) * _sgn(a1)
        t2 -= damping * math.copysign(t2, a2) * _sgn(a2)
        step(bq[b], bl[b], bj[b], t0, t1, t2, dt, omega, rmat[b], ln, half, new, W0, W1, W2)
        bw[b, 0] = omega[0]
        bw[b, 1] = omega[1]
        bw[b, 2] = omega[2]
        matrix(bq[b], rmat[b])
    D00 = L[0, 0]
    D11 = L[1, 1]
    D22 = L[2, 2]
    D01 = 0.5 * (L[0, 1] + L[1, 0])
    D02 = 0.5 * (L[0, 2] + L[2, 0])
    D12 = 0.5 * (L[1, 2] + L[2, 1])
    umax2 = 0.0
    for i in range(body.shape[0]):
        b = body[i]
        p0, p1, p2 = rho[i, 0], rho[i, 1], rho[i, 2]
        r0 = rmat[b, 0, 0] * p0 + rmat[b, 0, 1] * p1 + rmat[b, 0, 2] * p2
        r1 = rmat[b, 1, 0] * p0 + rmat[b, 1, 1] * p1 + rmat[b, 1, 2] * p2
        r2 = rmat[b, 2, 0] * p0 + rmat[b, 2, 1] * p1 + rmat[b, 2, 2] * p2
        off[i, 0] = r0
        off[i, 1] = r1
        off[i, 2] = r2
        e0 = bs[b, 0] + hinv[0, 0] * r0 + hinv[0, 1] * r1 + hinv[0, 2] * r2 + image[i, 0]
        e1 = bs[b, 1] + hinv[1, 0] * r0 + hinv[1, 1] * r1 + hinv[1, 2] * r2 + image[i, 1]
        e2 = bs[b, 2] + hinv[2, 0] * r0 + hinv[2, 1] * r1 + hinv[2, 2] * r2 + image[i, 2]
        s[i, 0] = e0
        s[i, 1] = e1
        s[i, 2] = e2
        a0, a1, a2 = bw[b, 0], bw[b, 1], bw[b, 2]
        v[i, 0] = bv[b, 0] + a1 * r2 - a2 * r1 - (D00 * r0 + D01 * r1 + D02 * r2)
        v[i, 1] = bv[b, 1] + a2 * r0 - a0 * r2 - (D01 * r0 + D11 * r1 + D12 * r2)
        v[i, 2] = bv[b, 2] + a0 * r1 - a1 * r0 - (D02 * r0 + D12 * r1 + D22 * r2)
        w[i, 0] = a0
        w[i, 1] = a1
        w[i, 2] = a2
        rot[i] += math.sqrt(a0 * a0 + a1 * a1 + a2 * a2) * dt
        e0 -= s_ref[i, 0]
        e1 -= s_ref[i, 1]
        e2 -= s_ref[i, 2]
        umax2 = max(umax2, e0 * e0 + e1 * e1 + e2 * e2)
    return umax2


@njit(cache=True, error_model="numpy")
def residuals(cl, bforce, rmat):
    """Sum of the bodies' resultant |F_b| [N] and their fluctuating kinetic energy
    (1/2) M |V'|^2 + (1/2) w . I w [J] (I = R diag(J) R^T; rmat the bodies' rotations),
    in body order."""
    fres = 0.0
    ekin = 0.0
    bv, bw, bm, bj = cl.bv, cl.bw, cl.bm, cl.bj
    for b in range(bm.shape[0]):
        fres += math.sqrt(bforce[b, 0] ** 2 + bforce[b, 1] ** 2 + bforce[b, 2] ** 2)
        ekin += 0.5 * bm[b] * (bv[b, 0] ** 2 + bv[b, 1] ** 2 + bv[b, 2] ** 2)
        for a in range(3):  # the spin's component on principal axis a
            wa = rmat[b, 0, a] * bw[b, 0] + rmat[b, 1, a] * bw[b, 1] + rmat[b, 2, a] * bw[b, 2]
            ekin += 0.5 * bj[b, a] * wa * wa
    return fres, ekin

"""The rigid-body step of clumps on the GPU: rigid.py's functions as device functions
of cuda_kernel.py's block (one block per RVE, its threads striding over members or
bodies), with rigid.py's arithmetic in the same order.

Sums stay free of float atomics, as in cuda_kernel: a body's resultant force and torque
are summed by one thread over its members in increasing member order (`first`/`members`,
the members of each body sorted, made on the host by `member_lists`), the order in
which rigid.reduce adds them on the CPU.
"""

from __future__ import annotations

import math

import numpy as np
from numba import cuda, float64

from grainscale.dem import quaternion

_matrix = cuda.jit(device=True)(quaternion.matrix.py_func)  # R(q), the CPU's arithmetic
_turned = cuda.jit(device=True)(quaternion.turned.py_func)


def member_lists(body: np.ndarray, n_bodies: int) -> tuple[np.ndarray, np.ndarray]:
    """(first, members) of a batch's body indices (R,N): the members of body b of RVE r
    are members[r, first[r, b]:first[r, b + 1]], in increasing order (int32 each)."""
    r = body.shape[0]
    first = np.zeros((r, n_bodies + 1), np.int32)
    members = np.empty(body.shape, np.int32)
    for k in range(r):
        members[k] = np.argsort(body[k], kind="stable")
        first[k, 1:] = np.cumsum(np.bincount(body[k], minlength=n_bodies))
    return first, members


@cuda.jit(device=True)
def signed(f, u):
    """|f| sign(u), 0 where u = 0: kernel.py's and rigid.py's copysign(f, u) _sgn(u),
    damping acting only on moving degrees of freedom (no copysign: libdevice's fails
    NVVM's verifier with numba 0.68's CUDA target). cuda_kernel.py uses it too."""
    if u > 0.0:
        return abs(f)
    if u < 0.0:
        return -abs(f)
    return 0.0


@cuda.jit(device=True)
def kick(u0, u1, u2, f0, f1, f2, im, damping, L, dt):
    """The velocity V' of a grain after one step (kernel._translate's arithmetic):
    V' + im (F - damping |F| sign V') - dt L V', im = dt/m; Cundall's damping and the
    SLLOD pseudo-force. The spheres' step (cuda_kernel._integrate) and the bodies'
    (`advance`) both take it."""
    lv0 = dt * (L[0, 0] * u0 + L[0, 1] * u1 + L[0, 2] * u2)
    lv1 = dt * (L[1, 0] * u0 + L[1, 1] * u1 + L[1, 2] * u2)
    lv2 = dt * (L[2, 0] * u0 + L[2, 1] * u1 + L[2, 2] * u2)
    u0 += im * (f0 - damping * signed(f0, u0)) - lv0
    u1 += im * (f1 - damping * signed(f1, u1)) - lv1
    u2 += im * (f2 - damping * signed(f2, u2)) - lv2
    return u0, u1, u2


@cuda.jit(device=True)
def _angular_velocity(q, L, J, rot, out):
    """quaternion.angular_velocity: out = R diag(1/J) R^T L, rot (3,3) left R(q)."""
    _matrix(q, rot)
    for a in range(3):
        body = (rot[0, a] * L[0] + rot[1, a] * L[1] + rot[2, a] * L[2]) / J[a]
        if a == 0:
            out[0] = rot[0, 0] * body
            out[1] = rot[1, 0] * body
            out[2] = rot[2, 0] * body
        else:
            out[0] += rot[0, a] * body
            out[1] += rot[1, a] * body
            out[2] += rot[2, a] * body


@cuda.jit(device=True)
def _step(q, L, J, T0, T1, T2, dt, omega, rot, ln, half, new, W0, W1, W2):
    """quaternion.step: Omelyan's implicit midpoint, q and L in place, omega receives
    omega_(n+1/2)."""
    ln[0] = L[0] + 0.5 * dt * T0
    ln[1] = L[1] + 0.5 * dt * T1
    ln[2] = L[2] + 0.5 * dt * T2
    L[0] += dt * T0
    L[1] += dt * T1
    L[2] += dt * T2
    _angular_velocity(q, ln, J, rot, omega)
    _turned(q, 0.5 * dt * (omega[0] + W0), 0.5 * dt * (omega[1] + W1),
            0.5 * dt * (omega[2] + W2), half)
    _angular_velocity(half, L, J, rot, omega)
    _turned(q, dt * (omega[0] + W0), dt * (omega[1] + W1), dt * (omega[2] + W2), new)
    for a in range(4):
        q[a] = new[a]


@cuda.jit(device=True)
def orient(r, g, tid, nthr, body, rho, bq, off, rmat):
    """rigid.orient for RVE r (collective): rmat[g, b] = R(q_b), off_i = R rho_i."""
    for b in range(tid, bq.shape[1], nthr):
        _matrix(bq[r, b], rmat[g, b])
    cuda.syncthreads()
    for i in range(tid, body.shape[1], nthr):
        b = body[r, i]
        for a in range(3):
            off[r, i, a] = rmat[g, b, a, 0] * rho[r, i, 0] + rmat[g, b, a, 1] * rho[r, i, 1] \
                + rmat[g, b, a, 2] * rho[r, i, 2]
    cuda.syncthreads()


@cuda.jit(device=True)
def after_build(r, g, tid, nthr, hinv, s, body, rho, image, off, bs, bq, nbr_j, nbr_shift,
                nbr_count, ft, rmat):
    """rigid.after_build for RVE r after a list build (collective): the pairs inside a
    body dropped from each row (history slots zeroed), the body centres wrapped into
    [0, 1), each member's image and lab offset fixed; hinv the cell's inverse."""
    hw = ft.shape[3]
    for i in range(tid, body.shape[1], nthr):
        m = nbr_count[r, i]
        c = 0
        for k in range(m):
            j = nbr_j[r, i, k]
            if body[r, j] == body[r, i]:
                continue
            if c != k:
                nbr_j[r, i, c] = j
                nbr_shift[r, i, c] = nbr_shift[r, i, k]
                for a in range(hw):
                    ft[r, i, c, a] = ft[r, i, k, a]
            c += 1
        for k in range(c, m):
            for a in range(hw):
                ft[r, i, k, a] = 0.0
        nbr_count[r, i] = c
    for b in range(tid, bs.shape[1], nthr):
        for a in range(3):
            bs[r, b, a] -= math.floor(bs[r, b, a])
    cuda.syncthreads()
    orient(r, g, tid, nthr, body, rho, bq, off, rmat)
    for i in range(tid, body.shape[1], nthr):
        b = body[r, i]
        for a in range(3):
            f = hinv[a, 0] * off[r, i, 0] + hinv[a, 1] * off[r, i, 1] + hinv[a, 2] * off[r, i, 2]
            image[r, i, a] = math.floor(s[r, i, a] - bs[r, b, a] - f + 0.5)
    cuda.syncthreads()


@cuda.jit(device=True)
def reduce(r, g, tid, nthr, off, force, torque, first, members, bforce, btorque):
    """rigid.reduce for RVE r: each body's resultant force and torque about its centre,
    its members added in increasing order by one thread (collective)."""
    for b in range(tid, bforce.shape[1], nthr):
        f0 = f1 = f2 = 0.0
        t0 = t1 = t2 = 0.0
        for k in range(first[r, b], first[r, b + 1]):
            i = members[r, k]
            a0 = force[g, i, 0]
            a1 = force[g, i, 1]
            a2 = force[g, i, 2]
            r0 = off[r, i, 0]
            r1 = off[r, i, 1]
            r2 = off[r, i, 2]
            f0 += a0
            f1 += a1
            f2 += a2
            t0 += torque[g, i, 0] + r1 * a2 - r2 * a1
            t1 += torque[g, i, 1] + r2 * a0 - r0 * a2
            t2 += torque[g, i, 2] + r0 * a1 - r1 * a0
        bforce[g, b, 0] = f0
        bforce[g, b, 1] = f1
        bforce[g, b, 2] = f2
        btorque[g, b, 0] = t0
        btorque[g, b, 1] = t1
        btorque[g, b, 2] = t2
    cuda.syncthreads()


@cuda.jit(device=True)
def advance(r, g, tid, nthr, dt, damping, Ls, hinv, s, v, w, rot, s_ref, off, force, torque,
            body, rho, image, bs, bv, bw, bq, bl, bm, bj, first, members, bforce, btorque,
            rmat):
    """rigid.advance for RVE r (collective): every body stepped, its members placed;
    returns the thread's max |s - s_ref|^2 over its members."""
    reduce(r, g, tid, nthr, off, force, torque, first, members, bforce, btorque)
    W0 = 0.5 * (Ls[2, 1] - Ls[1, 2])
    W1 = 0.5 * (Ls[0, 2] - Ls[2, 0])
    W2 = 0.5 * (Ls[1, 0] - Ls[0, 1])
    omega = cuda.local.array(3, float64)
    ln = cuda.local.array(3, float64)
    half = cuda.local.array(4, float64)
    new = cuda.local.array(4, float64)
    for b in range(tid, bm.shape[1], nthr):
        u0, u1, u2 = kick(bv[r, b, 0], bv[r, b, 1], bv[r, b, 2], bforce[g, b, 0],
                          bforce[g, b, 1], bforce[g, b, 2], dt / bm[r, b], damping, Ls, dt)
        bv[r, b, 0] = u0
        bv[r, b, 1] = u1
        bv[r, b, 2] = u2
        v0 = u0 * dt
        v1 = u1 * dt
        v2 = u2 * dt
        bs[r, b, 0] += hinv[0, 0] * v0 + hinv[0, 1] * v1 + hinv[0, 2] * v2
        bs[r, b, 1] += hinv[1, 0] * v0 + hinv[1, 1] * v1 + hinv[1, 2] * v2
        bs[r, b, 2] += hinv[2, 0] * v0 + hinv[2, 1] * v1 + hinv[2, 2] * v2
        a0 = bw[r, b, 0]
        a1 = bw[r, b, 1]
        a2 = bw[r, b, 2]
        t0 = btorque[g, b, 0] - damping * signed(btorque[g, b, 0], a0)
        t1 = btorque[g, b, 1] - damping * signed(btorque[g, b, 1], a1)
        t2 = btorque[g, b, 2] - damping * signed(btorque[g, b, 2], a2)
        _step(bq[r, b], bl[r, b], bj[r, b], t0, t1, t2, dt, omega, rmat[g, b], ln, half,
              new, W0, W1, W2)
        bw[r, b, 0] = omega[0]
        bw[r, b, 1] = omega[1]
        bw[r, b, 2] = omega[2]
        _matrix(bq[r, b], rmat[g, b])
    cuda.syncthreads()
    D00 = Ls[0, 0]
    D11 = Ls[1, 1]
    D22 = Ls[2, 2]
    D01 = 0.5 * (Ls[0, 1] + Ls[1, 0])
    D02 = 0.5 * (Ls[0, 2] + Ls[2, 0])
    D12 = 0.5 * (Ls[1, 2] + Ls[2, 1])
    umax2 = 0.0
    for i in range(tid, body.shape[1], nthr):
        b = body[r, i]
        p0 = rho[r, i, 0]
        p1 = rho[r, i, 1]
        p2 = rho[r, i, 2]
        r0 = rmat[g, b, 0, 0] * p0 + rmat[g, b, 0, 1] * p1 + rmat[g, b, 0, 2] * p2
        r1 = rmat[g, b, 1, 0] * p0 + rmat[g, b, 1, 1] * p1 + rmat[g, b, 1, 2] * p2
        r2 = rmat[g, b, 2, 0] * p0 + rmat[g, b, 2, 1] * p1 + rmat[g, b, 2, 2] * p2
        off[r, i, 0] = r0
        off[r, i, 1] = r1
        off[r, i, 2] = r2
        e0 = bs[r, b, 0] + hinv[0, 0] * r0 + hinv[0, 1] * r1 + hinv[0, 2] * r2 + image[r, i, 0]
        e1 = bs[r, b, 1] + hinv[1, 0] * r0 + hinv[1, 1] * r1 + hinv[1, 2] * r2 + image[r, i, 1]
        e2 = bs[r, b, 2] + hinv[2, 0] * r0 + hinv[2, 1] * r1 + hinv[2, 2] * r2 + image[r, i, 2]
        s[r, i, 0] = e0
        s[r, i, 1] = e1
        s[r, i, 2] = e2
        a0 = bw[r, b, 0]
        a1 = bw[r, b, 1]
        a2 = bw[r, b, 2]
        v[r, i, 0] = bv[r, b, 0] + a1 * r2 - a2 * r1 - (D00 * r0 + D01 * r1 + D02 * r2)
        v[r, i, 1] = bv[r, b, 1] + a2 * r0 - a0 * r2 - (D01 * r0 + D11 * r1 + D12 * r2)
        v[r, i, 2] = bv[r, b, 2] + a0 * r1 - a1 * r0 - (D02 * r0 + D12 * r1 + D22 * r2)
        w[r, i, 0] = a0
        w[r, i, 1] = a1
        w[r, i, 2] = a2
        rot[r, i] += math.sqrt(a0 * a0 + a1 * a1 + a2 * a2) * dt
        e0 -= s_ref[r, i, 0]
        e1 -= s_ref[r, i, 1]
        e2 -= s_ref[r, i, 2]
        m = e0 * e0 + e1 * e1 + e2 * e2
        umax2 = m if m > umax2 else umax2
    return umax2


@cuda.jit(device=True)
def residuals(r, g, tid, nthr, bv, bw, bm, bj, bforce, rmat, red):
    """rigid.residuals for RVE r: red[1, tid], red[2, tid] <- the thread's sums of the
    bodies' |F_b| [N] and kinetic energy [J] (bforce from `reduce`)."""
    fres = 0.0
    ekin = 0.0
    for b in range(tid, bm.shape[1], nthr):
        f0 = bforce[g, b, 0]
        f1 = bforce[g, b, 1]
        f2 = bforce[g, b, 2]
        fres += math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        ekin += 0.5 * bm[r, b] * (bv[r, b, 0] * bv[r, b, 0] + bv[r, b, 1] * bv[r, b, 1]
                                  + bv[r, b, 2] * bv[r, b, 2])
        for a in range(3):
            wa = rmat[g, b, 0, a] * bw[r, b, 0] + rmat[g, b, 1, a] * bw[r, b, 1] \
                + rmat[g, b, 2, a] * bw[r, b, 2]
            ekin += 0.5 * bj[r, b, a] * wa * wa
    red[1, tid] = fres
    red[2, tid] = ekin

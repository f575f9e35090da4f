"""The batched DEM step on one CUDA GPU (numba.cuda): `advance_batch` of kernel.py.

Same physics, arguments and outputs as `kernel.advance_batch` (see kernel.py for the
equations: cell control with servos, linear spring(-dashpot) contacts kn = E r*, r* =
2 ri rj/(ri + rj), kt = ratio kn, tangential history rotated with the contact frame and
capped at mu max(f_n, 0), Love-Weber stress minus the kinetic stress, affine stiffness,
leapfrog with Cundall damping and the SLLOD pseudo-force, the Verlet-skin list check),
the same status codes (neighbours.Status) and the same `out[r, 0..5]`: contacts,
unbalanced-force ratio, kinetic energy [J], row length a build asked for, steps done,
largest overlap delta/R* (Hertz-Mindlin: kn = 2 E* a, f_n = (2/3) kn delta).

Layout. One thread block per RVE (a block loops over RVEs r = blockIdx, blockIdx +
gridDim, ... so that the scratch below is needed per block, not per RVE); its threads
stride over particles (thread t takes i = t, t + T, t + 2T, ...). `launch` runs it on
device arrays (the RveState arrays, `link` aside, and the Controls): a run keeps them on
the device (device_batch.py); `advance_batch` copies host arrays down and back around
one call. Per step of an RVE:

1. list build, if flagged: brute force over pairs j > i, each listed when closer than
   r_i + r_j + skin (as on the CPU). A cell at least twice the largest cutoff 2 r_max +
   skin wide (checked, else TOO_THIN) has at most one image of j that close to i, the
   one with fractional offset s_j + k - s_i in (-1/2, 1/2) per axis: k is found by
   rounding, one distance per pair. Rows hold j in increasing order (the CPU's cell
   list gives another order, the same pairs and image codes); the tangential history of
   a persisting pair is carried over by matching (j, image) after re-wrapping, as
   `neighbours.build` does. A count pass first, so an overflow (OVERFLOW, needed row
   length in out[r, 3]) leaves the state untouched for `engine.advance` to regrow.
2. cell control on thread 0 (a few 3x3 products), shared with the block.
3. contacts: thread t evaluates the half-list rows of its particles and writes, per
   entry, the force on i and the torque l_j (n x f_t) on j to scratch; its own force and
   torque it sums in row order. After a barrier each particle j sums the entries that
   name it through a reverse list (entries (i, k) with nbr_j[i, k] = j, sorted by i K + k,
   built after each list build) and adds its own row sum last: force[j] =
   (0 - F_a - F_b - ...) + sum_row(j), exactly the CPU's order of additions. No float
   atomics anywhere (the reverse list uses integer atomics for slots, then a sort). The
   reverse list has 2 K slots per particle; a particle named by more entries stops the
   RVE with OVERFLOW and out[r, 3] >= count / 2, so that the regrown K fits it.
4. stress, stiffness, contact count, sum of f_n, |F| and kinetic energy: per-thread
   partial sums in particle order, then a fixed-order sum over the T partials.
5. integration per particle, as `_translate` / `_rotate`; the list-check maximum of
   |s - s_ref| is a maximum (exact in any order).

Guarantees.
- Bitwise run-to-run reproducibility on one GPU with the same `threads` (block size):
  every sum has a fixed order, and the only atomics are integer slot counters whose
  outcome is sorted before use. A different block size changes the partial sums of 4.
- Agreement with the CPU path at round-off, not bitwise: forces sum in the CPU's order
  over a row, but the row's order differs after a device list build; the stress and
  energy sums of 4 are split per thread; the CPU kernels use LLVM fast-math (FMA
  contraction, reassociation in the contact pass) while NVVM contracts multiply-adds
  its own way (the PTX has fused multiply-adds). On the simulator (no FMA) states agree
  to <= 6e-14 relative after 40 steps of 24-sphere RVEs; DEM dynamics amplifies
  round-off (chaotic grain collisions), so over many steps RVEs agree statistically, not
  pointwise. Status codes, step counts and contact counts agree exactly as long as no
  contact sits within round-off of touching.
Clumps (`_make_kernel(..., clumped=True)`, the arguments CLUMP_ARGS and the bodies'
member lists): after a build the pairs inside a body are dropped and the images fixed,
the stress uses the branch between the bodies' centres and their kinetic stress, and
step 5 is cuda_rigid.advance (bodies, then members placed) instead of the spheres'
integration; the unbalanced ratio and kinetic energy are per body (kernel.py's clumps).

tests/dem/test_cuda_kernel.py runs it on numba's simulator (NUMBA_ENABLE_CUDASIM=1)
and, where one is usable, on a GPU; measured on an H100 in docs/performance.md.
"""

from __future__ import annotations

import math

import numpy as np
from numba import config as numba_config
from numba import cuda, float64

from grainscale.dem import cuda_rigid
from grainscale.dem.cuda_rigid import kick
from grainscale.dem.cuda_rigid import signed as _signed
from grainscale.dem.kernel import SERVO_EVERY
from grainscale.dem.neighbours import Status
from grainscale.linalg3 import det3, inv3

THREADS = 128  # block size (threads per RVE) of calls that name none; may be set
# registers per thread the kernel may use (None: the compiler's choice, 255 on an H200,
# which allows 2 blocks of 128 threads per SM). 128 allows 4 and was 1.11x faster on
# 10,000 RVEs of 800 spheres; 80 spills and was 1.4x slower (docs/performance.md)
MAX_REGISTERS = 128
MAX_BLOCKS = 1024  # blocks (RVEs in flight) of calls that name none; the scratch is per
# block; may be set
NSUM = 17  # partial sums reduced per block: contacts, sum f_n, 9 stress, 6 stiffness
NRED = NSUM + 1  # and a maximum: the largest overlap delta/R* (Hertz-Mindlin)
# status codes as plain ints (compile-time constants of the device code)
OK, OVERFLOW, TOO_THIN, NOT_FINITE = (int(Status.OK), int(Status.OVERFLOW),
                                      int(Status.TOO_THIN), int(Status.NOT_FINITE))


def is_available() -> bool:
    """True if numba.cuda finds a usable GPU (or runs its simulator)."""
    try:
        return bool(cuda.is_available())
    except Exception:  # a broken driver install: treat as no GPU
        return False


def select_gpu(node_rank: int) -> int:
    """Make GPU node_rank % (visible GPUs) this process's device, so that the MPI ranks
    of a node share its GPUs round robin (one visible GPU per rank, as set by
    CUDA_VISIBLE_DEVICES, gives device 0). Call before any kernel runs. Returns its
    index among the visible GPUs."""
    dev = node_rank % len(cuda.gpus)
    cuda.select_device(dev)
    return dev


# --------------------------------------------------------------------- device helpers
@cuda.jit(device=True)
def _max(a, b):
    """max(a, b) as Python's builtin (a unless b > a). The builtin's varargs overload
    does not compile as a device call with numba 0.68's CUDA target."""
    return b if b > a else a


@cuda.jit(device=True)
def _min(a, b):
    """min(a, b) as Python's builtin (a unless b < a)."""
    return b if b < a else a


# out = a^-1 of a 3x3, returns det a: the CPU's own function, compiled for the device
_inv3 = cuda.jit(device=True)(inv3.py_func)


_det3 = cuda.jit(device=True)(det3.py_func)  # linalg3.det3 on the device


@cuda.jit(device=True)
def _min_width(h):
    """Smallest perpendicular width of the cell h [m], as cell.perpendicular_widths."""
    vol = abs(_det3(h))
    wmin = math.inf
    for k in range(3):
        i = (k + 1) % 3
        j = (k + 2) % 3
        c0 = h[1, i] * h[2, j] - h[2, i] * h[1, j]
        c1 = h[2, i] * h[0, j] - h[0, i] * h[2, j]
        c2 = h[0, i] * h[1, j] - h[1, i] * h[0, j]
        wmin = _min(wmin, vol / math.sqrt(c0 * c0 + c1 * c1 + c2 * c2))
    return wmin


@cuda.jit(device=True)
def _sum_rows(red, res, nq, tid):
    """res[q] = sum over threads t (in order t = 0, 1, ...) of red[q, t], q < nq: a
    fixed-order block reduction. Barriers before and after."""
    cuda.syncthreads()
    for q in range(tid, nq, red.shape[1]):  # a block smaller than nq takes several
        acc = red[q, 0]
        for t in range(1, red.shape[1]):
            acc += red[q, t]
        res[q] = acc
    cuda.syncthreads()


@cuda.jit(device=True)
def _max_row(red, res, q, tid):
    """res[q] = max over threads of red[q, t]. Barriers before and after."""
    cuda.syncthreads()
    if tid == 0:
        acc = red[q, 0]
        for t in range(1, red.shape[1]):
            acc = _max(acc, red[q, t])
        res[q] = acc
    cuda.syncthreads()


@cuda.jit(device=True)
def _nearest_image(sw, g, r, i, j, h, radius, skin):
    """Image code (0..26) of the image of j closer to i than r_i + r_j + skin, or -1 if
    none.

    sw holds wrapped fractional positions in [0, 1); k_a = -round(s_j - s_i)_a is the
    only candidate when every perpendicular width is at least twice the largest cutoff
    2 r_max + skin (|s_j + k - s_i|_a <= |d| / w_a < 1/2). The distance is computed as
    `neighbours._scan` computes it, (s_j + k) - s_i mapped by h."""
    a = -math.floor(sw[g, j, 0] - sw[g, i, 0] + 0.5)
    b = -math.floor(sw[g, j, 1] - sw[g, i, 1] + 0.5)
    c = -math.floor(sw[g, j, 2] - sw[g, i, 2] + 0.5)
    f0 = sw[g, j, 0] + a - sw[g, i, 0]
    f1 = sw[g, j, 1] + b - sw[g, i, 1]
    f2 = sw[g, j, 2] + c - sw[g, i, 2]
    d0 = h[0, 0] * f0 + h[0, 1] * f1 + h[0, 2] * f2
    d1 = h[1, 0] * f0 + h[1, 1] * f1 + h[1, 2] * f2
    d2 = h[2, 0] * f0 + h[2, 1] * f1 + h[2, 2] * f2
    cij = radius[r, i] + radius[r, j] + skin  # as neighbours._scan
    if d0 * d0 + d1 * d1 + d2 * d2 < cij * cij:
        return (int(a) + 1) * 9 + (int(b) + 1) * 3 + (int(c) + 1)
    return -1


@cuda.jit(device=True)
def _build(r, g, tid, nthr, h, s, radius, nbr_j, nbr_shift, nbr_count, ft, s_ref, h_ref,
           wrapv, sw, old_j, old_code, old_ft, skin, cutoff, red, res):
    """Rebuild the half list of RVE r on its block (collective: every thread calls it);
    returns (status, largest row length needed), the same in every thread, as
    neighbours.build. On success s is wrapped into [0, 1), s_ref and h_ref record the
    build, and every surviving pair keeps its history ft (old_ft: the entries' scratch,
    6 components a slot, room for a rolling history)."""
    n = s.shape[1]
    cap = nbr_j.shape[2]
    hw = ft.shape[3]
    hr = h[r]
    if _min_width(hr) < 2.0 * cutoff:  # the same arithmetic in every thread
        return TOO_THIN, 0
    # wrap into [0, 1): the image counts removed (wrapv) re-map the old shifts below
    bad = 0.0
    for i in range(tid, n, nthr):
        for k in range(3):
            f = math.floor(s[r, i, k])
            x = s[r, i, k] - f
            if x >= 1.0:  # s slightly below an integer rounds to exactly 1.0
                x -= 1.0
                f += 1.0
            if not (x >= 0.0 and x < 1.0):  # NaN or infinite s
                bad = 1.0
            else:
                wrapv[g, i, k] = int(f)
                sw[g, i, k] = x
    red[0, tid] = bad
    _max_row(red, res, 0, tid)
    if res[0] != 0.0:
        return NOT_FINITE, 0
    # pass 1: count only, so that an overflow leaves the state untouched
    need = 0
    for i in range(tid, n, nthr):
        c = 0
        for j in range(i + 1, n):
            if _nearest_image(sw, g, r, i, j, hr, radius, skin) >= 0:
                c += 1
        need = _max(need, c)
    red[0, tid] = need
    _max_row(red, res, 0, tid)
    need = int(res[0])
    if need > cap:
        return OVERFLOW, need
    # pass 2: each thread rewrites its own rows, history matched by (j, image)
    for i in range(tid, n, nthr):
        m = nbr_count[r, i]
        for k in range(m):
            j = nbr_j[r, i, k]
            code = int(nbr_shift[r, i, k])  # uint8: no wrap-around in the sums below
            a = code // 9 - 1 + wrapv[g, j, 0] - wrapv[g, i, 0]
            b = (code // 3) % 3 - 1 + wrapv[g, j, 1] - wrapv[g, i, 1]
            c = code % 3 - 1 + wrapv[g, j, 2] - wrapv[g, i, 2]
            old_j[g, i, k] = j
            if abs(a) <= 1 and abs(b) <= 1 and abs(c) <= 1:
                old_code[g, i, k] = (a + 1) * 9 + (b + 1) * 3 + (c + 1)
            else:
                old_code[g, i, k] = -1
            for c in range(hw):
                old_ft[g, i, k, c] = ft[r, i, k, c]
        cnew = 0
        for j in range(i + 1, n):
            code = _nearest_image(sw, g, r, i, j, hr, radius, skin)
            if code < 0:
                continue
            nbr_j[r, i, cnew] = j
            nbr_shift[r, i, cnew] = code
            for c in range(hw):
                ft[r, i, cnew, c] = 0.0
            for q in range(m):
                if old_j[g, i, q] == j and old_code[g, i, q] == code:
                    for c in range(hw):
                        ft[r, i, cnew, c] = old_ft[g, i, q, c]
                    break
            cnew += 1
        for k in range(cnew, m):  # slots out of use hold zeros, as on the CPU
            for c in range(hw):
                ft[r, i, k, c] = 0.0
        nbr_count[r, i] = cnew
    cuda.syncthreads()  # every row re-mapped wrapv of others before s changes
    for i in range(tid, n, nthr):
        for k in range(3):
            s[r, i, k] = sw[g, i, k]
            s_ref[r, i, k] = sw[g, i, k]
    if tid == 0:
        for a in range(3):
            for b in range(3):
                h_ref[r, a, b] = hr[a, b]
    cuda.syncthreads()
    return OK, need


@cuda.jit(device=True)
def _reverse(r, g, tid, nthr, nbr_j, nbr_count, rev, revc, red, res):
    """rev[g, j, :revc[g, j]] = the entries i K + k of the half list with nbr_j[i, k] = j,
    in increasing order (the order the CPU kernel adds them to j). Collective; returns
    the largest count (above rev.shape[2]: overflow, rev incomplete)."""
    n = nbr_count.shape[1]
    cap = nbr_j.shape[2]
    rk = rev.shape[2]
    for j in range(tid, n, nthr):
        revc[g, j] = 0
    cuda.syncthreads()
    for i in range(tid, n, nthr):
        for k in range(nbr_count[r, i]):
            j = nbr_j[r, i, k]
            slot = cuda.atomic.add(revc, (g, j), 1)  # integer: the slot order is sorted away
            if slot < rk:
                rev[g, j, slot] = i * cap + k
    cuda.syncthreads()
    need = 0
    for j in range(tid, n, nthr):
        c = revc[g, j]
        need = _max(need, c)
        if c <= rk:  # insertion sort: a few tens of entries
            for a in range(1, c):
                e = rev[g, j, a]
                b = a - 1
                while b >= 0 and rev[g, j, b] > e:
                    rev[g, j, b + 1] = rev[g, j, b]
                    b -= 1
                rev[g, j, b + 1] = e
    red[0, tid] = need
    _max_row(red, res, 0, tid)
    return int(res[0])


@cuda.jit(device=True)
def _contact_pass(r, g, tid, nthr, dt, young, kt_ratio, friction, gamma, alpha_r, eta_r, hz,
                  h, s, v, w, radius, mass, Ls, nbr_j, nbr_shift, nbr_count, ft, force, torque,
                  x, tab, ent, rev, revc, red, res, homogenise, commit, full_moduli,
                  clumped, off, bv, bm):
    """Contact forces and torques of RVE r (kernel.contact_pass, same law and arithmetic
    per contact, the history written only if `commit`); collective. Leaves in res: [0]
    contacts, [1] sum f_n [N] and, if `homogenise`, [2..10] sum d (x) F - sum m v (x) v
    (row-major), [11..16] the affine moduli sums c00, c11, c22, c01, c02, c12 (kt's
    part only with `full_moduli`; neither divided by V yet) and [17] the largest overlap
    delta/R* (Hertz-Mindlin, hz = 2 E* > 0; else 0). Clumped (members of bodies): the
    branch between the bodies' centres, d - off_j + off_i, in the stress and moduli, and
    the bodies' kinetic stress (kernel.contact_pass)."""
    n = s.shape[1]
    cap = nbr_j.shape[2]
    hw = ft.shape[3]
    rolling = alpha_r > 0.0
    # x = h s; the image table was filled by thread 0 from the same h
    for i in range(tid, n, nthr):
        s0 = s[r, i, 0]
        s1 = s[r, i, 1]
        s2 = s[r, i, 2]
        x[g, i, 0] = h[r, 0, 0] * s0 + h[r, 0, 1] * s1 + h[r, 0, 2] * s2
        x[g, i, 1] = h[r, 1, 0] * s0 + h[r, 1, 1] * s1 + h[r, 1, 2] * s2
        x[g, i, 2] = h[r, 2, 0] * s0 + h[r, 2, 1] * s1 + h[r, 2, 2] * s2
    sp0 = 0.5 * (Ls[2, 1] - Ls[1, 2])
    sp1 = 0.5 * (Ls[0, 2] - Ls[2, 0])
    sp2 = 0.5 * (Ls[1, 0] - Ls[0, 1])
    D00 = Ls[0, 0]
    D11 = Ls[1, 1]
    D22 = Ls[2, 2]
    D01 = 0.5 * (Ls[0, 1] + Ls[1, 0])
    D02 = 0.5 * (Ls[0, 2] + Ls[2, 0])
    D12 = 0.5 * (Ls[1, 2] + Ls[2, 1])
    sxx = sxy = sxz = syx = syy = syz = szx = szy = szz = 0.0
    c00 = c11 = c22 = c01 = c02 = c12 = 0.0
    ncontact = 0.0
    fsum = 0.0
    omax = 0.0
    kt_mod = kt_ratio if full_moduli else 0.0
    geo = 1.0 if full_moduli else 0.0  # the turning of the contact forces
    cuda.syncthreads()  # every x written
    for i in range(tid, n, nthr):
        xi0 = x[g, i, 0]
        xi1 = x[g, i, 1]
        xi2 = x[g, i, 2]
        ri = radius[r, i]
        fi0 = fi1 = fi2 = 0.0
        ti0 = ti1 = ti2 = 0.0
        for k in range(nbr_count[r, i]):
            j = nbr_j[r, i, k]
            t = nbr_shift[r, i, k]
            d0 = x[g, j, 0] - xi0 + tab[t, 0]
            d1 = x[g, j, 1] - xi1 + tab[t, 1]
            d2 = x[g, j, 2] - xi2 + tab[t, 2]
            rj = radius[r, j]
            rr = ri + rj
            dist2 = d0 * d0 + d1 * d1 + d2 * d2
            if dist2 >= rr * rr:
                if commit:
                    for c in range(hw):
                        ft[r, i, k, c] = 0.0
                for c in range(6):
                    ent[g, i, k, c] = 0.0  # adds nothing to j's sums
                continue
            dist = math.sqrt(dist2)
            inv2 = 1.0 / (dist * rr)
            inv = inv2 * rr
            n0 = d0 * inv
            n1 = d1 * inv
            n2 = d2 * inv
            if hz > 0.0:  # Hertz, as kernel.contact_pass
                ovl = (rr - dist) * rr / (ri * rj)
                kn = hz * ri * rj * dist * inv2 * math.sqrt(ovl)
                fn = (2.0 / 3.0) * kn * (rr - dist)
                omax = _max(omax, ovl)
            else:
                kn = young * 2.0 * ri * rj * dist * inv2
                fn = kn * (rr - dist)
            half = 0.5 * (rr - dist)
            li = ri - half
            lj = rj - half
            wa0 = li * w[r, i, 0] + lj * w[r, j, 0]
            wa1 = li * w[r, i, 1] + lj * w[r, j, 1]
            wa2 = li * w[r, i, 2] + lj * w[r, j, 2]
            vr0 = v[r, j, 0] - v[r, i, 0] + D00 * d0 + D01 * d1 + D02 * d2 - (wa1 * n2 - wa2 * n1)
            vr1 = v[r, j, 1] - v[r, i, 1] + D01 * d0 + D11 * d1 + D12 * d2 - (wa2 * n0 - wa0 * n2)
            vr2 = v[r, j, 2] - v[r, i, 2] + D02 * d0 + D12 * d1 + D22 * d2 - (wa0 * n1 - wa1 * n0)
            vn = vr0 * n0 + vr1 * n1 + vr2 * n2
            if gamma > 0.0:
                mst = mass[r, i] * mass[r, j] / (mass[r, i] + mass[r, j])
                fn -= 2.0 * gamma * math.sqrt(mst * kn) * vn
            f0 = ft[r, i, k, 0]
            f1 = ft[r, i, k, 1]
            f2 = ft[r, i, k, 2]
            tw = 0.5 * ((w[r, i, 0] + w[r, j, 0]) * n0 + (w[r, i, 1] + w[r, j, 1]) * n1
                        + (w[r, i, 2] + w[r, j, 2]) * n2)
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
            cap_f = friction * _max(fn, 0.0)
            fm2 = f0 * f0 + f1 * f1 + f2 * f2
            if fm2 > cap_f * cap_f:
                sc = cap_f / math.sqrt(fm2)
                f0 *= sc
                f1 *= sc
                f2 *= sc
            if commit:
                ft[r, i, k, 0] = f0
                ft[r, i, k, 1] = f1
                ft[r, i, k, 2] = f2
            F0 = f0 - fn * n0
            F1 = f1 - fn * n1
            F2 = f2 - fn * n2
            fi0 += F0
            fi1 += F1
            fi2 += F2
            tq0 = n1 * f2 - n2 * f1
            tq1 = n2 * f0 - n0 * f2
            tq2 = n0 * f1 - n1 * f0
            ti0 += li * tq0
            ti1 += li * tq1
            ti2 += li * tq2
            tj0 = lj * tq0
            tj1 = lj * tq1
            tj2 = lj * tq2
            if rolling:  # the rolling moment, as kernel.contact_pass
                m0 = ft[r, i, k, 3]
                m1 = ft[r, i, k, 4]
                m2 = ft[r, i, k, 5]
                g0 = m0 + o1 * m2 - o2 * m1
                g1 = m1 + o2 * m0 - o0 * m2
                g2 = m2 + o0 * m1 - o1 * m0
                gn = g0 * n0 + g1 * n1 + g2 * n2
                a0 = w[r, j, 0] - w[r, i, 0]
                a1 = w[r, j, 1] - w[r, i, 1]
                a2 = w[r, j, 2] - w[r, i, 2]
                an = a0 * n0 + a1 * n1 + a2 * n2
                kr = alpha_r * kt * ri * rj
                m0 = g0 - gn * n0 - kr * (a0 - an * n0) * dt
                m1 = g1 - gn * n1 - kr * (a1 - an * n1) * dt
                m2 = g2 - gn * n2 - kr * (a2 - an * n2) * dt
                cap_m = eta_r * _min(ri, rj) * _max(fn, 0.0)
                mm2 = m0 * m0 + m1 * m1 + m2 * m2
                if mm2 > cap_m * cap_m:
                    sc = cap_m / math.sqrt(mm2)
                    m0 *= sc
                    m1 *= sc
                    m2 *= sc
                if commit:
                    ft[r, i, k, 3] = m0
                    ft[r, i, k, 4] = m1
                    ft[r, i, k, 5] = m2
                ti0 -= m0
                ti1 -= m1
                ti2 -= m2
                tj0 += m0
                tj1 += m1
                tj2 += m2
            # j's share, summed by j's thread after the barrier (no atomics)
            ent[g, i, k, 0] = F0
            ent[g, i, k, 1] = F1
            ent[g, i, k, 2] = F2
            ent[g, i, k, 3] = tj0
            ent[g, i, k, 4] = tj1
            ent[g, i, k, 5] = tj2
            ncontact += 1.0
            fsum += abs(fn)  # as kernel.py: the mean normal force magnitude
            if homogenise and clumped:  # branch between the bodies' centres
                e0 = d0 - off[r, j, 0] + off[r, i, 0]
                e1 = d1 - off[r, j, 1] + off[r, i, 1]
                e2 = d2 - off[r, j, 2] + off[r, i, 2]
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
            elif homogenise:
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
                kq = kt_mod * kn
                fa = geo * (abs(fn) + math.sqrt(f0 * f0 + f1 * f1 + f2 * f2))
                c00 += kn * q0 * q0 + kq * q0 * (dist - q0) + q0 * fa
                c11 += kn * q1 * q1 + kq * q1 * (dist - q1) + q1 * fa
                c22 += kn * q2 * q2 + kq * q2 * (dist - q2) + q2 * fa
                c01 += (kn - kq) * q0 * q1
                c02 += (kn - kq) * q0 * q2
                c12 += (kn - kq) * q1 * q2
        force[g, i, 0] = fi0  # the row's sum; j's entries are added before it below
        force[g, i, 1] = fi1
        force[g, i, 2] = fi2
        torque[g, i, 0] = ti0
        torque[g, i, 1] = ti1
        torque[g, i, 2] = ti2
    if homogenise:  # kinetic stress of the thread's particles (clumps: bodies)
        kin_m = bm if clumped else mass
        kin_v = bv if clumped else v
        for i in range(tid, kin_m.shape[1], nthr):
            mi = kin_m[r, i]
            u0 = kin_v[r, i, 0]
            u1 = kin_v[r, i, 1]
            u2 = kin_v[r, i, 2]
            sxx -= mi * u0 * u0
            sxy -= mi * u0 * u1
            sxz -= mi * u0 * u2
            syx -= mi * u1 * u0
            syy -= mi * u1 * u1
            syz -= mi * u1 * u2
            szx -= mi * u2 * u0
            szy -= mi * u2 * u1
            szz -= mi * u2 * u2
    cuda.syncthreads()  # every entry written
    for j in range(tid, n, nthr):
        a0 = a1 = a2 = 0.0
        b0 = b1 = b2 = 0.0
        for q in range(revc[g, j]):
            e = rev[g, j, q]
            i = e // cap
            k = e - i * cap
            a0 -= ent[g, i, k, 0]
            a1 -= ent[g, i, k, 1]
            a2 -= ent[g, i, k, 2]
            b0 += ent[g, i, k, 3]
            b1 += ent[g, i, k, 4]
            b2 += ent[g, i, k, 5]
        force[g, j, 0] = a0 + force[g, j, 0]
        force[g, j, 1] = a1 + force[g, j, 1]
        force[g, j, 2] = a2 + force[g, j, 2]
        torque[g, j, 0] = b0 + torque[g, j, 0]
        torque[g, j, 1] = b1 + torque[g, j, 1]
        torque[g, j, 2] = b2 + torque[g, j, 2]
    red[0, tid] = ncontact
    red[1, tid] = fsum
    if homogenise:
        red[2, tid] = sxx
        red[3, tid] = sxy
        red[4, tid] = sxz
        red[5, tid] = syx
        red[6, tid] = syy
        red[7, tid] = syz
        red[8, tid] = szx
        red[9, tid] = szy
        red[10, tid] = szz
        red[11, tid] = c00
        red[12, tid] = c11
        red[13, tid] = c22
        red[14, tid] = c01
        red[15, tid] = c02
        red[16, tid] = c12
        red[NSUM, tid] = omax
        _sum_rows(red, res, NSUM, tid)
        _max_row(red, res, NSUM, tid)
    else:
        _sum_rows(red, res, 2, tid)


@cuda.jit(device=True)
def _write_homogenised(r, h, res, out, stiff, write_stiff):
    """out[r] = stress sums / V and, if write_stiff, stiff[r] = stiffness sums / V [Pa]."""
    iv = 1.0 / _det3(h[r])
    for a in range(3):
        for b in range(3):
            out[r, a, b] = res[2 + 3 * a + b] * iv
    if write_stiff:
        stiff[r, 0, 0] = res[11] * iv
        stiff[r, 1, 1] = res[12] * iv
        stiff[r, 2, 2] = res[13] * iv
        stiff[r, 0, 1] = res[14] * iv
        stiff[r, 1, 0] = res[14] * iv
        stiff[r, 0, 2] = res[15] * iv
        stiff[r, 2, 0] = res[15] * iv
        stiff[r, 1, 2] = res[16] * iv
        stiff[r, 2, 1] = res[16] * iv


@cuda.jit(device=True)
def _cell_control(r, dt, h, L, stress_servo, stiffness, e_step, l_mean, hdot_fixed, l_ctrl,
                  servo_mask, servo_target, servo_gain, max_rate, hnew, hinv, Ls, tab):
    """Thread 0's part of step 2 (kernel.advance_rve): h_new = E h + dt (hdot_fixed +
    L_c h), L = L_mean + (hdot_fixed + L_c h) h^-1 (into Ls and L[r]), the servo rates
    L_c, and the image table h k of the current cell (27 shifts k)."""
    lc = cuda.local.array((3, 3), float64)
    hdot = cuda.local.array((3, 3), float64)
    for a in range(3):
        for b in range(3):
            lc[a, b] = l_ctrl[r, a, b]
    mr = max_rate[r]
    for a in range(3):
        for b in range(a, 3):
            if servo_mask[r, a, b] == 0:
                continue
            err = servo_target[r, a, b] - 0.5 * (stress_servo[r, a, b] + stress_servo[r, b, a])
            c = stiffness[r, a, b] if a == b else 2.0 * stiffness[r, a, b]
            if c > 0.0:
                rate = servo_gain * err / (c * dt)
            else:  # no contacts yet: move at the largest rate toward the target
                rate = mr if err > 0.0 else -mr
            rate = _min(_max(rate, -mr), mr)
            lc[a, b] = rate
            lc[b, a] = rate
    for a in range(3):
        for b in range(3):
            hdot[a, b] = hdot_fixed[r, a, b] + lc[a, 0] * h[r, 0, b] + lc[a, 1] * h[r, 1, b] \
                + lc[a, 2] * h[r, 2, b]
            hnew[a, b] = e_step[r, a, 0] * h[r, 0, b] + e_step[r, a, 1] * h[r, 1, b] \
                + e_step[r, a, 2] * h[r, 2, b] + dt * hdot[a, b]
    _inv3(h[r], hinv)
    for a in range(3):
        for b in range(3):
            la = l_mean[r, a, b] + hdot[a, 0] * hinv[0, b] + hdot[a, 1] * hinv[1, b] \
                + hdot[a, 2] * hinv[2, b]
            Ls[a, b] = la
            L[r, a, b] = la
    _image_table(r, h, tab)


@cuda.jit(device=True)
def _lists(r, g, tid, nthr, h, s, radius, nbr_j, nbr_shift, nbr_count, ft, s_ref, h_ref,
           wrapv, x, old_j, old_code, ent, rev, revc, skin, cutoff, need_rebuild, out, red,
           res, rev_ok, clumped, hinv, body, rho, image, off, bs, bq, rmat):
    """The lists a contact pass of RVE r needs (collective): the neighbour list rebuilt if
    the last check flagged it (clumped: then cuda_rigid.after_build, hinv receiving the
    cell's inverse), the reverse list made if stale. Returns (status code, rev_ok); on
    OVERFLOW out[r, 3] holds the row capacity to ask for."""
    if need_rebuild[r] != 0:
        code, needed = _build(r, g, tid, nthr, h, s, radius, nbr_j, nbr_shift, nbr_count, ft,
                              s_ref, h_ref, wrapv, x, old_j, old_code, ent, skin, cutoff,
                              red, res)
        if tid == 0:
            out[r, 3] = needed
        if code != OK:
            return code, rev_ok
        rev_ok = False
        cuda.syncthreads()  # need_rebuild read by all before thread 0 clears it
        if tid == 0:
            need_rebuild[r] = 0
            if clumped:
                _inv3(h[r], hinv)
        if clumped:
            cuda.syncthreads()
            cuda_rigid.after_build(r, g, tid, nthr, hinv, s, body, rho, image, off, bs, bq,
                                   nbr_j, nbr_shift, nbr_count, ft, rmat)
    if not rev_ok:
        rneed = _reverse(r, g, tid, nthr, nbr_j, nbr_count, rev, revc, red, res)
        if rneed > rev.shape[2]:  # rev holds 2 K: ask for K >= rneed / 2
            if tid == 0:
                out[r, 3] = _max(out[r, 3], float((rneed + 1) // 2))
            return OVERFLOW, rev_ok
        rev_ok = True
    return OK, rev_ok


@cuda.jit(device=True)
def _end_frame(r, h, L, Ls, tab):
    """Thread 0, before the end-of-increment evaluation: Ls <- L[r] (the last step's
    velocity gradient) and the image table of the current cell."""
    for a in range(3):
        for b in range(3):
            Ls[a, b] = L[r, a, b]
    _image_table(r, h, tab)


@cuda.jit(device=True)
def _image_table(r, h, tab):
    """tab[k] = h k for the 27 image shifts k of RVE r's cell (thread 0)."""
    for a in range(-1, 2):
        for b in range(-1, 2):
            for c in range(-1, 2):
                k = (a + 1) * 9 + (b + 1) * 3 + (c + 1)
                for d in range(3):
                    tab[k, d] = h[r, d, 0] * a + h[r, d, 1] * b + h[r, d, 2] * c


@cuda.jit(device=True)
def _integrate(r, g, tid, nthr, dt, damping, v, w, s, s_ref, rot, force, torque, mass,
               inertia, Ls, hinv, red):
    """Step 6 for the thread's particles (kernel._translate and _rotate, same
    arithmetic); red[0, tid] <- max |s - s_ref|^2."""
    n = s.shape[1]
    umax2 = 0.0
    for i in range(tid, n, nthr):
        u0, u1, u2 = kick(v[r, i, 0], v[r, i, 1], v[r, i, 2], force[g, i, 0],
                          force[g, i, 1], force[g, i, 2], dt / mass[r, i], damping, Ls, dt)
        v[r, i, 0] = u0
        v[r, i, 1] = u1
        v[r, i, 2] = u2
        e0 = u0 * dt
        e1 = u1 * dt
        e2 = u2 * dt
        s0 = s[r, i, 0] + (hinv[0, 0] * e0 + hinv[0, 1] * e1 + hinv[0, 2] * e2)
        s1 = s[r, i, 1] + (hinv[1, 0] * e0 + hinv[1, 1] * e1 + hinv[1, 2] * e2)
        s2 = s[r, i, 2] + (hinv[2, 0] * e0 + hinv[2, 1] * e1 + hinv[2, 2] * e2)
        s[r, i, 0] = s0
        s[r, i, 1] = s1
        s[r, i, 2] = s2
        e0 = s0 - s_ref[r, i, 0]
        e1 = s1 - s_ref[r, i, 1]
        e2 = s2 - s_ref[r, i, 2]
        umax2 = _max(umax2, e0 * e0 + e1 * e1 + e2 * e2)
        ii = dt / inertia[r, i]
        t0 = torque[g, i, 0]
        t1 = torque[g, i, 1]
        t2 = torque[g, i, 2]
        a0 = w[r, i, 0]
        a1 = w[r, i, 1]
        a2 = w[r, i, 2]
        a0 += ii * (t0 - damping * _signed(t0, a0))
        a1 += ii * (t1 - damping * _signed(t1, a1))
        a2 += ii * (t2 - damping * _signed(t2, a2))
        w[r, i, 0] = a0
        w[r, i, 1] = a1
        w[r, i, 2] = a2
        rot[r, i] += math.sqrt(a0 * a0 + a1 * a1 + a2 * a2) * dt
    red[0, tid] = umax2


@cuda.jit(device=True)
def _residuals(r, g, tid, nthr, force, v, w, mass, inertia, red):
    """red[1, tid], red[2, tid] <- the thread's sums of |F| [N] and of the kinetic energy
    [J] (kernel._residuals)."""
    fres = 0.0
    ekin = 0.0
    for i in range(tid, v.shape[1], nthr):
        f0 = force[g, i, 0]
        f1 = force[g, i, 1]
        f2 = force[g, i, 2]
        fres += math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        ww = w[r, i, 0] * w[r, i, 0] + w[r, i, 1] * w[r, i, 1] + w[r, i, 2] * w[r, i, 2]
        vv = v[r, i, 0] * v[r, i, 0] + v[r, i, 1] * v[r, i, 1] + v[r, i, 2] * v[r, i, 2]
        ekin += 0.5 * (mass[r, i] * vv + inertia[r, i] * ww)
    red[1, tid] = fres
    red[2, tid] = ekin


def _make_kernel(nthr: int, max_registers: int | None = None, clumped: bool = False):
    """The batch kernel for blocks of `nthr` threads (shared-array sizes are constants),
    at most `max_registers` registers per thread if given (more blocks per SM, spills);
    `clumped`: the spheres are members of rigid clumps (cuda_rigid.py steps the bodies;
    a constant of the kernel, so the spheres' variant holds no clump code)."""
    plain = max_registers is None or numba_config.ENABLE_CUDASIM  # the simulator takes none
    jit = cuda.jit if plain else cuda.jit(max_registers=max_registers)

    @jit
    def advance_kernel(nsteps, young, kt_ratio, friction, gamma, damping, skin, alpha_r,
                       eta_r, hz, dt,
                       servo_gain, h, s, v, w, rot, radius, mass, inertia, L, stress,
                       stress_servo, stiffness, step_count, nbr_j, nbr_shift, nbr_count, ft,
                       s_ref, h_ref, need_rebuild, e_step, l_mean, hdot_fixed, l_ctrl,
                       servo_mask, servo_target, max_rate, status, out, ent, rev, revc, old_j,
                       old_code, force, torque, x, wrapv, body, rho, image, off, bs, bv, bw,
                       bq, bl, bm, bj, first, members, bforce, btorque, rmat):
        tid = cuda.threadIdx.x
        g = cuda.blockIdx.x
        red = cuda.shared.array((NRED, nthr), float64)
        res = cuda.shared.array(NRED, float64)
        hnew = cuda.shared.array((3, 3), float64)
        hinv = cuda.shared.array((3, 3), float64)
        Ls = cuda.shared.array((3, 3), float64)
        tab = cuda.shared.array((27, 3), float64)
        nrve = s.shape[0]
        n = s.shape[1]
        r = g
        while r < nrve:  # the same r in every thread: control flow is block-uniform
            nst = nsteps[r]
            rmax = 0.0
            for i in range(tid, n, nthr):
                rmax = _max(rmax, radius[r, i])
            red[0, tid] = rmax
            _max_row(red, res, 0, tid)
            cutoff = 2.0 * res[0] + skin
            servo_on = False
            for a in range(3):
                for b in range(3):
                    if servo_mask[r, a, b] != 0:
                        servo_on = True
            code = OK
            done = 0
            ncontact = 0.0
            fsum = 0.0
            rev_ok = False
            if clumped:
                cuda_rigid.orient(r, g, tid, nthr, body, rho, bq, off, rmat)
            for _step in range(nst):
                # 1. neighbour list, if the last step's check asked for it
                code, rev_ok = _lists(r, g, tid, nthr, h, s, radius, nbr_j, nbr_shift,
                                      nbr_count, ft, s_ref, h_ref, wrapv, x, old_j, old_code,
                                      ent, rev, revc, skin, cutoff, need_rebuild, out, red,
                                      res, rev_ok, clumped, hinv, body, rho, image, off, bs,
                                      bq, rmat)
                if code != OK:
                    break
                sample = servo_on and step_count[r] % SERVO_EVERY == 0
                # 2. cell control (thread 0), shared with the block
                if tid == 0:
                    _cell_control(r, dt, h, L, stress_servo, stiffness, e_step, l_mean,
                                  hdot_fixed, l_ctrl, servo_mask, servo_target, servo_gain,
                                  max_rate, hnew, hinv, Ls, tab)
                cuda.syncthreads()
                # 3-4. contacts, and the stress the servo reads
                _contact_pass(r, g, tid, nthr, dt, young, kt_ratio, friction, gamma, alpha_r,
                              eta_r, hz, h, s, v, w, radius, mass, Ls, nbr_j, nbr_shift,
                              nbr_count, ft, force, torque, x, tab, ent, rev, revc, red, res,
                              sample, True, False, clumped, off, bv, bm)
                ncontact = res[0]
                fsum = res[1]
                if tid == 0:
                    if sample:
                        _write_homogenised(r, h, res, stress_servo, stiffness, True)
                    step_count[r] += 1
                    # 5. new cell, its inverse for the position update
                    for a in range(3):
                        for b in range(3):
                            h[r, a, b] = hnew[a, b]
                    _inv3(h[r], hinv)
                cuda.syncthreads()
                # 6. integration
                if clumped:
                    red[0, tid] = cuda_rigid.advance(
                        r, g, tid, nthr, dt, damping, Ls, hinv, s, v, w, rot, s_ref, off,
                        force, torque, body, rho, image, bs, bv, bw, bq, bl, bm, bj, first,
                        members, bforce, btorque, rmat)
                else:
                    _integrate(r, g, tid, nthr, dt, damping, v, w, s, s_ref, rot, force,
                               torque, mass, inertia, Ls, hinv, red)
                _max_row(red, res, 0, tid)
                umax2 = res[0]
                # 7. list check (thread 0), as kernel.advance_rve
                if tid == 0:
                    hr = h[r]
                    n1 = _max(_max(abs(hr[0, 0]) + abs(hr[1, 0]) + abs(hr[2, 0]),
                                   abs(hr[0, 1]) + abs(hr[1, 1]) + abs(hr[2, 1])),
                              abs(hr[0, 2]) + abs(hr[1, 2]) + abs(hr[2, 2]))
                    ninf = _max(_max(abs(hr[0, 0]) + abs(hr[0, 1]) + abs(hr[0, 2]),
                                     abs(hr[1, 0]) + abs(hr[1, 1]) + abs(hr[1, 2])),
                                abs(hr[2, 0]) + abs(hr[2, 1]) + abs(hr[2, 2]))
                    umax2 *= n1 * ninf
                    _inv3(h_ref[r], hinv)
                    e2sum = 0.0
                    for a in range(3):
                        for b in range(3):
                            m = hr[a, 0] * hinv[0, b] + hr[a, 1] * hinv[1, b] \
                                + hr[a, 2] * hinv[2, b]
                            if a == b:
                                m -= 1.0
                            e2sum += m * m
                    if 2.0 * math.sqrt(umax2) + math.sqrt(e2sum) * cutoff >= skin:
                        need_rebuild[r] = 1
                done += 1
                cuda.syncthreads()  # need_rebuild and hinv settled before the next step
            # 8. end of the increment (kernel.advance_rve): the caller's stress and moduli
            # of the state reached, the history left as it is
            if code == OK and nst != 0:
                code, rev_ok = _lists(r, g, tid, nthr, h, s, radius, nbr_j, nbr_shift,
                                      nbr_count, ft, s_ref, h_ref, wrapv, x, old_j, old_code,
                                      ent, rev, revc, skin, cutoff, need_rebuild, out, red,
                                      res, rev_ok, clumped, hinv, body, rho, image, off, bs,
                                      bq, rmat)
                if code == OK:
                    if tid == 0:  # the last step's L, and the image table of the new cell
                        _end_frame(r, h, L, Ls, tab)
                    cuda.syncthreads()
                    _contact_pass(r, g, tid, nthr, 0.0, young, kt_ratio, friction, gamma,
                                  alpha_r, eta_r, hz, h, s, v, w, radius, mass, Ls, nbr_j,
                                  nbr_shift, nbr_count, ft, force, torque, x, tab, ent, rev,
                                  revc, red, res, True, False, not servo_on, clumped, off, bv,
                                  bm)
                    ncontact = res[0]
                    fsum = res[1]
                    if tid == 0:
                        _write_homogenised(r, h, res, stress, stiffness, not servo_on)
                        out[r, 5] = res[NSUM]
                    cuda.syncthreads()  # res read before the residuals overwrite it
                    grains = n
                    if clumped:  # per body: a member's force is not a grain's
                        cuda_rigid.reduce(r, g, tid, nthr, off, force, torque, first,
                                          members, bforce, btorque)
                        cuda_rigid.residuals(r, g, tid, nthr, bv, bw, bm, bj, bforce, rmat,
                                             red)
                        grains = bm.shape[1]
                    else:
                        _residuals(r, g, tid, nthr, force, v, w, mass, inertia, red)
                    _sum_rows(red, res, 3, tid)  # res[0] is then max-free: not read
                    if tid == 0:
                        out[r, 1] = (res[1] / grains) / (fsum / ncontact) if ncontact > 0 \
                            else 0.0
                        out[r, 2] = res[2]
                    cuda.syncthreads()
            if tid == 0:
                out[r, 0] = ncontact
                out[r, 4] = done
                status[r] = code
            cuda.syncthreads()
            r += cuda.gridDim.x

    return advance_kernel


_KERNELS: dict[int, object] = {}
SCRATCH_SHAPES = 8  # scratch shapes kept at once (a material retiled 8-fold has 4 sizes)
# (blocks, n, cap) -> _scratch's arrays, in order of last use (the oldest first)
_SCRATCH: dict[tuple[int, int, int], tuple] = {}


def _scratch(blocks: int, n: int, cap: int) -> tuple:
    """Per-block device scratch: the list entries' forces and torques (ent), the reverse
    list (rev, revc), a build's old rows (old_j, old_code), and a step's forces, torques,
    Cartesian (or, in a build, wrapped fractional) positions and wrap counts (force,
    torque, x, wrapv). The kernel writes it for an RVE before reading it for that RVE,
    so it needs no initialisation and is kept from call to call.

    Kept per shape (blocks, n, cap), the SCRATCH_SHAPES used last: the groups of a
    retiled material (N, 2N, ... spheres) alternate every update, each with its own
    arrays, allocated once. The device then holds the sum of these shapes' scratch, not
    the largest one's (groups of N and 2N spheres at equal blocks and cap: 1.5 times the
    2N group's), and a shape no longer launched (a group's RVE count or capacity changed)
    until SCRATCH_SHAPES newer ones displace it."""
    key = (blocks, n, cap)
    arrays = _SCRATCH.pop(key, None)
    if arrays is None:
        while len(_SCRATCH) >= SCRATCH_SHAPES:
            del _SCRATCH[next(iter(_SCRATCH))]  # free the oldest before allocating
        arrays = (cuda.device_array((blocks, n, cap, 6), np.float64),
                  cuda.device_array((blocks, n, 2 * cap), np.int32),
                  cuda.device_array((blocks, n), np.int32),
                  cuda.device_array((blocks, n, cap), np.int32),
                  cuda.device_array((blocks, n, cap), np.int32),
                  cuda.device_array((blocks, n, 3), np.float64),
                  cuda.device_array((blocks, n, 3), np.float64),
                  cuda.device_array((blocks, n, 3), np.float64),
                  cuda.device_array((blocks, n, 3), np.int32))
    _SCRATCH[key] = arrays  # (re)inserted last: the most recently used
    return arrays


# the state fields the kernel reads and writes, in its argument order, and those of the
# controls. The CPU's scratch of a step (force, torque, x, wrapv, link) is not state on
# the device: the kernel keeps it per block (_scratch)
STATE_ARGS = ("h", "s", "v", "w", "rot", "radius", "mass", "inertia", "L", "stress",
              "stress_servo", "stiffness", "step_count", "nbr_j", "nbr_shift", "nbr_count",
              "ft", "s_ref", "h_ref", "need_rebuild")
SCRATCH_ARGS = ("force", "torque", "x", "wrapv")  # per block; see advance_batch
READ_ONLY = ("radius", "mass", "inertia")  # not copied back
CONTROL_ARGS = ("e_step", "l_mean", "hdot_fixed", "l_ctrl", "servo_mask", "servo_target",
                "max_rate")


# the clump arrays the clumped kernel reads and writes (kernel.Clumps' fields), and the
# members of each body (cuda_rigid.member_lists)
CLUMP_ARGS = ("body", "rho", "image", "off", "bs", "bv", "bw", "bq", "bl", "bm", "bj")
CLUMP_READ_ONLY = ("body", "rho", "bm", "bj")


def _no_clumps() -> tuple:
    """Stand-ins for the clump arguments of the spheres' kernel, which never reads them
    (one element each: no zero-size device arrays)."""
    shapes = ((1, 1), (1, 1, 3), (1, 1, 3), (1, 1, 3), (1, 1, 3), (1, 1, 3), (1, 1, 3),
              (1, 1, 4), (1, 1, 3), (1, 1), (1, 1, 3), (1, 2), (1, 1), (1, 1, 3), (1, 1, 3),
              (1, 1, 3, 3))
    types = (np.int32,) + (np.float64,) * 10 + (np.int32, np.int32) + (np.float64,) * 3
    return tuple(cuda.device_array(sh, t) for sh, t in zip(shapes, types, strict=True))


def launch(d_nsteps, law, dev, dctl, dt: float, servo_gain: float, d_status, d_out,
           threads: int | None = None, max_blocks: int | None = None,
           dcl: tuple | None = None) -> tuple | None:
    """Run the batch kernel on device arrays: d_nsteps (R,) int64, dev the state arrays
    in STATE_ARGS order, dctl the controls in CONTROL_ARGS order, d_status (R,) int64,
    d_out (R,6). Nothing crosses to the host (dem/device_batch.py keeps the state there).
    Returns the per-block scratch (_scratch's arrays; None for an empty batch): block g
    ran RVEs g, g + B, ... with B = min(R, max_blocks), so where R <= max_blocks its
    SCRATCH_ARGS hold RVE g's last step.

    `threads` is the block size (threads per RVE; default the module's THREADS, read at
    each call, which is how engine.advance's callers choose it); `max_blocks` (default
    MAX_BLOCKS, read at each call) bounds the blocks in flight, and so the scratch: per
    block 6 doubles per list slot (entry forces and torques), 4 ints per slot (old rows
    during a build, the reverse list) and 88 B per sphere (a step's forces, torques,
    positions and wrap counts, the reverse-list counts).

    `dcl`: for clumped RVEs, their clump arrays on the device in CLUMP_ARGS order and
    the bodies' member lists (first, members); the per-block body scratch is added here
    (forces, torques, rotations: 120 B per body)."""
    threads = THREADS if threads is None else int(threads)
    max_blocks = MAX_BLOCKS if max_blocks is None else int(max_blocks)
    key = (threads, MAX_REGISTERS, dcl is not None)
    if key not in _KERNELS:
        _KERNELS[key] = _make_kernel(*key)
    nrve, n = dev[1].shape[:2]  # s
    if nrve == 0:
        return
    cap = dev[STATE_ARGS.index("nbr_j")].shape[2]
    blocks = max(1, min(nrve, max_blocks))
    scratch = _scratch(blocks, n, cap)
    if dcl is None:
        clumps = _no_clumps()
    else:
        nb = dcl[CLUMP_ARGS.index("bm")].shape[1]
        clumps = (*dcl, cuda.device_array((blocks, nb, 3), np.float64),
                  cuda.device_array((blocks, nb, 3), np.float64),
                  cuda.device_array((blocks, nb, 3, 3), np.float64))
    _KERNELS[key][blocks, threads](
        d_nsteps, float(law.young), float(law.kt_ratio), float(law.friction),
        float(law.gamma), float(law.damping), float(law.skin), float(law.rolling_stiffness),
        float(law.rolling_friction), float(law.hertz_kn), float(dt), float(servo_gain),
        *dev, *dctl, d_status, d_out, *scratch, *clumps)
    return scratch


def advance_batch(nsteps, law, st, ctl, status, out, threads: int | None = None,
                  max_blocks: int | None = None, cl=None) -> None:
    """Advance every RVE r by nsteps[r] steps on the GPU: kernel.advance_batch's
    arguments (host arrays: RveState st, ContactLaw law, Controls ctl with the RVE index
    first, status (R,), out (R,6)), results written back into them.

    The per-call path: copies the state to the device, runs every step there (`launch`),
    and copies it back. A run keeps its state on the device instead (device_batch.py).
    `st.force` and `st.torque` (the CPU's scratch, read by nothing after a call) get the
    last step's values for the RVEs that stepped where the batch fits the blocks in
    flight (R <= max_blocks, default MAX_BLOCKS), as tests compare them with the CPU's;
    otherwise they keep what they held. `cl`: the batch's kernel.Clumps (host arrays)
    when its spheres are clump members, copied down and back with the state."""
    if st.s.shape[0] == 0:
        return
    max_blocks = MAX_BLOCKS if max_blocks is None else int(max_blocks)
    host = [getattr(st, name) for name in STATE_ARGS]
    for name, a in zip(STATE_ARGS, host, strict=True):
        if not a.flags.c_contiguous:
            raise ValueError(f"RVE state array {name!r} is not C-contiguous")
    dev = [cuda.to_device(a) for a in host]
    dctl = [cuda.to_device(np.ascontiguousarray(getattr(ctl, name))) for name in CONTROL_ARGS]
    d_status = cuda.to_device(status)
    d_out = cuda.to_device(out)
    dcl = None
    if cl is not None:
        lists = cuda_rigid.member_lists(cl.body, cl.bm.shape[1])
        dcl = tuple(cuda.to_device(np.ascontiguousarray(getattr(cl, name)))
                    for name in CLUMP_ARGS) + tuple(cuda.to_device(a) for a in lists)
    scratch = launch(cuda.to_device(np.ascontiguousarray(nsteps, np.int64)), law, dev,
                     dctl, ctl.dt, ctl.servo_gain, d_status, d_out, threads, max_blocks, dcl)
    for name, a, d in zip(STATE_ARGS, host, dev, strict=True):
        if name not in READ_ONLY:
            d.copy_to_host(a)
    if cl is not None:
        for name, d in zip(CLUMP_ARGS, dcl, strict=False):
            if name not in CLUMP_READ_ONLY:
                d.copy_to_host(getattr(cl, name))
    d_status.copy_to_host(status)
    d_out.copy_to_host(out)
    if st.s.shape[0] <= max_blocks:
        # an RVE that took no step and made no end-of-increment evaluation (nsteps 0, or
        # a list overflow at its first build) left its block's scratch unwritten
        ran = (out[:, 4] > 0) | ((np.asarray(nsteps) == -1) & (status == OK))
        for name in ("force", "torque"):
            d = scratch[-len(SCRATCH_ARGS) + SCRATCH_ARGS.index(name)]
            getattr(st, name)[ran] = d.copy_to_host()[:st.s.shape[0]][ran]

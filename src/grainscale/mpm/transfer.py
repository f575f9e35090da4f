"""Particle-to-grid and grid-to-particle transfers (seed Eq. 4-6, 16-19), in numba.

Determinism. Every nodal sum (mass, momentum, force) is accumulated exactly in 64-bit
fixed point: each point's contribution c is rounded once to `round(c * scale)` and the
integers are added. Integer addition is associative, so the nodal sums do not depend on
the order in which points are visited, on the number of threads, or on how points are
split over MPI ranks before the integer all-reduce. `scale` is a power of two chosen
from an order-independent global bound, `n * max |c|` over all ranks (n: the points,
plus the traction loads for forces, each adding at most one term per node), so no sum
can overflow 2^62; the resolution is then that bound times 2^-62 (about 1e-13 of the
largest single contribution for a million points).

Threads (parallel.py): each thread scatters into its own integer buffer (race free), the
buffers are summed node by node. Points are visited in fixed chunks of `CHUNK`, so the
floating-point work per point is identical whatever the thread count.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from grainscale.linalg3 import det3
from grainscale.mpm.parallel import CHUNK, parallel_for
from grainscale.mpm.points import half_widths

HEADROOM = 62  # bits available to a nodal sum (int64 has 63 plus sign)


def stencil_counts(ns) -> np.ndarray:
    """The stencil's node counts per axis (3,) int64 from one count for all axes or
    three: the kernels visit ns[0] x ns[1] x ns[2] nodes from each point's base."""
    return np.ascontiguousarray(np.broadcast_to(np.asarray(ns, dtype=np.int64), (3,)))


def fixed_point_scale(bound: float) -> float:
    """Largest power of two s with bound * s <= 2^62 (1 when bound is 0)."""
    if not bound > 0.0 or not math.isfinite(bound):
        if bound > 0.0:
            raise FloatingPointError("non-finite value in a particle-to-grid transfer")
        return 1.0
    _, e = math.frexp(bound)  # bound < 2^e
    return math.ldexp(1.0, min(HEADROOM - e, 1000))  # capped: 2^1000 is still finite


@njit(cache=True, fastmath=True, inline="always")
def _p2g_mm_point(p, m, v, C, x, origin, h, base, w, nx, ny, ns, mscale, pscale, b):
    mp = m[p]
    for k in range(ns[2]):
        iz = base[p, 2] + k
        wz = w[p, 2, k]
        dz = origin[2] + iz * h[2] - x[p, 2]
        for j in range(ns[1]):
            iy = base[p, 1] + j
            row = nx * (iy + ny * iz) + base[p, 0]
            wyz = w[p, 1, j] * wz
            dy = origin[1] + iy * h[1] - x[p, 1]
            for i in range(ns[0]):
                I = row + i
                dx = origin[0] + (base[p, 0] + i) * h[0] - x[p, 0]
                sm = w[p, 0, i] * wyz * mp
                # APIC: the point's velocity field v_p + C_p (x_I - x_p) taken at the node
                vx = v[p, 0] + C[p, 0, 0] * dx + C[p, 0, 1] * dy + C[p, 0, 2] * dz
                vy = v[p, 1] + C[p, 1, 0] * dx + C[p, 1, 1] * dy + C[p, 1, 2] * dz
                vz = v[p, 2] + C[p, 2, 0] * dx + C[p, 2, 1] * dy + C[p, 2, 2] * dz
                b[I, 0] += np.int64(np.rint(sm * mscale))
                b[I, 1] += np.int64(np.rint(sm * vx * pscale))
                b[I, 2] += np.int64(np.rint(sm * vy * pscale))
                b[I, 3] += np.int64(np.rint(sm * vz * pscale))


@njit(cache=True, fastmath=True, inline="always")
def _p2g_mm_point_rect(p, m, v, C, x, X, base, w, nx, ny, ns, mscale, pscale, b):
    """_p2g_mm_point on a rectilinear grid: node (i, j, k) at (X[0, i], X[1, j], X[2, k])."""
    mp = m[p]
    for k in range(ns[2]):
        iz = base[p, 2] + k
        wz = w[p, 2, k]
        dz = X[2, iz] - x[p, 2]
        for j in range(ns[1]):
            iy = base[p, 1] + j
            row = nx * (iy + ny * iz) + base[p, 0]
            wyz = w[p, 1, j] * wz
            dy = X[1, iy] - x[p, 1]
            for i in range(ns[0]):
                I = row + i
                dx = X[0, base[p, 0] + i] - x[p, 0]
                sm = w[p, 0, i] * wyz * mp
                vx = v[p, 0] + C[p, 0, 0] * dx + C[p, 0, 1] * dy + C[p, 0, 2] * dz
                vy = v[p, 1] + C[p, 1, 0] * dx + C[p, 1, 1] * dy + C[p, 1, 2] * dz
                vz = v[p, 2] + C[p, 2, 0] * dx + C[p, 2, 1] * dy + C[p, 2, 2] * dz
                b[I, 0] += np.int64(np.rint(sm * mscale))
                b[I, 1] += np.int64(np.rint(sm * vx * pscale))
                b[I, 2] += np.int64(np.rint(sm * vy * pscale))
                b[I, 3] += np.int64(np.rint(sm * vz * pscale))


@njit(cache=True, fastmath=True, nogil=True)
def _p2g_mm_rect_task(t, nt, m, v, C, x, X, base, w, nodes, ns, mscale, pscale, buf):
    P = m.shape[0]
    b = buf[t]
    b[:, :] = 0
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            _p2g_mm_point_rect(p, m, v, C, x, X, base, w, nodes[0], nodes[1], ns, mscale,
                               pscale, b)


@njit(cache=True, fastmath=True, nogil=True)
def _p2g_mm_task(t, nt, m, v, C, x, origin, h, base, w, nodes, ns, mscale, pscale, buf):
    P = m.shape[0]
    b = buf[t]
    b[:, :] = 0
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            _p2g_mm_point(p, m, v, C, x, origin, h, base, w, nodes[0], nodes[1], ns, mscale,
                          pscale, b)


def p2g_mass_momentum_kernel(m, v, C, x, origin, h, base, w, nodes, ns, mscale, pscale, buf):
    """Scatter S_Ip m_p and S_Ip m_p (v_p + C_p (x_I - x_p)) into buf[t, I, 0:4] (fixed
    point): seed Eq. 16, with the affine term of APIC (Jiang et al. 2015, Eq. 11); C = 0
    is the FLIP/PIC transfer."""
    ns = stencil_counts(ns)
    parallel_for(_p2g_mm_task, m, v, C, x, origin, h, base, w, nodes, ns, mscale, pscale, buf,
                 nt=buf.shape[0])


@njit(cache=True, fastmath=True, nogil=True)
def _force_bound_task(t, nt, m, vol, stress, fext, gravity, h, out):
    P = m.shape[0]
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        mx = 0.0
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            for a in range(3):
                s = 0.0
                for b in range(3):
                    s += abs(stress[p, a, b]) / h[b]
                s = s * vol[p] + m[p] * abs(gravity[a]) + abs(fext[p, a])
                mx = max(mx, s)
        out[c] = mx


def force_bound_kernel(m, vol, stress, fext, gravity, h, out):
    """out[c] = max over the points of chunk c of a bound on |f_Ip| (any component)."""
    parallel_for(_force_bound_task, m, vol, stress, fext, gravity, h, out)


@njit(cache=True, fastmath=True, inline="always")
def _p2g_force_point(p, m, vol, stress, fext, gravity, base, w, dw, nx, ny, ns, fscale, b):
    V = vol[p]
    s00 = stress[p, 0, 0] * V
    s01 = stress[p, 0, 1] * V
    s02 = stress[p, 0, 2] * V
    s10 = stress[p, 1, 0] * V
    s11 = stress[p, 1, 1] * V
    s12 = stress[p, 1, 2] * V
    s20 = stress[p, 2, 0] * V
    s21 = stress[p, 2, 1] * V
    s22 = stress[p, 2, 2] * V
    ex = m[p] * gravity[0] + fext[p, 0]
    ey = m[p] * gravity[1] + fext[p, 1]
    ez = m[p] * gravity[2] + fext[p, 2]
    for k in range(ns[2]):
        iz = base[p, 2] + k
        wz = w[p, 2, k]
        gz = dw[p, 2, k]
        for j in range(ns[1]):
            wy = w[p, 1, j]
            gy = dw[p, 1, j]
            row = nx * (base[p, 1] + j + ny * iz) + base[p, 0]
            for i in range(ns[0]):
                I = row + i
                wx = w[p, 0, i]
                S = wx * wy * wz
                dx = dw[p, 0, i] * wy * wz
                dy = wx * gy * wz
                dz = wx * wy * gz
                fx = S * ex - (s00 * dx + s01 * dy + s02 * dz)
                fy = S * ey - (s10 * dx + s11 * dy + s12 * dz)
                fz = S * ez - (s20 * dx + s21 * dy + s22 * dz)
                b[I, 0] += np.int64(np.rint(fx * fscale))
                b[I, 1] += np.int64(np.rint(fy * fscale))
                b[I, 2] += np.int64(np.rint(fz * fscale))


@njit(cache=True, fastmath=True, nogil=True)
def _p2g_force_task(t, nt, m, vol, stress, fext, gravity, base, w, dw, nodes, ns, fscale, buf):
    P = m.shape[0]
    b = buf[t]
    b[:, :] = 0
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            _p2g_force_point(p, m, vol, stress, fext, gravity, base, w, dw, nodes[0],
                             nodes[1], ns, fscale, b)


def p2g_force_kernel(m, vol, stress, fext, gravity, base, w, dw, nodes, ns, fscale, buf):
    """Scatter f_Ip = -V_p sigma_p . grad S_Ip + S_Ip (m_p g + f_ext,p) into buf[t, I, 0:3].

    Internal force seed Eq. 5, external force (gravity and point forces) seed Eq. 6.
    """
    ns = stencil_counts(ns)
    parallel_for(_p2g_force_task, m, vol, stress, fext, gravity, base, w, dw, nodes, ns,
                 fscale, buf, nt=buf.shape[0])


@njit(cache=True, fastmath=True, inline="always")
def _vgrad_point(p, vgrid, base, w, dw, nx, ny, ns, dt, dH, F, vol0, vol):
    # scalar accumulators stay in registers
    g00 = g01 = g02 = g10 = g11 = g12 = g20 = g21 = g22 = 0.0
    for k in range(ns[2]):
        iz = base[p, 2] + k
        wz = w[p, 2, k]
        gz = dw[p, 2, k]
        for j in range(ns[1]):
            wy = w[p, 1, j]
            gy = dw[p, 1, j]
            row = nx * (base[p, 1] + j + ny * iz) + base[p, 0]
            for i in range(ns[0]):
                I = row + i
                wx = w[p, 0, i]
                dx = dw[p, 0, i] * wy * wz
                dy = wx * gy * wz
                dz = wx * wy * gz
                v0 = vgrid[I, 0]
                v1 = vgrid[I, 1]
                v2 = vgrid[I, 2]
                g00 += v0 * dx
                g01 += v0 * dy
                g02 += v0 * dz
                g10 += v1 * dx
                g11 += v1 * dy
                g12 += v1 * dz
                g20 += v2 * dx
                g21 += v2 * dy
                g22 += v2 * dz
    h00, h01, h02 = dt * g00, dt * g01, dt * g02
    h10, h11, h12 = dt * g10, dt * g11, dt * g12
    h20, h21, h22 = dt * g20, dt * g21, dt * g22
    dH[p, 0, 0] = h00
    dH[p, 0, 1] = h01
    dH[p, 0, 2] = h02
    dH[p, 1, 0] = h10
    dH[p, 1, 1] = h11
    dH[p, 1, 2] = h12
    dH[p, 2, 0] = h20
    dH[p, 2, 1] = h21
    dH[p, 2, 2] = h22
    # F <- (I + dH) F, column by column
    for b in range(3):
        f0 = F[p, 0, b]
        f1 = F[p, 1, b]
        f2 = F[p, 2, b]
        F[p, 0, b] = f0 + h00 * f0 + h01 * f1 + h02 * f2
        F[p, 1, b] = f1 + h10 * f0 + h11 * f1 + h12 * f2
        F[p, 2, b] = f2 + h20 * f0 + h21 * f1 + h22 * f2
    vol[p] = det3(F[p]) * vol0[p]


@njit(cache=True, fastmath=True, nogil=True)
def _vgrad_task(t, nt, vgrid, base, w, dw, nodes, ns, dt, dH, F, vol0, vol):
    P = F.shape[0]
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            _vgrad_point(p, vgrid, base, w, dw, nodes[0], nodes[1], ns, dt, dH, F, vol0, vol)


def velocity_gradient_kernel(vgrid, base, w, dw, nodes, ns, dt, dH, F, vol0, vol):
    """dH_p = dt sum_I v_I (x) grad S_Ip (seed Eq. 17), then F <- (I + dH) F, V = det F V0.

    Index convention: dH[p, a, b] = d(Delta u_a) / d x_b.
    """
    ns = stencil_counts(ns)
    parallel_for(_vgrad_task, vgrid, base, w, dw, nodes, ns, dt, dH, F, vol0, vol)


@njit(cache=True, fastmath=True, nogil=True)
def _gradient_task(t, nt, field, base, w, dw, nodes, ns, out):
    P = out.shape[0]
    nx, ny = nodes[0], nodes[1]
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            for a in range(3):
                for b in range(3):
                    out[p, a, b] = 0.0
            for k in range(ns[2]):
                iz = base[p, 2] + k
                wz = w[p, 2, k]
                gz = dw[p, 2, k]
                for j in range(ns[1]):
                    wy = w[p, 1, j]
                    gy = dw[p, 1, j]
                    row = nx * (base[p, 1] + j + ny * iz) + base[p, 0]
                    for i in range(ns[0]):
                        wx = w[p, 0, i]
                        dx = dw[p, 0, i] * wy * wz
                        dy = wx * gy * wz
                        dz = wx * wy * gz
                        for a in range(3):
                            f = field[row + i, a]
                            out[p, a, 0] += f * dx
                            out[p, a, 1] += f * dy
                            out[p, a, 2] += f * dz


def gradient_kernel(field, base, w, dw, nodes, ns, out):
    """out[p, a, b] = sum_I field[I, a] dS_Ip/dx_b: the gradient at the points of a nodal
    field (n_nodes, 3), in its units per m."""
    ns = stencil_counts(ns)
    parallel_for(_gradient_task, field, base, w, dw, nodes, ns, out)


@njit(cache=True, fastmath=True, nogil=True)
def _interpolate_task(t, nt, field, base, w, nodes, ns, out):
    P = out.shape[0]
    nx, ny = nodes[0], nodes[1]
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            acc = 0.0
            for k in range(ns[2]):
                iz = base[p, 2] + k
                wz = w[p, 2, k]
                for j in range(ns[1]):
                    wyz = w[p, 1, j] * wz
                    row = nx * (base[p, 1] + j + ny * iz) + base[p, 0]
                    for i in range(ns[0]):
                        acc += field[row + i] * w[p, 0, i] * wyz
            out[p] = acc


def interpolate_kernel(field, base, w, nodes, ns, out):
    """out[p] = sum_I S_Ip field[I]: a nodal scalar (n_nodes,) at the points (P,)."""
    ns = stencil_counts(ns)
    parallel_for(_interpolate_task, field, base, w, nodes, ns, out)


@njit(cache=True, fastmath=True, inline="always")
def _g2p_point(p, vold, vnew, vaff, base, w, dw, nx, ny, ns, dt, flip, apic, lo, hi, x, v, C):
    ax = ay = az = ux = uy = uz = 0.0
    c00 = c01 = c02 = c10 = c11 = c12 = c20 = c21 = c22 = 0.0
    for k in range(ns[2]):
        iz = base[p, 2] + k
        wz = w[p, 2, k]
        gz = dw[p, 2, k]
        for j in range(ns[1]):
            wy = w[p, 1, j]
            gy = dw[p, 1, j]
            wyz = wy * wz
            row = nx * (base[p, 1] + j + ny * iz) + base[p, 0]
            for i in range(ns[0]):
                I = row + i
                wx = w[p, 0, i]
                S = wx * wyz
                n0 = vnew[I, 0]
                n1 = vnew[I, 1]
                n2 = vnew[I, 2]
                ux += S * n0
                uy += S * n1
                uz += S * n2
                if apic:
                    dx = dw[p, 0, i] * wyz
                    dy = wx * gy * wz
                    dz = wx * wy * gz
                    a0 = vaff[I, 0]
                    a1 = vaff[I, 1]
                    a2 = vaff[I, 2]
                    c00 += a0 * dx
                    c01 += a0 * dy
                    c02 += a0 * dz
                    c10 += a1 * dx
                    c11 += a1 * dy
                    c12 += a1 * dz
                    c20 += a2 * dx
                    c21 += a2 * dy
                    c22 += a2 * dz
                if flip > 0.0:
                    ax += S * (n0 - vold[I, 0])
                    ay += S * (n1 - vold[I, 1])
                    az += S * (n2 - vold[I, 2])
    if apic:
        C[p, 0, 0], C[p, 0, 1], C[p, 0, 2] = c00, c01, c02
        C[p, 1, 0], C[p, 1, 1], C[p, 1, 2] = c10, c11, c12
        C[p, 2, 0], C[p, 2, 1], C[p, 2, 2] = c20, c21, c22
    if flip == 0.0:  # PIC, or APIC
        v0, v1, v2 = ux, uy, uz
    else:
        v0 = flip * (v[p, 0] + ax) + (1.0 - flip) * ux
        v1 = flip * (v[p, 1] + ay) + (1.0 - flip) * uy
        v2 = flip * (v[p, 2] + az) + (1.0 - flip) * uz
    v[p, 0] = v0
    v[p, 1] = v1
    v[p, 2] = v2
    x0 = x[p, 0] + dt * ux
    x1 = x[p, 1] + dt * uy
    x2 = x[p, 2] + dt * uz
    x[p, 0] = x0
    x[p, 1] = x1
    x[p, 2] = x2
    out = (x0 < lo[0] or x0 > hi[0] or x1 < lo[1] or x1 > hi[1] or x2 < lo[2]
           or x2 > hi[2])
    return v0 * v0 + v1 * v1 + v2 * v2, out


@njit(cache=True, fastmath=True, nogil=True)
def _g2p_task(t, nt, vold, vnew, vaff, base, w, dw, nodes, ns, dt, flip, apic, lo, hi, x, v, C,
              vmax_out, nout_out):
    P = x.shape[0]
    for c in range(t, (P + CHUNK - 1) // CHUNK, nt):
        vm = 0.0
        nout = 0
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            s2, out = _g2p_point(p, vold, vnew, vaff, base, w, dw, nodes[0], nodes[1], ns, dt, flip,
                                 apic, lo, hi, x, v, C)
            vm = max(vm, s2)
            if out:
                nout += 1
        vmax_out[c] = np.sqrt(vm)
        nout_out[c] = nout


def g2p_kernel(vold, vnew, vaff, base, w, dw, nodes, ns, dt, flip, apic, lo, hi, x, v, C, vmax_out,
               nout_out):
    """Point velocity (seed Eq. 18) and position (seed Eq. 19) update.

    APIC (apic = True, flip = 0; Jiang et al. 2015, in the velocity-gradient form of
    Taylor PIC, Nakamura et al. 2023, which is exactly APIC for linear shape functions):
        v_p <- sum S v_new,   C_p <- sum v_aff (x) grad S
    (v_aff is v_new but at nodes holding a sliver of mass: step.affine_velocity)
    FLIP/PIC blend (apic = False; C_p is left untouched, zero):
        v_p <- flip (v_p + sum S (v_new - v_old)) + (1 - flip) sum S v_new
    with v_old the mapped grid velocity before the boundaries acted, so that their
    impulse reaches the points. AFLIP (apic = True, flip > 0): the blend for v_p and
    APIC's C_p (P2G then maps the affine field). All: x_p <- x_p + dt sum S v_new.
    Per chunk: the largest point speed (for the CFL check) and the number of points
    whose centre left the grid box [lo, hi].
    """
    ns = stencil_counts(ns)
    parallel_for(_g2p_task, vold, vnew, vaff, base, w, dw, nodes, ns, dt, flip, apic, lo, hi, x, v,
                 C, vmax_out, nout_out)


@njit(cache=True)
def mark_covered_nodes_kernel(x, lp, origin, h, cells, mark):
    """mark[I] = True for every node inside or on the surface of a point's domain
    |x_I - x_p| <= l_p per axis (a relative tolerance of 1e-9 absorbs round-off)."""
    nx = cells[0] + 1
    ny = cells[1] + 1
    lo = np.empty(3, dtype=np.int64)
    hi = np.empty(3, dtype=np.int64)
    for p in range(x.shape[0]):
        for a in range(3):
            tol = 1e-9 * h[a]
            lo[a] = max(int(np.ceil((x[p, a] - lp[p] - tol - origin[a]) / h[a])), 0)
            hi[a] = min(int(np.floor((x[p, a] + lp[p] + tol - origin[a]) / h[a])), cells[a])
        for k in range(lo[2], hi[2] + 1):
            for j in range(lo[1], hi[1] + 1):
                for i in range(lo[0], hi[0] + 1):
                    mark[i + nx * (j + ny * k)] = True


@njit(cache=True)
def _mark_boxes(lo, hi, nx, ny, mark):
    for p in range(lo.shape[0]):
        for k in range(lo[p, 2], hi[p, 2] + 1):
            for j in range(lo[p, 1], hi[p, 1] + 1):
                for i in range(lo[p, 0], hi[p, 0] + 1):
                    mark[i + nx * (j + ny * k)] = True


def mark_covered_nodes_rectilinear(x, lp, axes, mark) -> None:
    """mark_covered_nodes_kernel on a rectilinear grid of node coordinates `axes`: the
    nodes with |X_I - x_p| <= l_p on every axis, lp (R,) or per axis (R,3) (a
    tolerance of 1e-9 of the smallest cell absorbs round-off), found by binary search
    per axis."""
    lo = np.empty((x.shape[0], 3), dtype=np.int64)
    hi = np.empty((x.shape[0], 3), dtype=np.int64)
    lp = half_widths(lp, x.shape[0])
    for a in range(3):
        X = np.asarray(axes[a])
        tol = 1e-9 * float(np.diff(X).min())
        lo[:, a] = np.searchsorted(X, x[:, a] - lp[:, a] - tol, side="left")
        hi[:, a] = np.searchsorted(X, x[:, a] + lp[:, a] + tol, side="right") - 1
    _mark_boxes(lo, hi, len(axes[0]), len(axes[1]), mark)


def stencil_box(base: np.ndarray, ns) -> np.ndarray:
    """(6,) float: minus the lowest and the highest-plus-one node index per axis touched
    by the stencils of ns nodes (one count or one per axis) starting at base (P,3);
    "minus" so that one MAX reduction gives the union of the ranks' boxes. An empty set
    gives an empty box."""
    if base.shape[0] == 0:
        return np.full(6, -np.inf)
    return np.concatenate([-base.min(axis=0),
                           base.max(axis=0) + stencil_counts(ns)]).astype(np.float64)


def box_view(a: np.ndarray, nodes: np.ndarray, box: np.ndarray) -> np.ndarray:
    """The nodes of `box` (from stencil_box, reduced) as a 3D view [k, j, i, ...] of the
    nodal array a (n_nodes, c)."""
    lo = np.maximum((-box[:3]).astype(np.int64), 0)
    hi = np.minimum(box[3:].astype(np.int64), nodes)
    grid = a.reshape(int(nodes[2]), int(nodes[1]), int(nodes[0]), a.shape[1])
    return grid[lo[2]:hi[2], lo[1]:hi[1], lo[0]:hi[0]]


class Transfer:
    """Scratch buffers for the fixed-point transfers of one point set on one grid.

    n_threads fixes the number of per-thread buffers, hence the threads used by P2G.
    Under MPI each rank holds a share of the points; `comm` reduces the integer nodal
    sums over the nodes any rank touches (the active box), and the fixed-point scales
    come from global maxima and the global point count `n_global`, so every rank gets
    the nodal values a single process would compute, bit for bit.
    """

    def __init__(self, n_nodes: int, n_points: int, n_threads: int, comm=None,
                 n_global: int | None = None, fold=None):
        from grainscale.distributed.comm import Comm

        self.fold = fold  # sums periodic images of the integer nodal sums (Grid.fold)
        self.n_threads = n_threads
        self.comm = comm if comm is not None else Comm()
        self.n_global = n_points if n_global is None else n_global
        self.buf4 = np.zeros((n_threads, n_nodes, 4), dtype=np.int64)
        self.buf3 = np.zeros((n_threads, n_nodes, 3), dtype=np.int64)
        self.sum4 = np.zeros((n_nodes, 4), dtype=np.int64)
        self.sum3 = np.zeros((n_nodes, 3), dtype=np.int64)
        self.chunk_max = np.zeros((n_points + CHUNK - 1) // CHUNK)
        self.chunk_count = np.zeros((n_points + CHUNK - 1) // CHUNK, dtype=np.int64)

    def _reduce(self, a: np.ndarray, nodes: np.ndarray, box: np.ndarray) -> None:
        """Sum the integer nodal array a over ranks, only on the nodes of box."""
        if self.comm.size == 1:
            return
        view = box_view(a, nodes, box)
        block = np.ascontiguousarray(view)
        self.comm.sum_int(block)
        view[...] = block

    def mass_momentum(self, m, v, C, x, grid, base, w, ns):
        """Nodal mass (n_nodes,) and momentum (n_nodes,3) from the points (seed Eq. 16,
        with the APIC affine velocity C of each point at x), and ok: False on every rank
        if any rank holds a non-finite velocity."""
        P = m.shape[0]
        # outside the fastmath kernels, and no NaN reduced
        bad = not (np.isfinite(v).all() and np.isfinite(C).all())
        # |v_p + C_p (x_I - x_p)| <= |v|max + max_a sum_b |C_ab| * 2 h: a stencil node lies
        # within 2 cells of its point. Its two maxima are reduced over ranks apart: the
        # maximum of per-rank sums is not the sum of the global maxima, and a scale that
        # depended on the split would round the momentum differently on other ranks
        reach = 2.0 * float(grid.cell_max.max())
        ok = P and not bad
        local = [float(m.max()) if P else 0.0, float(np.abs(v).max()) if ok else 0.0,
                 float(np.abs(C).sum(axis=2).max()) if ok else 0.0, 1.0 if bad else 0.0]
        g = self.comm.max([*local, *stencil_box(base, ns)])
        if g[3] > 0.0:
            return None, None, False
        vbound = g[1] + reach * g[2]
        mscale = fixed_point_scale(self.n_global * g[0])
        pscale = fixed_point_scale(self.n_global * g[0] * vbound)
        nodes = grid.nodes
        if P and grid.axes is not None:  # rectilinear: node positions from the table
            ns = stencil_counts(ns)
            parallel_for(_p2g_mm_rect_task, m, v, C, x, grid.node_table, base, w, nodes, ns, mscale,
                         pscale, self.buf4, nt=self.buf4.shape[0])
            np.sum(self.buf4, axis=0, out=self.sum4)
        elif P:
            p2g_mass_momentum_kernel(m, v, C, x, grid.origin, grid.cell_size, base, w, nodes,
                                     ns, mscale, pscale, self.buf4)
            np.sum(self.buf4, axis=0, out=self.sum4)  # exact: integers
        else:
            self.sum4[:] = 0
        self._reduce(self.sum4, nodes, g[4:])
        if self.fold is not None:
            self.fold(self.sum4)
        mass = self.sum4[:, 0] * (1.0 / mscale)
        mom = self.sum4[:, 1:4] * (1.0 / pscale)
        return mass, mom, True

    def force(self, m, vol, stress, fext, gravity, h, base, w, dw, nodes, ns,
              extra=None, n_extra: int = 0):
        """Nodal internal + external force (n_nodes,3), seed Eq. 5-6.

        extra = (node ids (k,), forces (k,3)): point loads mapped elsewhere (tractions),
        added in the same fixed point; n_extra bounds their global number per node.
        Returns (force, ok): ok is False on every rank if any rank met a non-finite
        stress or load (the force is then not computed).
        """
        P = m.shape[0]
        # checked outside the fastmath kernels, which may assume finite values
        bad = not (np.isfinite(stress).all() and np.isfinite(fext).all())
        if P and not bad:
            force_bound_kernel(m, vol, stress, fext, gravity, h, self.chunk_max)
        local = float(self.chunk_max.max()) if P and not bad else 0.0
        box = stencil_box(base, ns)
        if extra is not None and len(extra[0]):
            ids, f = extra
            bad = bad or not np.isfinite(f).all()
            local = max(local, float(np.abs(f).max()) if not bad else 0.0)
            kji = np.unravel_index(ids, (int(nodes[2]), int(nodes[1]), int(nodes[0])))
            box = np.maximum(box, stencil_box(np.stack(kji[::-1], axis=1), 1))
        g = self.comm.max([0.0 if bad else local, 1.0 if bad else 0.0, *box])
        if g[1] > 0.0:
            return None, False
        fscale = fixed_point_scale((self.n_global + n_extra) * g[0])
        if P:
            p2g_force_kernel(m, vol, stress, fext, gravity, base, w, dw, nodes, ns, fscale,
                             self.buf3)
            np.sum(self.buf3, axis=0, out=self.sum3)  # exact: integers
        else:
            self.sum3[:] = 0
        if extra is not None and len(extra[0]):
            np.add.at(self.sum3, extra[0], np.rint(extra[1] * fscale).astype(np.int64))
        self._reduce(self.sum3, nodes, g[2:])
        if self.fold is not None:
            self.fold(self.sum3)
        return self.sum3 * (1.0 / fscale), True

"""Particle-to-grid and grid-to-particle transfers (seed Eq. 4-6, 16-19), in numba.

Determinism. Every nodal sum (mass, momentum, force) is accumulated exactly in 64-bit
fixed point: each point's contribution c is rounded once to `round(c * scale)` and the
integers are added. Integer addition is associative, so the nodal sums do not depend on
the order in which points are visited, on the number of threads, or (later) on how points
are split over MPI ranks before an integer all-reduce. `scale` is a power of two chosen
from an order-independent global bound, `n_points * max_p |c_p|`, so no sum can overflow
2^62; the resolution is then that bound times 2^-62 (about 1e-13 of the largest
single contribution for a million points).

Threads: each thread scatters into its own integer buffer (race free), the buffers are
summed node by node. Points are visited in fixed chunks of `CHUNK`, so the floating-point
work per point is identical whatever the thread count.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from grainscale.mpm.shape import CHUNK

HEADROOM = 62  # bits available to a nodal sum (int64 has 63 plus sign)


def fixed_point_scale(bound: float) -> float:
    """Largest power of two s with bound * s <= 2^62 (1 when bound is 0)."""
    if not bound > 0.0 or not math.isfinite(bound):
        if bound > 0.0:
            raise FloatingPointError("non-finite value in a particle-to-grid transfer")
        return 1.0
    _, e = math.frexp(bound)  # bound < 2^e
    return math.ldexp(1.0, HEADROOM - e)


@njit(cache=True, fastmath=True, parallel=True)
def _reduce(buf, out):
    """out[I, q] = sum over threads of buf[t, I, q] (exact integer sum)."""
    nt = buf.shape[0]
    n = buf.shape[1]
    nq = buf.shape[2]
    for I in prange(n):
        for q in range(nq):
            s = 0
            for t in range(nt):
                s += buf[t, I, q]
            out[I, q] = s


@njit(cache=True, fastmath=True, parallel=True)
def p2g_mass_momentum_kernel(m, v, base, w, nodes, ns, mscale, pscale, buf):
    """Scatter S_Ip m_p and S_Ip m_p v_p into buf[t, I, 0:4] (fixed point), seed Eq. 16."""
    nt = buf.shape[0]
    P = m.shape[0]
    nx = nodes[0]
    ny = nodes[1]
    nchunks = (P + CHUNK - 1) // CHUNK
    for t in prange(nt):
        b = buf[t]
        b[:, :] = 0
        for c in range(t, nchunks, nt):
            for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
                mp = m[p]
                vx = v[p, 0]
                vy = v[p, 1]
                vz = v[p, 2]
                for k in range(ns):
                    iz = base[p, 2] + k
                    wz = w[p, 2, k]
                    for j in range(ns):
                        iy = base[p, 1] + j
                        wyz = w[p, 1, j] * wz
                        for i in range(ns):
                            I = base[p, 0] + i + nx * (iy + ny * iz)
                            sm = w[p, 0, i] * wyz * mp
                            b[I, 0] += np.int64(np.rint(sm * mscale))
                            b[I, 1] += np.int64(np.rint(sm * vx * pscale))
                            b[I, 2] += np.int64(np.rint(sm * vy * pscale))
                            b[I, 3] += np.int64(np.rint(sm * vz * pscale))


@njit(cache=True, fastmath=True, parallel=True)
def force_bound_kernel(m, vol, stress, fext, gravity, h, out):
    """out[c] = max over the points of chunk c of a bound on |f_Ip| (any component)."""
    P = m.shape[0]
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        mx = 0.0
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            for a in range(3):
                s = 0.0
                for b in range(3):
                    s += abs(stress[p, a, b]) / h[b]
                s = s * vol[p] + m[p] * abs(gravity[a]) + abs(fext[p, a])
                mx = max(mx, s)
        out[c] = mx


@njit(cache=True, fastmath=True, parallel=True)
def p2g_force_kernel(m, vol, stress, fext, gravity, base, w, dw, nodes, ns, fscale, buf):
    """Scatter f_Ip = -V_p sigma_p . grad S_Ip + S_Ip (m_p g + f_ext,p) into buf[t, I, 0:3].

    Internal force seed Eq. 5, external force (gravity and point tractions) seed Eq. 6.
    """
    nt = buf.shape[0]
    P = m.shape[0]
    nx = nodes[0]
    ny = nodes[1]
    nchunks = (P + CHUNK - 1) // CHUNK
    for t in prange(nt):
        b = buf[t]
        b[:, :] = 0
        for c in range(t, nchunks, nt):
            for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
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
                for k in range(ns):
                    iz = base[p, 2] + k
                    wz = w[p, 2, k]
                    gz = dw[p, 2, k]
                    for j in range(ns):
                        iy = base[p, 1] + j
                        wy = w[p, 1, j]
                        gy = dw[p, 1, j]
                        for i in range(ns):
                            I = base[p, 0] + i + nx * (iy + ny * iz)
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


@njit(cache=True, fastmath=True, parallel=True)
def velocity_gradient_kernel(vgrid, base, w, dw, nodes, ns, dt, dH, F, vol0, vol):
    """dH_p = dt sum_I v_I (x) grad S_Ip (seed Eq. 17), then F <- (I + dH) F, V = det F V0.

    Index convention: dH[p, a, b] = d(Delta u_a) / d x_b.
    """
    P = F.shape[0]
    nx = nodes[0]
    ny = nodes[1]
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        g = np.empty((3, 3))
        Fn = np.empty((3, 3))
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            for a in range(3):
                for bb in range(3):
                    g[a, bb] = 0.0
            for k in range(ns):
                iz = base[p, 2] + k
                wz = w[p, 2, k]
                gz = dw[p, 2, k]
                for j in range(ns):
                    iy = base[p, 1] + j
                    wy = w[p, 1, j]
                    gy = dw[p, 1, j]
                    for i in range(ns):
                        I = base[p, 0] + i + nx * (iy + ny * iz)
                        wx = w[p, 0, i]
                        dx = dw[p, 0, i] * wy * wz
                        dy = wx * gy * wz
                        dz = wx * wy * gz
                        for a in range(3):
                            va = vgrid[I, a]
                            g[a, 0] += va * dx
                            g[a, 1] += va * dy
                            g[a, 2] += va * dz
            for a in range(3):
                for bb in range(3):
                    dH[p, a, bb] = dt * g[a, bb]
            for a in range(3):
                for bb in range(3):
                    s = F[p, a, bb]
                    for q in range(3):
                        s += dH[p, a, q] * F[p, q, bb]
                    Fn[a, bb] = s
            for a in range(3):
                for bb in range(3):
                    F[p, a, bb] = Fn[a, bb]
            J = (Fn[0, 0] * (Fn[1, 1] * Fn[2, 2] - Fn[1, 2] * Fn[2, 1])
                 - Fn[0, 1] * (Fn[1, 0] * Fn[2, 2] - Fn[1, 2] * Fn[2, 0])
                 + Fn[0, 2] * (Fn[1, 0] * Fn[2, 1] - Fn[1, 1] * Fn[2, 0]))
            vol[p] = J * vol0[p]


@njit(cache=True, fastmath=True, parallel=True)
def g2p_kernel(vold, vnew, base, w, nodes, ns, dt, flip, lo, hi, x, v, vmax_out, nout_out):
    """Point velocity (FLIP/PIC blend, seed Eq. 18) and position (seed Eq. 19) update.

    v_p <- flip (v_p + sum S (v_new - v_old)) + (1 - flip) sum S v_new
    x_p <- x_p + dt sum S v_new
    Per chunk: the largest point speed (for the CFL check) and the number of points
    whose centre left the grid box [lo, hi].
    """
    P = x.shape[0]
    nx = nodes[0]
    ny = nodes[1]
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        vm = 0.0
        nout = 0
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            ax = 0.0
            ay = 0.0
            az = 0.0
            ux = 0.0
            uy = 0.0
            uz = 0.0
            for k in range(ns):
                iz = base[p, 2] + k
                wz = w[p, 2, k]
                for j in range(ns):
                    iy = base[p, 1] + j
                    wyz = w[p, 1, j] * wz
                    for i in range(ns):
                        I = base[p, 0] + i + nx * (iy + ny * iz)
                        S = w[p, 0, i] * wyz
                        ux += S * vnew[I, 0]
                        uy += S * vnew[I, 1]
                        uz += S * vnew[I, 2]
                        ax += S * (vnew[I, 0] - vold[I, 0])
                        ay += S * (vnew[I, 1] - vold[I, 1])
                        az += S * (vnew[I, 2] - vold[I, 2])
            v[p, 0] = flip * (v[p, 0] + ax) + (1.0 - flip) * ux
            v[p, 1] = flip * (v[p, 1] + ay) + (1.0 - flip) * uy
            v[p, 2] = flip * (v[p, 2] + az) + (1.0 - flip) * uz
            x[p, 0] += dt * ux
            x[p, 1] += dt * uy
            x[p, 2] += dt * uz
            s = v[p, 0] * v[p, 0] + v[p, 1] * v[p, 1] + v[p, 2] * v[p, 2]
            vm = max(vm, s)
            for a in range(3):
                if x[p, a] < lo[a] or x[p, a] > hi[a]:
                    nout += 1
                    break
        vmax_out[c] = np.sqrt(vm)
        nout_out[c] = nout


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


class Transfer:
    """Scratch buffers for the fixed-point transfers of one point set on one grid."""

    def __init__(self, n_nodes: int, n_points: int, n_threads: int):
        self.n_threads = n_threads
        self.buf4 = np.zeros((n_threads, n_nodes, 4), dtype=np.int64)
        self.buf3 = np.zeros((n_threads, n_nodes, 3), dtype=np.int64)
        self.sum4 = np.zeros((n_nodes, 4), dtype=np.int64)
        self.sum3 = np.zeros((n_nodes, 3), dtype=np.int64)
        self.chunk_max = np.zeros((n_points + CHUNK - 1) // CHUNK)
        self.chunk_count = np.zeros((n_points + CHUNK - 1) // CHUNK, dtype=np.int64)

    def mass_momentum(self, m, v, base, w, nodes, ns):
        """Nodal mass (n_nodes,) and momentum (n_nodes,3) from the points (seed Eq. 16)."""
        P = m.shape[0]
        mscale = fixed_point_scale(P * float(m.max())) if P else 1.0
        pscale = fixed_point_scale(P * float(m.max() * np.abs(v).max())) if P else 1.0
        p2g_mass_momentum_kernel(m, v, base, w, nodes, ns, mscale, pscale, self.buf4)
        _reduce(self.buf4, self.sum4)
        mass = self.sum4[:, 0] * (1.0 / mscale)
        mom = self.sum4[:, 1:4] * (1.0 / pscale)
        return mass, mom

    def force(self, m, vol, stress, fext, gravity, h, base, w, dw, nodes, ns):
        """Nodal internal + external force (n_nodes,3), seed Eq. 5-6."""
        P = m.shape[0]
        force_bound_kernel(m, vol, stress, fext, gravity, h, self.chunk_max)
        fscale = fixed_point_scale(P * float(self.chunk_max.max())) if P else 1.0
        p2g_force_kernel(m, vol, stress, fext, gravity, base, w, dw, nodes, ns, fscale,
                         self.buf3)
        _reduce(self.buf3, self.sum3)
        return self.sum3 * (1.0 / fscale)

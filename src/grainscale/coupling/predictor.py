"""The stress of an RVE that waits (adaptive updates, docs/coupling.md).

While an RVE's accumulated increment I + H_acc = R U stays below the tolerance, its
point's stress is predicted from the RVE's last update,

    sigma = R [sym(sigma_last) + C_aff : (U - I)] R^T,

with C_aff the affine stiffness of its contact network at that update, read from the six
moduli C_aabb the kernel stores (kernel.py item 8). One compiled loop over the waiting
RVEs: this runs every MPM step for most of a bed.
"""

from __future__ import annotations

import numba
import numpy as np

from grainscale.linalg3 import inv3


@numba.njit(cache=True)
def _affine_tangent(k, ratio, e, out):
    """out = C_aff : e [Pa] for one RVE (moduli k (3,3) [Pa], symmetric strain e (3,3)).

    For contacts with branch d = |d| n the affine moduli are C_abcd = (1/V) sum kn |d|^2
    [n_a n_b n_c n_d + ratio (delta_ac n_b n_d - n_a n_b n_c n_d)] (sym in ab), so
    k_ab = (1 - ratio) S_ab (a != b) and the row sums F_a = sum_c k_ac = (1/V) sum kn
    |d|^2 n_a^2, with S_ab = (1/V) sum kn |d|^2 n_a^2 n_b^2. The normal block is k
    itself, d sigma_aa = sum_b k_ab e_bb; the shear moduli come from the same sums,
    d sigma_ab = 2 G_ab e_ab, G_ab = k_ab + ratio (F_a + F_b) / 4 (a != b): the normal
    springs' C_abab = C_aabb (central forces obey Cauchy's relations). The fabric's mixed
    moments (n_a^3 n_b, ...) are not stored and are left out: exact for fabrics whose
    principal axes are the cell's, an approximation otherwise. k's diagonal also holds
    the bound on the forces' turning (kernel.contact_pass), pressure-sized against
    kn-sized moduli, which only stiffens the prediction."""
    f = np.empty(3)
    for a in range(3):
        f[a] = k[a, 0] + k[a, 1] + k[a, 2]
    for a in range(3):
        out[a, a] = k[a, 0] * e[0, 0] + k[a, 1] * e[1, 1] + k[a, 2] * e[2, 2]
        for b in range(a + 1, 3):
            out[a, b] = 2.0 * (k[a, b] + 0.25 * ratio * (f[a] + f[b])) * e[a, b]
            out[b, a] = out[a, b]


@numba.njit(cache=True)
def affine_tangent(moduli, ratio, strain):
    """(k,3,3) C_aff : strain [Pa] of k RVEs (`_affine_tangent`); moduli (k,3,3) the
    stored C_aabb [Pa], ratio = kt/kn, strain (k,3,3) symmetric."""
    out = np.empty_like(strain)
    for r in range(strain.shape[0]):
        _affine_tangent(moduli[r], ratio, strain[r], out[r])
    return out


@numba.njit(cache=True)
def polar_rotation(f, rot):
    """rot = R of f = R U (det f > 0) by Newton's iteration R <- (R + R^-T) / 2 from f,
    which converges quadratically; a waiting RVE's f is within the tolerance of a
    rotation, so two or three iterations reach round-off (the iteration stops one step
    after a change below 1e-10)."""
    rot[:, :] = f
    inv = np.empty((3, 3))
    close = False
    for _ in range(60):
        inv3(rot, inv)
        change = 0.0
        for a in range(3):
            for b in range(3):
                new = 0.5 * (rot[a, b] + inv[b, a])
                change = max(change, abs(new - rot[a, b]))
                rot[a, b] = new
        if close:  # one step after a change of 1e-10 the next is ~1e-20: round-off
            break
        close = change <= 1e-10


@numba.njit(cache=True)
def predicted_stress(stress, moduli, h_acc, ratio):
    """(k,3,3) R [sym(stress) + C_aff : (U - I)] R^T [Pa] of k waiting RVEs: stress
    (k,3,3) of their last update [Pa], moduli (k,3,3) its C_aabb [Pa], h_acc (k,3,3) the
    composed increments since, I + h_acc = R U; ratio = kt/kn."""
    out = np.empty_like(stress)
    f = np.empty((3, 3))
    rot = np.empty((3, 3))
    e = np.empty((3, 3))
    ds = np.empty((3, 3))
    s = np.empty((3, 3))
    for r in range(stress.shape[0]):
        for a in range(3):
            for b in range(3):
                f[a, b] = h_acc[r, a, b] + (1.0 if a == b else 0.0)
        polar_rotation(f, rot)
        # U - I = R^T f - I, symmetrised against round-off
        for a in range(3):
            for b in range(3):
                u_ab = 0.0
                u_ba = 0.0
                for c in range(3):
                    u_ab += rot[c, a] * f[c, b]
                    u_ba += rot[c, b] * f[c, a]
                e[a, b] = 0.5 * (u_ab + u_ba) - (1.0 if a == b else 0.0)
        _affine_tangent(moduli[r], ratio, e, ds)
        for a in range(3):
            for b in range(3):
                s[a, b] = 0.5 * (stress[r, a, b] + stress[r, b, a]) + ds[a, b]
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for c in range(3):
                    for d in range(3):
                        acc += rot[a, c] * s[c, d] * rot[b, d]
                out[r, a, b] = acc
    return out

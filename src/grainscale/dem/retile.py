"""Doubling a periodic cell that has become too thin: the same system, twice the grains.

A cell stretched in one direction (the flowing front of a column, an extension zone)
becomes thin across its other faces. Lattice reduction (lattice.py) cannot help: a
stretch is not a shear. A periodic assembly is unchanged, though, if its cell is taken
twice as long along one edge with the grains repeated once: h' = h with edge k doubled,
every grain i present as i (copy 0) and i + N (copy 1, shifted by the old edge a_k).
Positions, velocities, spins, forces and the Love-Weber stress (a sum over twice the
contacts in twice the volume) are those of the original at that instant, and every
contact keeps its tangential history; from then on the two copies may decorrelate,
which is the point: the cell is now twice as wide across the faces that edge k spans.

The width across the faces spanned by edges i and j is w_k = det h / |a_i x a_j|.
Doubling edge k doubles det h, hence w_k, and leaves the other two widths (their face
areas double too): the edge to double is k = argmin w.
"""

from __future__ import annotations

import numpy as np

from grainscale.dem.cell import perpendicular_widths_batch
from grainscale.dem.neighbours import INVALID_SHIFT, decode_shifts, encode_shifts
from grainscale.dem.state import RVEBatch, allocate, grow_capacity


def widths(h: np.ndarray) -> np.ndarray:
    """(R,3) perpendicular widths of a batch of cells [m] (cell.perpendicular_widths)."""
    return perpendicular_widths_batch(np.ascontiguousarray(h))


def double_cell(b: RVEBatch, r: int, k: int) -> RVEBatch:
    """RVE r of batch b with its cell doubled along edge k (multiply_cell with m = 2)."""
    return multiply_cell(b, r, k, 2)


def multiply_cell(b: RVEBatch, r: int, k: int, m: int) -> RVEBatch:
    """RVE r of batch b with its cell taken m times along edge k: a one-RVE batch of mN
    grains (the same periodic system, every contact with its tangential history).

    Fractional coordinates along k are divided by m (copy c adds c/m); a neighbour entry
    (i, j, image t) becomes, for each copy c of i, the pair (i + cN, j + c'N) with
    c' = (c + t_k) mod m and new image t'_k = floor((c + t_k) / m), other components
    unchanged; it is stored in the row of the smaller index (with the image and the
    history negated when the pair is reversed: the tangential force on i and the rolling
    moment on j are each the opposite of the other grain's). The rebuild before the next
    step matches these entries by partner and image, so every contact keeps its history.
    """
    n = b.n_particles
    nb = b.bm.shape[1]  # clumps (0: plain spheres)
    out = allocate(1, m * n, b.capacity, b.ft.shape[3], m * nb)  # grown if a row is longer
    scale = np.ones(3)
    scale[k] = m
    out.h[0] = b.h[r] * scale[None, :]
    out.h0[0] = b.h0[r] * scale[None, :]
    out.h_ref[0] = out.h[0]
    copies = []
    for c in range(m):
        s = b.s[r].copy()
        s[:, k] = (s[:, k] + c) / m
        copies.append(s)
    out.s[0] = np.concatenate(copies)
    out.s_ref[0] = out.s[0]
    for name in ("v", "w", "rot", "radius", "mass", "inertia", "force", "torque"):
        getattr(out, name)[0] = np.concatenate([getattr(b, name)[r]] * m)
    for name in ("L", "stress", "stress_servo", "stiffness", "step_count", "unbalanced"):
        getattr(out, name)[0] = getattr(b, name)[r]
    if nb:
        _multiply_clumps(b, r, k, m, out)
    out.ncontact[0] = m * b.ncontact[r]
    out.kinetic[0] = m * b.kinetic[r]
    out.need_rebuild[0] = 1

    cnt = b.nbr_count[r]
    rows, slots = np.nonzero(np.arange(b.capacity)[None, :] < cnt[:, None])
    codes = b.nbr_shift[r][rows, slots]
    keep = codes != INVALID_SHIFT  # entries already marked for removal stay removed
    rows, slots = rows[keep], slots[keep]
    j = b.nbr_j[r][rows, slots].astype(np.int64)
    t = decode_shifts(b.nbr_shift[r][rows, slots])
    ft = b.ft[r][rows, slots]
    pair_a, pair_b, shifts, forces = [], [], [], []
    for c in range(m):
        ck = c + t[:, k]
        tn = t.copy()
        tn[:, k] = np.floor_divide(ck, m)
        pair_a.append(rows + c * n)
        pair_b.append(j + np.mod(ck, m) * n)
        shifts.append(tn)
        forces.append(ft)
    a = np.concatenate(pair_a)
    bb = np.concatenate(pair_b)
    t = np.concatenate(shifts)
    f = np.concatenate(forces)
    swap = bb < a
    a, bb = np.where(swap, bb, a), np.where(swap, a, bb)
    t[swap] *= -1
    f[swap] *= -1
    order = np.lexsort((bb, a))
    a, bb, t, f = a[order], bb[order], t[order], f[order]
    counts = np.bincount(a, minlength=m * n)
    if counts.max(initial=0) > out.capacity:
        out = grow_capacity(out, int(counts.max()))
    slot = np.arange(len(a)) - np.repeat(np.cumsum(counts) - counts, counts)
    out.nbr_j[0][a, slot] = bb
    out.nbr_shift[0][a, slot] = encode_shifts(t)
    out.ft[0][a, slot] = f
    out.nbr_count[0] = counts
    return out


def _multiply_clumps(b: RVEBatch, r: int, k: int, m: int, out: RVEBatch) -> None:
    """The clumps of RVE r of b in the cell taken m times along edge k (multiply_cell):
    body B_b of copy c is b + cB, its centre (S + c e_k)/m, everything else as the
    original's. A member sits on the periodic image `image` of its body (s_i = S_b +
    h^-1 R rho_i + image_i, rigid.py), so copy c of member i belongs to the body copy
    c_b = (c + image_k) mod m with image_k' = floor((c + image_k) / m): the same
    bookkeeping as the neighbour pairs' images, which keeps s_i' = S_b' + h'^-1 R rho_i +
    image_i' exact (h'^-1 has row k divided by m)."""
    n, nb = b.n_particles, b.bm.shape[1]
    for name in ("bv", "bw", "bq", "bl", "bm", "bj", "bvol"):
        getattr(out, name)[0] = np.concatenate([getattr(b, name)[r]] * m)
    out.bs[0] = np.concatenate([b.bs[r] + c * np.eye(3)[k] for c in range(m)])
    out.bs[0, :, k] /= m
    out.rho[0] = np.concatenate([b.rho[r]] * m)
    out.off[0] = np.concatenate([b.off[r]] * m)
    img = np.rint(b.image[r]).astype(np.int64)
    for c in range(m):
        ck = c + img[:, k]
        out.body[0, c * n:(c + 1) * n] = b.body[r] + np.mod(ck, m) * nb
        image = img.copy()
        image[:, k] = np.floor_divide(ck, m)
        out.image[0, c * n:(c + 1) * n] = image

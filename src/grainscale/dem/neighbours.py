"""Verlet half neighbour lists for a periodic, possibly sheared cell.

A pair (i, j) is listed when |d| < r_i + r_j + skin, its own cutoff: with radii spread
over a factor of 2 or more, the common cutoff 2 r_max + skin would list about twice as
many pairs that cannot touch (6.6 against 3.5 entries per particle in the column's
300-sphere RVE), each of which the contact pass reads every step (docs/performance.md).
Built from a cell list in fractional coordinates: bins are cut along each cell axis so
that a bin's perpendicular width is at least the largest cutoff 2 r_max + skin, so every
listed pair lies in the 27 bins around a particle, and the bin offset fixes the image
shift. Lists are rebuilt when a pair could have moved by more than the skin (`kernel.py`
tracks that; its bound holds for each pair's cutoff, see there); rebuilding wraps
positions back into the cell and carries each contact's tangential history over to its
new list slot.

Status codes returned by `build`: 0 ok, 1 capacity overflow (nothing was modified; the
driver regrows the capacity and retries), 2 cell thinner than twice the largest cutoff
2 r_max + skin, 3 a position not finite (nothing was modified: a NaN would give a bin
index outside the cell list).
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import njit

from grainscale.dem.cell import perpendicular_widths

SHIFT_ZERO = 13  # code of the image shift (0, 0, 0)
INVALID_SHIFT = 255  # an entry awaiting removal by the next build (never matched)


class Status(IntEnum):
    """Outcome of a list build or a kernel call, per RVE (stored in int64 arrays)."""

    OK = 0
    OVERFLOW = 1  # a neighbour list needs more capacity; the caller regrows and redoes
    TOO_THIN = 2  # a perpendicular cell width is below 2 (2 r_max + skin)
    NOT_FINITE = 3  # a non-finite position (NaN or infinite fractional coordinate)


@njit(cache=True, inline="always")
def shift_code(a: int, b: int, c: int) -> int:
    """Image shift (a, b, c) in {-1, 0, 1}^3 as a number 0..26."""
    return (a + 1) * 9 + (b + 1) * 3 + (c + 1)


def decode_shifts(codes: np.ndarray) -> np.ndarray:
    """Image shift codes (M,) as integer shifts (M, 3) in {-1, 0, 1}^3."""
    c = codes.astype(np.int64)
    return np.stack([c // 9 - 1, (c // 3) % 3 - 1, c % 3 - 1], axis=-1)


def encode_shifts(k: np.ndarray) -> np.ndarray:
    """Integer shifts (M, 3) in {-1, 0, 1}^3 as codes (M,), as `shift_code` does."""
    return (k[:, 0] + 1) * 9 + (k[:, 1] + 1) * 3 + (k[:, 2] + 1)


@njit(cache=True)
def image_table(h: np.ndarray, table: np.ndarray) -> None:
    """table[code] = h @ shift: the Cartesian offset of each of the 27 images [m]."""
    for a in range(-1, 2):
        for b in range(-1, 2):
            for c in range(-1, 2):
                k = shift_code(a, b, c)
                for d in range(3):
                    table[k, d] = h[d, 0] * a + h[d, 1] * b + h[d, 2] * c


@njit(cache=True)
def _bins_per_axis(widths: np.ndarray, cutoff: float, n: int) -> np.ndarray:
    nb = np.empty(3, np.int64)
    for k in range(3):
        nb[k] = max(1, int(widths[k] / cutoff))
    while nb[0] * nb[1] * nb[2] > max(n, 1):  # at most one bin per particle on average
        k = np.argmax(nb)
        nb[k] -= 1
    return nb


@njit(cache=True)
def build(h, s, radius, nbr_j, nbr_shift, nbr_count, ft, s_ref, h_ref, link, wrapv, sw,
          skin):
    """Rebuild the half list of one RVE; returns (status, largest row length needed).

    `sw` is scratch (N,3) that receives the wrapped positions; `link` scratch (2N+1).
    On success s is wrapped into [0,1), s_ref/h_ref record the build configuration and
    every surviving pair keeps its contact history (all of ft's components).
    """
    n = s.shape[0]
    cap = nbr_j.shape[1]
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, radius[i])
    cutoff = 2.0 * rmax + skin
    widths = perpendicular_widths(h)
    if widths.min() < 2.0 * cutoff:
        return Status.TOO_THIN, 0
    nb = _bins_per_axis(widths, cutoff, n)
    nbins = nb[0] * nb[1] * nb[2]
    head = link[:nbins]
    nxt = link[n + 1:2 * n + 1]
    head[:] = -1
    for i in range(n):
        for k in range(3):
            f = math.floor(s[i, k])
            x = s[i, k] - f
            if x >= 1.0:  # s slightly below an integer rounds to exactly 1.0
                x -= 1.0
                f += 1
            if not (x >= 0.0 and x < 1.0):  # NaN or infinite s (inf - inf is NaN)
                return Status.NOT_FINITE, 0
            wrapv[i, k] = int(f)
            sw[i, k] = x
        b0 = min(int(sw[i, 0] * nb[0]), nb[0] - 1)
        b1 = min(int(sw[i, 1] * nb[1]), nb[1] - 1)
        b2 = min(int(sw[i, 2] * nb[2]), nb[2] - 1)
        b = (b0 * nb[1] + b1) * nb[2] + b2
        nxt[i] = head[b]
        head[b] = i

    # pass 1: count only, so that an overflow leaves the state untouched
    need = 0
    for i in range(n):
        c = _scan(i, h, sw, radius, skin, nb, head, nxt, nbr_j, nbr_shift, False)
        need = max(need, c)
    if need > cap:
        return Status.OVERFLOW, need

    # pass 2: write rows, carrying the history over (matched by j and image)
    hw = ft.shape[2]
    old_j = np.empty(cap, np.int64)
    old_code = np.empty(cap, np.int64)
    old_ft = np.empty((cap, hw))
    for i in range(n):
        m = nbr_count[i]
        for k in range(m):
            j = nbr_j[i, k]
            code = nbr_shift[i, k]
            a = code // 9 - 1 + wrapv[j, 0] - wrapv[i, 0]
            b = (code // 3) % 3 - 1 + wrapv[j, 1] - wrapv[i, 1]
            c = code % 3 - 1 + wrapv[j, 2] - wrapv[i, 2]
            old_j[k] = j
            old_code[k] = shift_code(a, b, c) if (abs(a) <= 1 and abs(b) <= 1
                                                 and abs(c) <= 1) else -1
            for c in range(hw):
                old_ft[k, c] = ft[i, k, c]
        cnew = _scan(i, h, sw, radius, skin, nb, head, nxt, nbr_j, nbr_shift, True)
        nbr_count[i] = cnew
        for k in range(cnew):
            j = nbr_j[i, k]
            code = nbr_shift[i, k]
            for c in range(hw):
                ft[i, k, c] = 0.0
            for q in range(m):
                if old_j[q] == j and old_code[q] == code:
                    for c in range(hw):
                        ft[i, k, c] = old_ft[q, c]
                    break
        for k in range(cnew, m):  # slots out of use hold zeros: a checkpoint that cuts
            for c in range(hw):   # them off restores the same arrays
                ft[i, k, c] = 0.0
    for i in range(n):
        for k in range(3):
            s[i, k] = sw[i, k]
            s_ref[i, k] = sw[i, k]
    for a in range(3):
        for b in range(3):
            h_ref[a, b] = h[a, b]
    return Status.OK, need


@njit(cache=True)
def _scan(i, h, sw, radius, skin, nb, head, nxt, nbr_j, nbr_shift, write):
    """Visit the 27 bins around particle i; count (and optionally write) the pairs j > i
    closer than r_i + r_j + skin."""
    b0 = min(int(sw[i, 0] * nb[0]), nb[0] - 1)
    b1 = min(int(sw[i, 1] * nb[1]), nb[1] - 1)
    b2 = min(int(sw[i, 2] * nb[2]), nb[2] - 1)
    count = 0
    for o0 in range(-1, 2):
        t0 = b0 + o0
        sh0 = -1 if t0 < 0 else (1 if t0 >= nb[0] else 0)
        t0 -= sh0 * nb[0]
        for o1 in range(-1, 2):
            t1 = b1 + o1
            sh1 = -1 if t1 < 0 else (1 if t1 >= nb[1] else 0)
            t1 -= sh1 * nb[1]
            for o2 in range(-1, 2):
                t2 = b2 + o2
                sh2 = -1 if t2 < 0 else (1 if t2 >= nb[2] else 0)
                t2 -= sh2 * nb[2]
                j = head[(t0 * nb[1] + t1) * nb[2] + t2]
                while j >= 0:
                    if j > i:
                        f0 = sw[j, 0] + sh0 - sw[i, 0]
                        f1 = sw[j, 1] + sh1 - sw[i, 1]
                        f2 = sw[j, 2] + sh2 - sw[i, 2]
                        d0 = h[0, 0] * f0 + h[0, 1] * f1 + h[0, 2] * f2
                        d1 = h[1, 0] * f0 + h[1, 1] * f1 + h[1, 2] * f2
                        d2 = h[2, 0] * f0 + h[2, 1] * f1 + h[2, 2] * f2
                        c = radius[i] + radius[j] + skin
                        if d0 * d0 + d1 * d1 + d2 * d2 < c * c:
                            if write:
                                nbr_j[i, count] = j
                                nbr_shift[i, count] = shift_code(sh0, sh1, sh2)
                            count += 1
                    j = nxt[j]
    return count

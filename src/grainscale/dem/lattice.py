"""Re-expressing distorted periodic cells by a compact basis (lattice reduction).

A cell sheared far becomes a thin parallelepiped: its perpendicular widths shrink until
the neighbour search must refuse it. The seed re-initialises such RVEs and loses their
history (seed §5). But the periodic system only depends on the lattice {h k : k integer},
and the same lattice has many bases: h' = h M with M integer and det M = 1. Choosing a
short, nearly orthogonal basis (Lagrange-Gauss reduction, as YADE's cell flipping does)
leaves every particle, contact and force unchanged; only the bookkeeping moves:
fractional coordinates become s' = M^-1 s, and each neighbour entry's image shift
k becomes M^-1 k plus the wrap of its two particles.
"""

from __future__ import annotations

import numpy as np

from grainscale.dem.cell import lattice_reduce
from grainscale.dem.neighbours import INVALID_SHIFT, decode_shifts, encode_shifts
from grainscale.dem.state import RVEBatch


def needs_reduction(h: np.ndarray, tol: float = 0.5 + 1e-9) -> np.ndarray:
    """(R,) bool: some edge could be shortened by an integer multiple of another.

    The Lagrange condition |a_i . a_j| <= 1/2 |a_j|^2 for all i != j holds for a reduced
    basis; `tol` above 1/2 avoids flipping back and forth at the boundary.
    """
    g = np.einsum("rai,raj->rij", h, h)  # Gram matrix of the edge vectors
    diag = np.diagonal(g, axis1=1, axis2=2)
    off = np.abs(g) / diag[:, None, :]  # |a_i . a_j| / |a_j|^2
    off[:, np.arange(3), np.arange(3)] = 0.0
    return np.any(off > tol, axis=(1, 2))


REDUCE_TOL = 0.75  # reduce_cells' default: a cell is re-expressed beyond this


def reduce_cells(batch: RVEBatch, tol: float = REDUCE_TOL) -> np.ndarray:
    """Re-express every cell that fails the Lagrange condition by `tol`; returns their ids.

    Positions are wrapped into the new cell, list shifts transformed, and a list rebuild
    flagged (history is carried over by the build). Physically nothing changes.
    """
    todo = np.flatnonzero(needs_reduction(batch.h, tol))
    for r in todo:
        h_new, m = lattice_reduce(batch.h[r])
        m_inv = np.rint(np.linalg.inv(m)).astype(np.int64)
        s = batch.s[r] @ m_inv.T
        wrap = np.floor(s)
        batch.s[r] = s - wrap
        batch.h[r] = h_new
        batch.h_ref[r] = h_new
        batch.s_ref[r] = batch.s[r]
        cnt = batch.nbr_count[r]
        rows, slots = np.nonzero(np.arange(batch.capacity)[None, :] < cnt[:, None])
        j = batch.nbr_j[r][rows, slots]
        k = decode_shifts(batch.nbr_shift[r][rows, slots]) @ m_inv.T
        k += (wrap[j] - wrap[rows]).astype(np.int64)
        ok = np.all(np.abs(k) <= 1, axis=1)
        # an image beyond the nearest ones cannot be within the cutoff of a reduced
        # cell: such entries get the invalid code, which the forced rebuild never matches
        codes = np.full(len(rows), INVALID_SHIFT, np.int64)
        codes[ok] = encode_shifts(k[ok])
        batch.nbr_shift[r][rows, slots] = codes.astype(np.uint8)
        batch.need_rebuild[r] = 1
    return todo

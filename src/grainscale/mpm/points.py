"""Material points: the Lagrangian carriers of mass, momentum and material state.

Points are created by filling a box or a cylinder with n x n x n points per grid cell
(each at the centre of its sub-cell, volume (h/n)^3), or read from a text file with one
point per line `x y z volume`. Arrays are structure-of-arrays, C-contiguous float64
(material id int64), so that every numba kernel sees a single signature.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from grainscale.mpm.grid import Grid


@dataclass
class Points:
    x: np.ndarray  # (P,3) m, position
    x0: np.ndarray  # (P,3) m, initial position (for the displacement field)
    v: np.ndarray  # (P,3) m/s, velocity
    C: np.ndarray  # (P,3,3) 1/s, affine velocity of APIC, C[a, b] = d v_a / d x_b near x_p
    m: np.ndarray  # (P,) kg, mass (constant: seed Eq. 1 holds point by point)
    vol0: np.ndarray  # (P,) m^3, initial volume
    vol: np.ndarray  # (P,) m^3, current volume = det(F) vol0
    F: np.ndarray  # (P,3,3) deformation gradient, F[a, b] = d x_a / d X_b
    stress: np.ndarray  # (P,3,3) Pa, Cauchy stress, tension positive
    lp: np.ndarray  # (P,3) m, GIMP half-width per axis (constant: "undeformed" uGIMP)
    mat: np.ndarray  # (P,) int64, material index

    @property
    def n(self) -> int:
        return self.x.shape[0]

    def arrays(self) -> dict[str, np.ndarray]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def make_points(x: np.ndarray, vol: np.ndarray, density: float, mat: int,
                velocity=(0.0, 0.0, 0.0), lp: np.ndarray | None = None) -> Points:
    """Points at x (P,3) with volumes vol (P,). Half-widths lp: one value, one per point
    (P,) (a cube) or one per point and axis (P,3) (a box, as a sub-cell of a graded
    grid); default half the cube root of vol."""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    P = x.shape[0]
    vol = np.ascontiguousarray(np.broadcast_to(vol, (P,)), dtype=np.float64).copy()
    if lp is None:
        lp = 0.5 * np.cbrt(vol)
    return Points(
        x=x.copy(), x0=x.copy(),
        v=np.tile(np.asarray(velocity, dtype=np.float64), (P, 1)), C=np.zeros((P, 3, 3)),
        m=density * vol, vol0=vol.copy(), vol=vol.copy(),
        F=np.tile(np.eye(3), (P, 1, 1)), stress=np.zeros((P, 3, 3)),
        lp=half_widths(lp, P),
        mat=np.full(P, mat, dtype=np.int64),
    )


def half_widths(lp, P: int) -> np.ndarray:
    """lp as (P,3) half-widths [m]: a scalar or (P,) is the same on every axis."""
    lp = np.asarray(lp, dtype=np.float64)
    if lp.ndim < 2:
        lp = np.broadcast_to(lp.reshape(-1, 1) if lp.ndim == 1 else lp, (P, 3))
    if lp.shape != (P, 3):
        raise ValueError(f"lp: shape {lp.shape}; valid: (), ({P},) or ({P}, 3)")
    return np.ascontiguousarray(lp).copy()


def half_extent(lp: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Half-extent [m] of box domains lp (P,3) along unit normals n (3,) or (P,3): the
    support function sqrt(sum_a (lp_a n_a)^2) of the inscribed ellipsoid, which is lp
    itself for a cube (taken as is, so that cubic domains give the same digits as a
    scalar half-width)."""
    lp = np.asarray(lp)
    cube = (lp[:, 0] == lp[:, 1]) & (lp[:, 1] == lp[:, 2])
    return np.where(cube, lp[:, 0], np.sqrt(((lp * n) ** 2).sum(axis=1)))


def concatenate(sets: list[Points]) -> Points:
    """One point set from several, in order."""
    return Points(**{f.name: np.ascontiguousarray(
        np.concatenate([getattr(s, f.name) for s in sets])) for f in fields(Points)})


def take(pts: Points, ids: np.ndarray) -> Points:
    """The points ids (in that order), as a new contiguous point set."""
    return Points(**{f.name: np.ascontiguousarray(getattr(pts, f.name)[ids])
                     for f in fields(Points)})


def _lattice(grid: Grid, lo, hi, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Sub-cell centres (n per cell and axis) of all grid cells overlapping the box
    [lo, hi], and the volume of each sub-cell (its cell's volume / n^3)."""
    if grid.axes is not None:
        return _lattice_rectilinear(grid, lo, hi, n)
    h = grid.cell_size
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    c0 = np.maximum(np.floor((lo - grid.origin) / h).astype(np.int64), 0)
    c1 = np.minimum(np.ceil((hi - grid.origin) / h).astype(np.int64), grid.cells)
    axes = []
    for a in range(3):
        k = np.arange(c0[a] * n, c1[a] * n)
        axes.append(grid.origin[a] + (k + 0.5) * h[a] / n)
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    x = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    return x, np.full(x.shape[0], np.prod(grid.cell_size / n))


def _lattice_rectilinear(grid: Grid, lo, hi, n: int) -> tuple[np.ndarray, np.ndarray]:
    """_lattice on a rectilinear grid: n sub-cells per local cell and axis."""
    centres, widths = [], []
    for a in range(3):
        X = grid.axes[a]
        c0 = max(int(np.searchsorted(X, lo[a], side="right")) - 1, 0)
        c1 = min(int(np.searchsorted(X, hi[a], side="left")), len(X) - 1)
        h = np.repeat(np.diff(X[c0:c1 + 1]), n) / n
        start = np.repeat(X[c0:c1], n)
        k = np.tile(np.arange(n), c1 - c0)
        centres.append(start + (k + 0.5) * h)
        widths.append(h)
    C = np.meshgrid(*centres, indexing="ij")
    W = np.meshgrid(*widths, indexing="ij")
    x = np.stack([c.ravel() for c in C], axis=1)
    return x, (W[0] * W[1] * W[2]).ravel()


def sub_cell_half_widths(grid: Grid, x: np.ndarray, n: int) -> np.ndarray:
    """(P,3) half-widths [m] of the sub-cells (n per cell and axis, as fill_box makes)
    centred at x (P,3): half the size of the local cell over n, per axis. On a graded
    grid a sub-cell is a box, not a cube, and GIMP needs its own extent on each axis (an
    isotropic 0.5 V^(1/3) overlaps its neighbours along the fine axis)."""
    x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
    if grid.axes is None:
        return np.tile(0.5 * grid.cell_size / n, (x.shape[0], 1))
    return 0.5 * grid.cell_sizes_at(x) / n


def fill_box(grid: Grid, lo, hi, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions (P,3) and volumes (P,) of the n^3-per-cell points whose centres lie in [lo, hi]."""
    x, vol = _lattice(grid, lo, hi, n)
    inside = np.all((x >= np.asarray(lo)) & (x <= np.asarray(hi)), axis=1)
    return x[inside], vol[inside]


def fill_cylinder(grid: Grid, center, radius: float, height: float, axis: int,
                  n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points in the cylinder of the given radius whose base centre is `center` and which
    extends `height` along +axis (axis 0, 1 or 2)."""
    center = np.asarray(center, dtype=np.float64)
    lo = center - radius
    hi = center + radius
    lo[axis] = center[axis]
    hi[axis] = center[axis] + height
    x, vol = _lattice(grid, lo, hi, n)
    d = x - center
    d[:, axis] = 0.0
    inside = (np.einsum("ij,ij->i", d, d) <= radius**2) & (x[:, axis] >= lo[axis]) & (
        x[:, axis] <= hi[axis])
    return x[inside], vol[inside]


def read_points(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Points from a text file: one `x y z volume` per line (SI), '#' comments allowed."""
    data = np.loadtxt(path, comments="#", ndmin=2)
    if data.shape[1] != 4:
        raise ValueError(f"{path}: expected 4 columns 'x y z volume', got {data.shape[1]}")
    if np.any(data[:, 3] <= 0):
        raise ValueError(f"{path}: point volumes must be > 0")
    return data[:, :3].copy(), data[:, 3].copy()

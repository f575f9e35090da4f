"""Clump templates: rigid grains made of overlapping spheres, and their mass properties.

A template holds its member spheres in the clump's principal frame: offsets rho_k [m]
from the centre of mass along the principal axes of inertia, radii r_k [m], and the
clump's solid volume V [m^3] and principal moments per unit density J_a [m^5] (the
inertia of a grain of density rho is rho J_a). Members overlap, so V and J are those of
the union of the spheres, not sums over the members: they are integrated on a voxel grid
(`mass_properties`), the midpoint rule on cells of RESOLUTION per smallest radius, which
leaves ~1e-3 of the volume and inertia (tests/dem/test_clump.py against a single sphere
and the lens of two overlapping ones).

Named templates (`template`):
- "sphere": one sphere of radius 1 (the spheres' law, a check of the clump path);
- "elongated": `spheres` equal spheres on a line, centres spaced so that the clump's
  length over its width is `aspect` (>= 1): spacing 2 r (aspect - 1)/(spheres - 1);
- "tetrahedral": four equal spheres on the vertices of a regular tetrahedron whose edge
  is `overlap_edge` radii (default 1.6, overlapping): a compact, angular grain.
A template is scaled to a grain by `scaled(template, size)`: every length times `size`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

RESOLUTION = 48  # voxel cells per smallest member radius in mass_properties


class Template(NamedTuple):
    """A rigid clump of spheres in its principal frame (module docstring)."""

    name: str
    offsets: np.ndarray   # (k,3) member centres from the centre of mass, principal axes [m]
    radii: np.ndarray     # (k,) [m]
    volume: float         # solid volume of the union [m^3]
    inertia: np.ndarray   # (3,) principal moments per unit density [m^5], ascending


@njit(cache=True)
def _voxel_moments(centres, radii, lo, h, n0, n1, n2):
    """Volume, first and second moments of the union of spheres by the midpoint rule on
    n0 x n1 x n2 cells of side h from corner lo: (V, sum x dV (3,), sum x x^T dV (3,3))."""
    vol = 0.0
    first = np.zeros(3)
    second = np.zeros((3, 3))
    dv = h * h * h
    r2 = radii * radii
    p = np.empty(3)
    for i in range(n0):
        p[0] = lo[0] + (i + 0.5) * h
        for j in range(n1):
            p[1] = lo[1] + (j + 0.5) * h
            for k in range(n2):
                p[2] = lo[2] + (k + 0.5) * h
                inside = False
                for m in range(radii.shape[0]):
                    d0 = p[0] - centres[m, 0]
                    d1 = p[1] - centres[m, 1]
                    d2 = p[2] - centres[m, 2]
                    if d0 * d0 + d1 * d1 + d2 * d2 <= r2[m]:
                        inside = True
                        break
                if not inside:
                    continue
                vol += dv
                for a in range(3):
                    first[a] += p[a] * dv
                    for b in range(3):
                        second[a, b] += p[a] * p[b] * dv
    return vol, first, second


def mass_properties(centres, radii, resolution: int = RESOLUTION
                    ) -> tuple[float, np.ndarray, np.ndarray]:
    """(V [m^3], centre of mass (3,) [m], inertia tensor per unit density about it
    (3,3) [m^5]) of the union of spheres (centres (k,3) [m], radii (k,) [m]): I_ab =
    integral (|x|^2 delta_ab - x_a x_b) dV over the union, by `_voxel_moments` on cells
    of min(radii) / resolution."""
    centres = np.asarray(centres, float).reshape(-1, 3)
    radii = np.asarray(radii, float).ravel()
    if radii.size == 0 or np.any(radii <= 0):
        raise ValueError(f"clump radii {radii.tolist()}: need at least one, each > 0")
    h = radii.min() / resolution
    lo = (centres - radii[:, None]).min(axis=0)
    hi = (centres + radii[:, None]).max(axis=0)
    n = np.ceil((hi - lo) / h).astype(np.int64)
    vol, first, second = _voxel_moments(centres, radii, lo, h, int(n[0]), int(n[1]),
                                        int(n[2]))
    com = first / vol
    second_c = second - vol * np.outer(com, com)  # about the centre of mass
    tensor = np.trace(second_c) * np.eye(3) - second_c
    return vol, com, tensor


def principal(name: str, centres, radii, resolution: int = RESOLUTION) -> Template:
    """The Template of members at `centres` (any frame) with `radii`: offsets from the
    centre of mass along the principal axes (right-handed, moments ascending)."""
    vol, com, tensor = mass_properties(centres, radii, resolution)
    moments, axes = np.linalg.eigh(tensor)  # columns: principal axes
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1.0
    offsets = (np.asarray(centres, float).reshape(-1, 3) - com) @ axes
    return Template(name, offsets, np.asarray(radii, float).ravel().copy(), float(vol),
                    moments)


def from_members(centres, radii, resolution: int = RESOLUTION
                 ) -> tuple[Template, np.ndarray, np.ndarray]:
    """A clump given by its members' lab centres (k,3) [m] and radii: (its Template, its
    centre of mass (3,) [m], its orientation, the unit quaternion (4,) that turns the
    template's principal frame into the lab)."""
    vol, com, tensor = mass_properties(centres, radii, resolution)
    moments, axes = np.linalg.eigh(tensor)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1.0
    offsets = (np.asarray(centres, float).reshape(-1, 3) - com) @ axes
    t = Template("file", offsets, np.asarray(radii, float).ravel().copy(), float(vol),
                 moments)
    return t, com, quaternion_of(axes)


def quaternion_of(rot: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (Shepperd's method:
    from its largest of 1 + trace and the diagonal, for accuracy)."""
    m = np.asarray(rot, float)
    tr = np.trace(m)
    k = int(np.argmax([tr, m[0, 0], m[1, 1], m[2, 2]]))
    if k == 0:
        w = 0.5 * math.sqrt(1.0 + tr)
        q = [w, (m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w),
             (m[1, 0] - m[0, 1]) / (4 * w)]
    else:
        i = k - 1
        j, l = (i + 1) % 3, (i + 2) % 3
        s = 0.5 * math.sqrt(1.0 + m[i, i] - m[j, j] - m[l, l])
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (m[l, j] - m[j, l]) / (4 * s)
        q[1 + i] = s
        q[1 + j] = (m[j, i] + m[i, j]) / (4 * s)
        q[1 + l] = (m[l, i] + m[i, l]) / (4 * s)
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def template(name: str, aspect: float = 2.0, spheres: int = 2,
             overlap_edge: float = 1.6) -> Template:
    """A named template of unit member radius (module docstring); ValueError naming the
    parameter and its valid range otherwise."""
    if name == "sphere":
        return principal(name, np.zeros((1, 3)), np.ones(1))
    if name == "elongated":
        if not 1.0 < aspect <= 4.0:
            raise ValueError(f"aspect = {aspect!r}: valid range (1, 4] for 'elongated'")
        if not 2 <= spheres <= 8:
            raise ValueError(f"spheres = {spheres!r}: valid range 2-8 for 'elongated'")
        step = 2.0 * (aspect - 1.0) / (spheres - 1)
        if step >= 2.0:
            raise ValueError(f"aspect = {aspect!r} with spheres = {spheres}: members "
                             "would not overlap; more spheres or a smaller aspect")
        z = (np.arange(spheres) - 0.5 * (spheres - 1)) * step
        centres = np.column_stack([np.zeros(spheres), np.zeros(spheres), z])
        return principal(name, centres, np.ones(spheres))
    if name == "tetrahedral":
        if not 0.0 < overlap_edge < 2.0:
            raise ValueError(f"overlap_edge = {overlap_edge!r}: valid range (0, 2) radii "
                             "for 'tetrahedral' (members overlap)")
        v = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0],
                      [-1.0, -1.0, 1.0]])
        centres = v * overlap_edge / (2.0 * math.sqrt(2.0))  # edge |v_i - v_j| = 2 sqrt 2
        return principal(name, centres, np.ones(4))
    raise ValueError(f"clump template {name!r}: valid names 'sphere', 'elongated', "
                     "'tetrahedral'")


def scaled(t: Template, size: float) -> Template:
    """The template with every length times `size` (volume size^3, inertia size^5)."""
    return Template(t.name, t.offsets * size, t.radii * size, t.volume * size**3,
                    t.inertia * size**5)

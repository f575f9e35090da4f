"""ParaView snapshot of one RVE: spheres as points, the contact force network as lines.

`<stem>_spheres.vtu`: one vertex per sphere (Cartesian centre, wrapped into the cell)
with point data radius, mass, velocity (fluctuating), angular_velocity, rotation
(accumulated angle), and for clumps `clump`, the grain each sphere is a member of (its
mass and velocity are then the member's: the clump's mass, the velocity of its material
point). In ParaView: Glyph filter, glyph type Sphere, scale array
`radius`, scale factor 2 (the glyph source has radius 0.5).
`<stem>_contacts.vtu`: one line per contact from centre i to the image of centre j that
touches it (lines cross the cell boundary where contacts do), so a line's end minus its
start is the branch vector d = x_j - x_i; cell data normal_force, tangential_force and
force magnitude [N], and force_vector, the force on sphere i (at the line's start) [N]:
the Love-Weber stress of the contacts is (1/V) sum d (x) force_vector.
`<stem>_cell.vtu`: the parallelepiped of the periodic cell as a hexahedron, with cell
data stress (the batch's Love-Weber stress, 9 components row-major, tension positive
[Pa]), p, q [Pa] (compression positive) and porosity.

The contact forces are those of the stored configuration, as the kernel evaluates them
at the end of a call (dem/kernel.py, item 8): normal force kn overlap minus the dashpot
2 gamma sqrt(m* kn) v_n when `gamma` (engine.ContactParams.gamma) is given, and the
stored tangential force projected onto the contact plane and capped at friction
max(f_n, 0). They match `batch.stress` after engine.advance or engine.refresh. Each file
is written to a temporary name and renamed, so a crash never leaves half a file.
"""

from __future__ import annotations

import os
from pathlib import Path

import meshio
import numpy as np

from grainscale.dem.engine import ContactParams
from grainscale.dem.neighbours import image_table
from grainscale.dem.state import RVEBatch
from grainscale.stress import p_q


def contact_list(batch: RVEBatch, cp: ContactParams, r: int = 0):
    """(i, j, branch d [m], normal force [N], tangential force vector [N]) of contacts.

    The normal force is kn delta (linear) or (2/3) kn delta with kn = 2 E* sqrt(R* delta)
    (Hertz-Mindlin), minus the normal dashpot 2 gamma sqrt(m* kn) v_n (v_n > 0
    separating, the mean-field strain rate of batch.L included) when gamma > 0; the
    tangential force the stored history on the current contact plane, capped at friction
    max(f_n, 0): as the kernel evaluates them (dem/kernel.py, contact_pass)."""
    h = batch.h[r]
    x = batch.s[r] @ h.T
    table = np.empty((27, 3))
    image_table(h, table)
    rows_i, rows_k = np.nonzero(np.arange(batch.capacity)[None, :] < batch.nbr_count[r][:, None])
    j = batch.nbr_j[r][rows_i, rows_k]
    d = x[j] - x[rows_i] + table[batch.nbr_shift[r][rows_i, rows_k]]
    dist = np.linalg.norm(d, axis=1)
    ri, rj = batch.radius[r][rows_i], batch.radius[r][j]
    overlap = ri + rj - dist
    touch = overlap > 0
    if cp.hertz:
        kn = cp.hertz_kn * np.sqrt(ri * rj / (ri + rj) * np.maximum(overlap, 0.0))
        fn = (2.0 / 3.0) * kn * overlap
    else:
        kn = cp.young * 2.0 * ri * rj / (ri + rj)
        fn = kn * overlap
    n = d / np.where(dist > 0, dist, 1.0)[:, None]
    gamma = cp.gamma
    if gamma > 0.0:
        L = batch.L[r]
        vrel = batch.v[r][j] - batch.v[r][rows_i] + d @ (0.5 * (L + L.T))
        vn = np.einsum("ca,ca->c", vrel, n)
        mi, mj = batch.mass[r][rows_i], batch.mass[r][j]
        fn = fn - 2.0 * gamma * np.sqrt(mi * mj / (mi + mj) * kn) * vn
    ft = batch.ft[r][rows_i, rows_k, :3]
    n, fn, ft = n[touch], fn[touch], ft[touch]
    ft = ft - np.einsum("ca,ca->c", ft, n)[:, None] * n
    cap = cp.friction * np.maximum(fn, 0.0)
    norm = np.linalg.norm(ft, axis=1)
    over = norm > cap
    ft[over] *= (cap[over] / norm[over])[:, None]
    return rows_i[touch], j[touch], d[touch], fn, ft


def _write(mesh: meshio.Mesh, path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp.vtu")
    meshio.write(str(tmp), mesh, file_format="vtu", binary=True)
    os.replace(tmp, path)


def write_rve_vtk(stem: str | Path, batch: RVEBatch, cp: ContactParams,
                  r: int = 0) -> list[Path]:
    """Write the three snapshot files of RVE r, its contact forces by the contact law cp;
    returns their paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    h = batch.h[r]
    s = batch.s[r] - np.floor(batch.s[r])
    x = s @ h.T
    n = len(x)
    point_data = {"radius": batch.radius[r], "mass": batch.mass[r], "velocity": batch.v[r],
                  "angular_velocity": batch.w[r], "rotation": batch.rot[r]}
    if batch.clumped:  # colour by it to see the grains
        point_data["clump"] = batch.body[r].astype(np.int32)
    spheres = meshio.Mesh(x, [("vertex", np.arange(n).reshape(-1, 1))],
                          point_data=point_data)
    i, j, d, fn, ft = contact_list(batch, cp, r)
    start = x[i]
    pts = np.concatenate([start, start + d]) if len(i) else np.zeros((0, 3))
    lines = np.stack([np.arange(len(i)), np.arange(len(i)) + len(i)], axis=1)
    tmag = np.linalg.norm(ft, axis=1)
    normal = d / np.linalg.norm(d, axis=1)[:, None] if len(i) else np.zeros((0, 3))
    contacts = meshio.Mesh(
        pts, [("line", lines)],
        cell_data={"normal_force": [fn], "tangential_force": [tmag],
                   "force": [np.sqrt(fn**2 + tmag**2)],
                   "force_vector": [ft - fn[:, None] * normal]})
    corners = np.array([[a, b, c] for c in (0, 1) for b in (0, 1) for a in (0, 1)], float)
    corners = corners[[0, 1, 3, 2, 4, 5, 7, 6]] @ h.T
    p, q = p_q(batch.stress[r])
    cell = meshio.Mesh(corners, [("hexahedron", np.arange(8).reshape(1, 8))],
                       cell_data={"stress": [batch.stress[r].reshape(1, 9)],
                                  "p": [np.array([p])], "q": [np.array([q])],
                                  "porosity": [batch.porosity()[r:r + 1]]})
    paths = [stem.with_name(stem.name + suffix) for suffix in
             ("_spheres.vtu", "_contacts.vtu", "_cell.vtu")]
    for mesh, path in zip((spheres, contacts, cell), paths, strict=True):
        _write(mesh, path)
    return paths

"""ParaView snapshot of one RVE: spheres as points, the contact force network as lines.

`<stem>_spheres.vtu`: one vertex per sphere (Cartesian centre, wrapped into the cell)
with point data radius, velocity (fluctuating), angular_velocity, rotation (accumulated
angle). In ParaView: Glyph filter, glyph type Sphere, scale array `radius`, scale
factor 2 (the glyph source has radius 0.5).
`<stem>_contacts.vtu`: one line per contact from centre i to the image of centre j that
touches it (lines cross the cell boundary where contacts do), with cell data
normal_force, tangential_force and force magnitude [N].
`<stem>_cell.vtu`: the parallelepiped of the periodic cell as a hexahedron.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from grainscale.dem.neighbours import image_table
from grainscale.dem.state import RVEBatch


def contact_list(batch: RVEBatch, young: float, r: int = 0):
    """(i, j, branch d [m], normal force [N], tangential force vector [N]) of contacts."""
    h = batch.h[r]
    x = batch.s[r] @ h.T
    table = np.empty((27, 3))
    image_table(h, table)
    rows_i, rows_k = np.nonzero(np.arange(batch.capacity)[None, :] < batch.nbr_count[r][:, None])
    j = batch.nbr_j[r][rows_i, rows_k]
    d = x[j] - x[rows_i] + table[batch.nbr_shift[r][rows_i, rows_k]]
    dist = np.linalg.norm(d, axis=1)
    overlap = batch.radius[r][rows_i] + batch.radius[r][j] - dist
    touch = overlap > 0
    kn = young * 2.0 * batch.radius[r][rows_i] * batch.radius[r][j] / (
        batch.radius[r][rows_i] + batch.radius[r][j])
    ft = batch.ft[r][rows_i, rows_k]
    return rows_i[touch], j[touch], d[touch], (kn * overlap)[touch], ft[touch]


def write_rve_vtk(stem: str | Path, batch: RVEBatch, young: float, r: int = 0) -> list[Path]:
    """Write the three snapshot files of RVE r; returns their paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    h = batch.h[r]
    s = batch.s[r] - np.floor(batch.s[r])
    x = s @ h.T
    n = len(x)
    spheres = meshio.Mesh(
        x, [("vertex", np.arange(n).reshape(-1, 1))],
        point_data={"radius": batch.radius[r], "velocity": batch.v[r],
                    "angular_velocity": batch.w[r], "rotation": batch.rot[r]})
    i, j, d, fn, ft = contact_list(batch, young, r)
    start = x[i]
    pts = np.concatenate([start, start + d]) if len(i) else np.zeros((0, 3))
    lines = np.stack([np.arange(len(i)), np.arange(len(i)) + len(i)], axis=1)
    tmag = np.linalg.norm(ft, axis=1)
    contacts = meshio.Mesh(
        pts, [("line", lines)],
        cell_data={"normal_force": [fn], "tangential_force": [tmag],
                   "force": [np.sqrt(fn**2 + tmag**2)]})
    corners = np.array([[a, b, c] for c in (0, 1) for b in (0, 1) for a in (0, 1)], float)
    corners = corners[[0, 1, 3, 2, 4, 5, 7, 6]] @ h.T
    cell = meshio.Mesh(corners, [("hexahedron", np.arange(8).reshape(1, 8))])
    paths = [stem.with_name(stem.name + suffix) for suffix in
             ("_spheres.vtu", "_contacts.vtu", "_cell.vtu")]
    for mesh, path in zip((spheres, contacts, cell), paths, strict=True):
        meshio.write(str(path), mesh, binary=True)
    return paths

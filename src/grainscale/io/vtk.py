"""ParaView output: point clouds as VTK XML unstructured grids (.vtu) and .pvd series.

Generic: used for MPM material points and reusable for DEM spheres. Files are written to
a temporary name and moved into place, so a crash never leaves a half-written frame or a
broken series file.
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np

from grainscale.io import faults


def _atomic_replace(tmp: Path, path: Path) -> None:
    os.replace(tmp, path)


def write_points_vtu(path: str | Path, points: np.ndarray,
                     point_data: dict[str, np.ndarray]) -> None:
    """Write points (P,3) with per-point fields as vertex cells to a .vtu file.

    Fields may be (P,), (P,k) or (P,3,3) (tensors are flattened row-major to 9
    components, which ParaView shows as a tensor).
    """
    path = Path(path)
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    data = {}
    for k, v in point_data.items():
        a = np.asarray(v)
        if a.ndim == 3:
            a = a.reshape(a.shape[0], -1)
        if a.dtype == np.bool_:
            a = a.astype(np.uint8)
        data[k] = np.ascontiguousarray(a)
    cells = [("vertex", np.arange(pts.shape[0], dtype=np.int64).reshape(-1, 1))]
    tmp = path.with_name(path.name + ".tmp.vtu")
    meshio.write(tmp, meshio.Mesh(pts, cells, point_data=data), file_format="vtu",
                 binary=True, compression=None)
    faults.point("vtu.tmp_written")
    _atomic_replace(tmp, path)
    faults.point("vtu.renamed")


def write_grid_vtr(path: str | Path, axes) -> None:
    """The background grid as a VTK XML RectilinearGrid (.vtr): the node coordinates of
    each axis (3 arrays, m), uniform or graded, for ParaView to draw under the points."""
    path = Path(path)
    axes = [np.asarray(a, dtype=np.float64) for a in axes]
    extent = " ".join(f"0 {len(a) - 1}" for a in axes)
    coords = "\n".join(
        f'<DataArray type="Float64" Name="{n}" format="ascii">'
        f'{" ".join(repr(float(v)) for v in a)}</DataArray>'
        for n, a in zip("xyz", axes, strict=True))
    text = (f'<?xml version="1.0"?>\n<VTKFile type="RectilinearGrid" version="0.1" '
            f'byte_order="LittleEndian">\n<RectilinearGrid WholeExtent="{extent}">\n'
            f'<Piece Extent="{extent}">\n<Coordinates>\n{coords}\n</Coordinates>\n'
            "</Piece>\n</RectilinearGrid>\n</VTKFile>\n")
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    _atomic_replace(tmp, path)


def read_points_vtu(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Points (P,3) and per-point fields of a .vtu written by write_points_vtu (tensor
    fields come back flattened, (P,9))."""
    mesh = meshio.read(path)
    return mesh.points, dict(mesh.point_data)


class PVDSeries:
    """A .pvd collection file listing (time, file) entries, rewritten atomically on add."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.entries: list[tuple[float, str]] = []

    @classmethod
    def load(cls, path: str | Path, keep: int | None = None,
             until: float | None = None) -> PVDSeries:
        """Read an existing series (cut back to its first `keep` entries, if it has
        more, and to the entries at times <= `until`) to continue it."""
        import xml.etree.ElementTree as ET

        s = cls(path)
        if s.path.is_file():
            root = ET.parse(s.path).getroot()
            for ds in root.iter("DataSet"):
                s.entries.append((float(ds.get("timestep")), ds.get("file")))
        if until is not None:
            keep = min(len(s.entries) if keep is None else keep,
                       sum(t <= until for t, _ in s.entries))
        if keep is not None and len(s.entries) > keep:  # (a series never begun stays so)
            s.entries = s.entries[:keep]
            s.write()
        return s

    def add(self, time: float, file: str | Path) -> None:
        rel = os.path.relpath(Path(file), self.path.parent)
        self.entries.append((float(time), rel))
        self.write()

    def write(self) -> None:
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "  <Collection>"]
        for t, f in self.entries:
            lines.append(f'    <DataSet timestep="{t!r}" group="" part="0" '
                         f"file={quoteattr(f)}/>")
        lines += ["  </Collection>", "</VTKFile>", ""]
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text("\n".join(lines))
        faults.point("pvd.tmp_written")
        _atomic_replace(tmp, self.path)

"""Probe RVEs: the full state of chosen points' RVEs as ParaView series.

Each `[[output.probes]]` entry names a position; at start-up it is resolved to the
material point of a 'dem' material whose initial position is nearest to it (straight-
line distance; on a tie the lowest point id), and the probe then follows that point
(and its RVE) wherever it moves. The resolution is written to `probes.json` and, unless
the run is quiet, to the log. At every frame time (output.frame_interval, also with
output.frames = false) the RVE is written with io/rve_vtk.py as
`frames/probe_NAME_NNNNN_{spheres,contacts,cell}.vtu` (NNNNN: the frame's number, as in
frame_NNNNN.vtu), listed in `probe_NAME_spheres.pvd`, `probe_NAME_contacts.pvd` and
`probe_NAME_cell.pvd`.

What is written is the RVE at the end of the step, with its contact forces and
Love-Weber stress evaluated in that configuration (engine.refresh on a copy, which
changes nothing: the RVE's update ends with the same evaluation). The stress in
frame_NNNNN.vtu, the one the MPM used, is its symmetric part.

Under MPI the rank that owns the point now (ownership changes when rebalancing) sends
a copy of its RVE to rank 0, which writes every file, as it does the frames. A resumed
run cuts each series back to the frames at or before the checkpoint's time and
continues it; a probe whose point changed (its position was edited) starts a new series.
"""

from __future__ import annotations

import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from grainscale.config.base import ConfigError
from grainscale.config.case import Case
from grainscale.dem import engine
from grainscale.io.rve_vtk import write_rve_vtk
from grainscale.io.vtk import PVDSeries
from grainscale.mpm.step import MPMState

KINDS = ("spheres", "contacts", "cell")  # the files of one snapshot (io/rve_vtk.py)
RECORD = "probes.json"


@dataclass
class Probe:
    """A probe resolved to a point: its name, the position asked for [m], the point's
    global id, material, initial position [m] and distance from the position [m]."""
    name: str
    position: list[float]
    point: int
    material: str
    point_position: list[float]
    distance: float


def resolve(case: Case, s: MPMState) -> list[Probe]:
    """The point of each of case.output.probes; `s` holds every point of the case (a
    serial state, as driver.check_geometry builds it). ConfigError if no point belongs
    to a 'dem' material."""
    if not case.output.probes:
        return []
    names = list(case.materials)
    dem = [k for k, n in enumerate(names) if case.materials[n].type == "dem"]
    on = np.flatnonzero(np.isin(s.points.mat, dem))
    if on.size == 0:
        raise ConfigError(f"output.probes[0].position = {list(case.output.probes[0].position)}:"
                          f" no material point of a 'dem' material ({[names[k] for k in dem]})"
                          " to show; bodies use materials "
                          f"{sorted({b.material for b in case.bodies})}")
    x0 = s.points.x0
    probes = []
    for p in case.output.probes:
        dist = np.linalg.norm(x0[on] - np.asarray(p.position), axis=1)
        k = int(np.argmin(dist))  # the first of equals: the lowest id
        point = int(s.point_ids[on[k]])
        probes.append(Probe(p.name, list(p.position), point, names[s.points.mat[on[k]]],
                            x0[on[k]].tolist(), float(dist[k])))
    return probes


def describe(p: Probe) -> str:
    pos = ", ".join(f"{v:.6g}" for v in p.point_position)
    return (f"probe {p.name!r}: point {p.point} of material {p.material!r}, initially at "
            f"[{pos}] m, {p.distance:.3g} m from the probe's position")


def _local_rve(s: MPMState, point: int):
    """(RVE copy refreshed in its configuration, its contact law) of global point
    `point` if this rank owns it, else None."""
    pos = int(np.searchsorted(s.point_ids, point))
    if pos == len(s.point_ids) or s.point_ids[pos] != point:
        return None
    m = int(s.points.mat[pos])
    mat, ids = s.materials[m], s.mat_points[m]
    row = pos if ids is None else int(np.searchsorted(ids, pos))
    batch = mat.rve(row)
    engine.refresh(batch, mat.cp)
    return batch, mat.cp


class ProbeWriter:
    """The probes' series of a run (files on rank 0); `write` is collective."""

    def __init__(self, out: Path, probes: list[Probe], comm, resume_time: float | None = None,
                 report: bool = False):
        self.out = Path(out)
        self.probes = probes
        self.comm = comm
        self.series: dict[str, dict[str, PVDSeries]] = {}
        if not comm.root:
            return
        before = {}
        record = self.out / RECORD
        if resume_time is not None and record.is_file():
            before = {p["name"]: p["point"] for p in json.loads(record.read_text())["probes"]}
        for p in probes:
            kept = resume_time is not None and before.get(p.name) == p.point
            self.series[p.name] = {
                kind: PVDSeries.load(self.pvd(p.name, kind), until=resume_time) if kept
                else PVDSeries(self.pvd(p.name, kind)) for kind in KINDS}
            if not kept:  # a new series (an earlier one of the name showed another point)
                for series in self.series[p.name].values():
                    series.write()
            if report:
                print(f"grainscale: {describe(p)}", file=sys.stderr)
        if probes or record.is_file():
            data = {"note": "each probe shows the RVE of the 'dem' material point nearest its "
                            "position at the start, and follows that point",
                    "probes": [{**asdict(p), "series": {k: self.pvd(p.name, k).name
                                                        for k in KINDS}} for p in probes]}
            tmp = record.with_name(record.name + ".tmp")
            tmp.write_text(json.dumps(data, indent=2) + "\n")
            tmp.replace(record)

    def pvd(self, name: str, kind: str) -> Path:
        return self.out / f"probe_{name}_{kind}.pvd"

    def write(self, s: MPMState, frame: int) -> None:
        """Every probe's RVE as frame number `frame` at the current time. Collective."""
        if not self.probes:
            return
        mine = [(i, found) for i, p in enumerate(self.probes)
                if (found := _local_rve(s, p.point)) is not None]
        parts = self.comm.gather(mine)
        if parts is None:
            return
        for i, (batch, cp) in sorted(
                (x for part in parts for x in part), key=lambda x: x[0]):
            name = self.probes[i].name
            paths = write_rve_vtk(self.out / "frames" / f"probe_{name}_{frame:05d}", batch,
                                  cp)
            for kind, path in zip(KINDS, paths, strict=True):
                self.series[name][kind].add(s.time, path)

"""Checkpoints of a (possibly distributed) run: every rank writes its own part, rank 0
commits them with a manifest.

Layout in the output folder:
    checkpoint.h5                       manifest: time, step, output counters, rank
                                        count, the parts folder, the rigid body
    checkpoint.parts/STEP_N/rank_R.h5   one part per rank (N ranks): its points (with their
                                        global ids) and its materials' state (every
                                        RVE in full, with its contact history)
Each file is written to a temporary name and renamed; the manifest is replaced only
after every rank has finished its part, and older parts are deleted only after that, so
a job killed at any moment leaves the previous checkpoint complete and valid.

Any number of ranks can resume a checkpoint: each rank reads from every part the rows
of the points it owns (by global id). Results do not depend on the rank count, so a
resume on a different number of ranks continues the same history.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np

from grainscale.config.base import ConfigError
from grainscale.io.checkpoint import read_checkpoint, write_checkpoint
from grainscale.mpm.step import MPMState, RemoteFailure, SimulationError

MANIFEST = "checkpoint.h5"
PARTS = "checkpoint.parts"


def _material_ids(s: MPMState, i: int) -> np.ndarray:
    ids = s.mat_points[i]
    return s.point_ids if ids is None else s.point_ids[ids]


def rank_state(s: MPMState) -> dict[str, dict[str, np.ndarray]]:
    """This rank's points and materials' state, every row tagged with its global point
    id (a checkpoint part, or what rebalancing moves between ranks)."""
    groups = {"points": {**s.points.arrays(), "global_id": s.point_ids}}
    for i, m in enumerate(s.materials):
        groups[f"material_{i}"] = {**m.state(), "global_id": _material_ids(s, i)}
    return groups


def save(out: Path, s: MPMState, counters: dict[str, int]) -> None:
    """Write this rank's part, then (rank 0) the manifest; collective."""
    # the rank count is in the name: a resume on other ranks that saves at the same step
    # must not overwrite the parts the current manifest still names
    folder = out / PARTS / f"{s.step:010d}_{s.comm.size}"
    error = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        write_checkpoint(folder / f"rank_{s.comm.rank:05d}.h5", rank_state(s),
                         {"step": s.step})
    except OSError as err:
        error = err
    if s.comm.any(error is not None):  # keep the previous checkpoint
        if error is not None:
            raise SimulationError(f"writing checkpoint part {folder}: {error}") from None
        raise RemoteFailure("another rank could not write its checkpoint part")
    if s.comm.root:
        groups = {}
        if s.rigid is not None:
            groups["rigid"] = {"x": s.rigid.x, "displacement": s.rigid.displacement,
                               "force": s.rigid.force}
        attrs = {"time": s.time, "step": s.step, "vmax": s.vmax, "last_dt": s.last_dt,
                 "ranks": s.comm.size,
                 "parts": f"{PARTS}/{folder.name}", **counters}
        write_checkpoint(out / MANIFEST, groups, attrs)
        for old in (out / PARTS).iterdir():  # superseded parts
            if old.name != folder.name:
                shutil.rmtree(old, ignore_errors=True)
    s.comm.barrier()  # no rank runs ahead into a new part while rank 0 cleans up


def rows_of(group, wanted: np.ndarray) -> tuple[np.ndarray, dict]:
    """The rows of a group (an HDF5 group or a dict of arrays) whose global ids are in
    `wanted` (sorted): their ids and arrays. Only those rows are read from a file."""
    gid = np.asarray(group["global_id"][()])
    rows = np.flatnonzero(np.isin(gid, wanted))
    arrays = {k: group[k][rows] if len(rows) else group[k][:0]
              for k in group if k != "global_id"}
    return gid[rows], arrays


def load_rows(s: MPMState, sources) -> bool:
    """Fill s with the rows it owns from `sources` (mappings group -> arrays: open part
    files or rank_state() dicts). Returns whether every point of s was found."""
    ids, point_parts = [], []
    mat_ids = [[] for _ in s.materials]
    mat_parts = [[] for _ in s.materials]
    for src in sources:
        g, a = rows_of(src["points"], s.point_ids)
        ids.append(g)
        point_parts.append(a)
        for i in range(len(s.materials)):
            g, a = rows_of(src[f"material_{i}"], _material_ids(s, i))
            mat_ids[i].append(g)
            mat_parts[i].append(a)
    found = np.concatenate(ids)
    if found.size != s.points.n:
        return False
    order = np.argsort(found)
    for k in point_parts[0]:
        getattr(s.points, k)[...] = np.concatenate([p[k] for p in point_parts])[order]
    for i, m in enumerate(s.materials):
        merge = getattr(m, "merge_states", None)
        state = merge(mat_parts[i]) if merge else {
            k: np.concatenate([p[k] for p in mat_parts[i]]) for k in mat_parts[i][0]}
        order = np.argsort(np.concatenate(mat_ids[i]))
        m.load_state({k: v[order] for k, v in state.items()})
    return True


def restore(out: Path, s: MPMState) -> dict:
    """Load the latest checkpoint into s (the rows this rank owns); returns the
    manifest's attributes. Collective: every rank reads alone, then the ranks agree on
    whether all found their points, so an error is raised on every rank or none."""
    groups, attrs = read_checkpoint(out / MANIFEST)
    folder = out / str(attrs["parts"])
    files = [folder / f"rank_{r:05d}.h5" for r in range(int(attrs["ranks"]))]
    missing = [f for f in files if not f.is_file()]
    if missing:
        raise ConfigError(f"{out / MANIFEST}: checkpoint part {missing[0]} is missing")
    handles = [h5py.File(path, "r") for path in files]
    try:
        for path, f in zip(files, handles, strict=True):
            if f.attrs["step"] != attrs["step"]:
                raise ConfigError(f"{path}: from step {f.attrs['step']}, the manifest is "
                                  f"at step {attrs['step']}")
        complete = load_rows(s, handles)
    finally:
        for f in handles:
            f.close()
    if s.comm.any(not complete):
        raise ConfigError(f"{out / MANIFEST}: the checkpoint does not hold the points this "
                          "case builds; was the case file changed?")
    if s.rigid is not None:
        s.rigid.x[...] = groups["rigid"]["x"]
        s.rigid.displacement[...] = groups["rigid"]["displacement"]
        s.rigid.force[...] = groups["rigid"]["force"]
    s.time = float(attrs["time"])
    s.step = int(attrs["step"])
    s.vmax = float(attrs["vmax"])
    s.last_dt = float(attrs.get("last_dt", 0.0))
    return attrs

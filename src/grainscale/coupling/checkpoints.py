"""Checkpoints of a (possibly distributed) run: every rank writes its own part, rank 0
commits them with a manifest; a resume checks them and the case before using them.

Layout in the output folder:
    checkpoint.h5                       manifest of the newest checkpoint: time, step,
                                        output counters, rank count, the parts folder,
                                        the rigid body, the case it was run with
    checkpoint.prev.h5                  manifest of the one before: the fallback
    checkpoint.parts/STEP_N/rank_R.h5   one part per rank (N ranks): its points (with their
                                        global ids) and its materials' state (every
                                        RVE in full, with its contact history)
Every file carries checksums of its arrays and attributes (io/checkpoint.py). Each file
is written to a temporary name and renamed; the manifest is replaced only after every
rank has finished its part, the manifest it replaces becomes checkpoint.prev.h5, and
only parts that neither manifest names are deleted, so a job killed at any moment, or a
checkpoint damaged later, leaves a complete and valid earlier one.

A resume (`find`) takes checkpoint.h5 if every checksum of it and its parts matches,
else checkpoint.prev.h5 with a warning naming the bad file and why; it then compares
the case the checkpoint was run with against the current one (`check_case`).

Any number of ranks can resume a checkpoint: each rank reads from every part the rows
of the points it owns (by global id). Results do not depend on the rank count, so a
resume on a different number of ranks continues the same history.
"""

from __future__ import annotations

import difflib
import json
import os
import shutil
import sys
from pathlib import Path
from typing import NamedTuple

import h5py
import numpy as np

from grainscale.config.base import ConfigError
from grainscale.io import faults
from grainscale.io.checkpoint import (
    CorruptCheckpoint,
    read_checkpoint,
    verify_checkpoint,
    write_checkpoint,
)
from grainscale.mpm.step import MPMState, RemoteFailure, SimulationError

MANIFEST = "checkpoint.h5"
PREVIOUS = "checkpoint.prev.h5"
PARTS = "checkpoint.parts"

# Case keys (and tables) that may change on a resume without --allow-changed: they do
# not change the physics of the steps already taken or to come. time.end: extending
# or shortening a run is the normal use; the rest are performance, element tests
# (`grainscale rve`, not this run) or outputs that do not touch history.csv.
FREE = ("title", "time.end", "solver.threads", "solver.device", "solver.partition_seed",
        "solver.rebalance_every", "output.frames", "output.frame_interval",
        "output.checkpoint_every", "output.probes", "triaxial", "undrained", "isotropic",
        "shear")
# Keys that can never change on a resume: history.csv keeps the columns of its header.
FIXED = ("output.history",)
# Keys added to a table after checkpoints were written without them, with the value that
# keeps those checkpoints' physics: absent from a checkpoint and at that value in the
# case is no change (a material's adaptive updates, off).
ADDED = {"update_tolerance": 0.0, "max_deferred_steps": 20}
# [rve] keys added with the Hertz-Mindlin law: absent from an older checkpoint's case,
# they change nothing while the law is the linear one it ran with
RVE_ADDED = ("rve.contact_law", "rve.poisson_ratio", "rve.numerics.max_overlap")
# [rve] keys added later still, with the value that keeps an older checkpoint's physics
# (no clumps: the grains are the spheres it ran with)
RVE_ADDED_AT = {"rve.clump": None}


class Checkpoint(NamedTuple):
    """A checkpoint whose files were all verified: its manifest, the manifest's
    attributes and arrays, and the case (as case_record) it was run with."""
    manifest: Path
    attrs: dict
    groups: dict
    case: dict


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


def save(out: Path, s: MPMState, counters: dict[str, int], case: dict,
         previous: Path | None) -> None:
    """Write this rank's part, then (rank 0) the manifest; collective.

    `case` is the case_record() of the run. `previous` is the manifest of this run's
    last valid checkpoint (the one it resumed from, or last wrote): it is kept as
    checkpoint.prev.h5, the fallback of a resume. None (a new run) removes an older run's
    checkpoint.prev.h5, which the new history.csv no longer matches. A file that cannot
    be written stops the run (SimulationError on every rank) and keeps the previous
    checkpoint."""
    # the rank count is in the name: a resume on other ranks that saves at the same step
    # must not overwrite the parts the current manifest still names
    folder = out / PARTS / f"{s.step:010d}_{s.comm.size}"
    error = None
    faults.point("checkpoint.begin")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        write_checkpoint(folder / f"rank_{s.comm.rank:05d}.h5", rank_state(s),
                         {"step": s.step}, fault="checkpoint.part")
    except OSError as err:
        shutil.rmtree(folder, ignore_errors=True)  # no manifest names it
        error = f"{err} (a checkpoint part){_intact(out, previous)}"
    _stop_if_any(s.comm, error)
    faults.point("checkpoint.parts_written")
    if s.comm.root:
        try:
            _commit(out, s, folder, counters, case, previous)
        except OSError as err:
            error = f"{err} (a checkpoint manifest){_intact(out, previous)}"
    _stop_if_any(s.comm, error)
    s.comm.barrier()  # no rank runs ahead into a new part while rank 0 cleans up
    faults.point("checkpoint.done")


def discard(out: Path) -> None:
    """Remove the checkpoints an earlier run left in `out` (rank 0, at the start of a
    new run, before its history.csv replaces the old one): a resume must not continue
    them with the new run's history. Until every manifest is gone the old history.csv
    is still there, so a kill at any moment leaves a consistent folder."""
    for name in (PREVIOUS, MANIFEST):
        (out / name).unlink(missing_ok=True)
    shutil.rmtree(out / PARTS, ignore_errors=True)


def _intact(out: Path, previous: Path | None) -> str:
    """What a failed checkpoint leaves to resume from, for its message."""
    if previous is None or not previous.is_file():
        return f"; no checkpoint in {out} yet: run again once the cause is removed"
    return (f"; the last checkpoint in {out} is intact: continue with --resume once the "
            "cause is removed")


def _stop_if_any(comm, error: str | None) -> None:
    if comm.any(error is not None):
        if error is not None:
            raise SimulationError(error) from None
        raise RemoteFailure("another rank could not write its checkpoint")


def _commit(out: Path, s: MPMState, folder: Path, counters: dict, case: dict,
            previous: Path | None) -> None:
    """Rank 0: rotate the manifests, write the new one, delete parts neither names."""
    manifest, prev = out / MANIFEST, out / PREVIOUS
    if previous is None:
        prev.unlink(missing_ok=True)
    elif previous == manifest and manifest.is_file():
        os.replace(manifest, prev)
    # else previous is prev: checkpoint.h5 is the bad one a resume fell back from
    faults.point("checkpoint.rotated")
    groups = {"case": {"json": np.frombuffer(json.dumps(case, sort_keys=True).encode(),
                                             dtype=np.uint8)}}
    if s.rigid is not None:
        groups["rigid"] = {"x": s.rigid.x, "displacement": s.rigid.displacement,
                           "force": s.rigid.force,
                           "wave_speed_ref": np.array([s.rigid.wave_speed_ref])}
    attrs = {"time": s.time, "step": s.step, "vmax": s.vmax, "last_dt": s.last_dt,
             "ranks": s.comm.size, "parts": f"{PARTS}/{folder.name}", **counters}
    write_checkpoint(manifest, groups, attrs, fault="checkpoint.manifest")
    faults.point("checkpoint.committed")
    keep = {folder.name, _parts_name(prev)}
    for old in (out / PARTS).iterdir():
        if old.name not in keep:
            shutil.rmtree(old, ignore_errors=True)
            faults.point("checkpoint.cleanup")


def _parts_name(manifest: Path) -> str | None:
    """The parts folder a manifest names (None if there is no readable manifest)."""
    try:
        with h5py.File(manifest, "r") as f:
            return Path(str(f.attrs["parts"])).name
    except Exception:
        return None


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
        a, into = np.concatenate([p[k] for p in point_parts])[order], getattr(s.points, k)
        into[...] = a if a.ndim == into.ndim else a[:, None]  # lp (P,) of older checkpoints
    for i, m in enumerate(s.materials):
        merge = getattr(m, "merge_states", None)
        state = merge(mat_parts[i]) if merge else {
            k: np.concatenate([p[k] for p in mat_parts[i]]) for k in mat_parts[i][0]}
        order = np.argsort(np.concatenate(mat_ids[i]))
        if np.array_equal(order, np.arange(len(order))):  # in order: no copy of the state
            m.load_state(state)
        else:
            m.load_state({k: v[order] for k, v in state.items()})
    return True


def find(out: Path, comm) -> Checkpoint:
    """The newest valid checkpoint in `out`: checkpoint.h5, else checkpoint.prev.h5.

    Valid: the manifest and every part exist, every checksum in them matches and every
    part is from the manifest's step. A checkpoint that is not valid is skipped with a
    warning on stderr naming the file and why; ConfigError if none is valid.
    Collective: each rank checks a share of the parts and the ranks agree."""
    problems = []
    for manifest in (out / MANIFEST, out / PREVIOUS):
        found, problem = _check(out, manifest, comm)
        if found is not None:
            if problems and comm.root:
                print(f"grainscale: warning: {'; '.join(problems)}: resuming from the "
                      f"previous checkpoint {manifest} (step {found.attrs['step']}, t = "
                      f"{found.attrs['time']:.6g} s)", file=sys.stderr)
            return found
        problems.append(problem)
    if not any(p.is_file() for p in (out / MANIFEST, out / PREVIOUS)):
        raise ConfigError(f"--resume: no checkpoint {str(out / MANIFEST)!r} to resume from")
    raise ConfigError(f"--resume: no valid checkpoint in {out}:\n"
                      + "\n".join(f"  {p}" for p in problems))


def _check(out: Path, manifest: Path, comm) -> tuple[Checkpoint | None, str | None]:
    problem = found = None
    try:
        groups, attrs = read_checkpoint(manifest)
        folder = out / str(attrs["parts"])
        for r in range(comm.rank, int(attrs["ranks"]), comm.size):
            part = folder / f"rank_{r:05d}.h5"
            step = verify_checkpoint(part).get("step")
            if step != attrs["step"]:
                raise CorruptCheckpoint(f"{part}: from step {step}, its manifest {manifest} "
                                        f"is at step {attrs['step']}")
        case = json.loads(bytes(groups["case"]["json"]).decode())
        found = Checkpoint(manifest, attrs, groups, case)
    except CorruptCheckpoint as err:
        problem = str(err)
    except (KeyError, ValueError) as err:  # a valid file without what a manifest holds
        problem = f"{manifest}: not a complete checkpoint manifest ({err!r} is missing)"
    problems = comm.gather(problem)
    problem = comm.bcast(next((p for p in problems if p), None) if comm.root else None)
    return (None, problem) if problem else (found, None)


def restore(found: Checkpoint, s: MPMState) -> dict:
    """Load a checkpoint (from find) into s: the rows this rank owns; returns the
    manifest's attributes. Collective: every rank reads alone, then the ranks agree on
    whether all found their points, so an error is raised on every rank or none."""
    out, attrs = found.manifest.parent, found.attrs
    folder = out / str(attrs["parts"])
    files = [folder / f"rank_{r:05d}.h5" for r in range(int(attrs["ranks"]))]
    handles = [h5py.File(path, "r") for path in files]
    try:
        complete = load_rows(s, handles)
    except KeyError as err:  # every rank alike: the same materials read the same files
        raise ConfigError(f"{found.manifest}: the checkpoint holds no state {err} for the "
                          "materials this case builds; was a material's type changed?"
                          ) from None
    finally:
        for f in handles:
            f.close()
    if s.comm.any(not complete):
        raise ConfigError(f"{found.manifest}: the checkpoint does not hold the points this "
                          "case builds; was the case file changed?")
    if s.rigid is not None:
        rigid = found.groups.get("rigid")
        if rigid is None or rigid["x"].shape != s.rigid.x.shape:
            raise ConfigError(f"{found.manifest}: the checkpoint does not hold the rigid "
                              "body this case builds; was the case file changed?")
        s.rigid.x[...] = rigid["x"]
        s.rigid.displacement[...] = rigid["displacement"]
        s.rigid.force[...] = rigid["force"]
        # the penalty stiffness was fixed when the contact first acted (mpm/rigid.py)
        if "wave_speed_ref" in rigid:  # absent from checkpoints of node-contact runs
            s.rigid.wave_speed_ref = float(rigid["wave_speed_ref"][0])
    s.time = float(attrs["time"])
    s.step = int(attrs["step"])
    s.vmax = float(attrs["vmax"])
    s.last_dt = float(attrs.get("last_dt", 0.0))
    return attrs


# --------------------------------------------------------------------------- the case
def case_record(case) -> dict:
    """The validated case as plain JSON data (every default filled in), as stored in a
    checkpoint. Take it before the run sets values (a "dem" material's density)."""
    return json.loads(json.dumps(case.model_dump(mode="json")))


def flat_keys(data, key: str = "") -> dict:
    """{dotted key: value} of case data, keys as in the case file: `solver.gravity`,
    `materials.soil.youngs_modulus`, `bodies[0].lo`. Lists of numbers are values."""
    if isinstance(data, dict):
        out = {}
        for k, v in data.items():
            out.update(flat_keys(v, f"{key}.{k}" if key else k))
        return out
    if isinstance(data, list) and any(isinstance(v, dict) for v in data):
        out = {}
        for i, v in enumerate(data):
            out.update(flat_keys(v, f"{key}[{i}]"))
        return out
    return {key: data}


def _covers(name: str, key: str) -> bool:
    """`name` is the key itself or a table holding it."""
    return key == name or key.startswith((name + ".", name + "["))


_ABSENT = object()


def _show(v) -> str:
    return "(absent)" if v is _ABSENT else repr(v)


def changed_keys(old: dict, new: dict) -> list[tuple[str, object, object]]:
    """(key, old value, new value) of every key that differs between two case records,
    the FREE keys left out, and the ADDED ones absent from `old` at the value that keeps
    its physics; a key present on one side only has the value _ABSENT."""
    a, b = flat_keys(old), flat_keys(new)
    return [(k, a.get(k, _ABSENT), b.get(k, _ABSENT)) for k in dict.fromkeys([*b, *a])
            if a.get(k, _ABSENT) != b.get(k, _ABSENT)
            and not any(_covers(f, k) for f in FREE)
            and not (k not in a and k.startswith("materials.")
                     and k.rsplit(".", 1)[-1] in ADDED
                     and b[k] == ADDED[k.rsplit(".", 1)[-1]])
            and not (k not in a and k in RVE_ADDED
                     and b.get("rve.contact_law", "linear") == "linear")
            and not (k not in a and k in RVE_ADDED_AT and b[k] == RVE_ADDED_AT[k])]


def check_case(found: Checkpoint, case: dict, allowed: list[str]) -> None:
    """Refuse to resume a checkpoint run with other physics than the current case.

    Every key that differs between the case stored in the checkpoint and `case` (both
    case_record()s), except the FREE ones, must be named in `allowed` (--allow-changed;
    a table such as `materials.soil` names all its keys); FIXED keys can never change.
    Every name in `allowed` must be a key (or table) of one of the two cases. Raises
    ConfigError listing each refused key with its old and new value."""
    keys = [*flat_keys(found.case), *flat_keys(case)]
    for name in allowed:
        if not any(_covers(name, k) for k in keys):
            close = difflib.get_close_matches(name, sorted(set(keys)), n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ConfigError(f"--allow-changed {name}: not a key of this case{hint}; valid: "
                              "a dotted key as the case file spells it (solver.gravity, "
                              "materials.NAME.youngs_modulus, bodies[0].lo) or a table "
                              "(materials.NAME)")
    changed = changed_keys(found.case, case)
    fixed = [k for k, _, _ in changed if any(_covers(f, k) for f in FIXED)]
    if fixed:
        raise ConfigError(f"--resume: {', '.join(fixed)} changed since the checkpoint "
                          f"{found.manifest} was written, and cannot: history.csv keeps the "
                          "columns of its header; restore it, or start a new run in another "
                          "--out folder")
    refused = [c for c in changed if not any(_covers(n, c[0]) for n in allowed)]
    if refused:
        lines = "\n".join(f"  {k} = {_show(o)} -> {_show(n)}" for k, o, n in refused)
        raise ConfigError(
            f"--resume: the case no longer matches the checkpoint {found.manifest}; these "
            f"keys changed since it was written (checkpoint -> case file):\n{lines}\n"
            "the resumed run would not continue the same physics: restore them, start a "
            "new run in another --out folder, or resume anyway with --resume "
            f"--allow-changed {' '.join(k for k, _, _ in refused)}")

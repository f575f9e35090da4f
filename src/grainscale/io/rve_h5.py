"""Full RVE state (cell, spheres, contact history) to and from HDF5.

Layout: one group `rve` holding every array of `dem.state.STATE_FIELDS` (and, for
clumps, CLUMP_FIELDS) with the RVE index first, plus attributes (format version, package
version, and any parameters the caller passes, e.g. the [rve] table as JSON). Written
atomically: a temporary file is renamed over the target only once complete, so an
existing file stays valid.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from grainscale import __version__
from grainscale.config.base import ConfigError
from grainscale.dem.state import (
    CLUMP_FIELDS,
    STATE_FIELDS,
    RVEBatch,
    from_state_arrays,
    state_arrays,
)
from grainscale.io.checkpoint import write_h5_atomic

FORMAT = "grainscale-rve-state v1"


def write_group(group: h5py.Group, batch: RVEBatch) -> None:
    """Store the state arrays of `batch` in an open HDF5 group."""
    for name, arr in state_arrays(batch).items():
        group.create_dataset(name, data=arr, compression="gzip", compression_opts=1,
                             shuffle=True)


def read_group(group: h5py.Group) -> RVEBatch:
    missing = [n for n in STATE_FIELDS if n not in group]
    if missing:
        raise ConfigError(f"RVE state is missing arrays {missing}")
    names = STATE_FIELDS + (CLUMP_FIELDS if "bm" in group else ())
    return from_state_arrays({name: group[name][()] for name in names})


def write_rve_state(path: str | Path, batch: RVEBatch, params: dict | None = None) -> None:
    """The batch's full state to `path` (.h5), atomically; a full disk is an OSError
    naming the file (io/checkpoint.write_h5_atomic)."""
    path = Path(path)

    def fill(f: h5py.File) -> None:
        f.attrs["format"] = FORMAT
        f.attrs["grainscale_version"] = __version__
        if params is not None:
            f.attrs["params"] = json.dumps(params)
        write_group(f.create_group("rve"), batch)

    write_h5_atomic(path, path.with_name(path.name + ".tmp"), fill)


def read_rve_state(path: str | Path) -> tuple[RVEBatch, dict | None]:
    """(batch, parameters stored with it or None)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"RVE state file {str(path)!r} does not exist")
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != FORMAT:
            raise ConfigError(f"{path}: not a grainscale RVE state file "
                              f"(format {f.attrs.get('format')!r}, expected {FORMAT!r})")
        params = json.loads(f.attrs["params"]) if "params" in f.attrs else None
        batch = read_group(f["rve"])
    batch.need_rebuild[:] = np.maximum(batch.need_rebuild, 0)
    return batch, params

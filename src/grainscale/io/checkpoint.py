"""HDF5 checkpoints, written atomically.

Layout: groups of arrays (`groups[name][key] -> ndarray`) and scalar attributes on the
root. Written to `<name>.tmp.h5`, flushed and fsync'ed, then renamed onto the final name,
so an interrupted write never destroys the previous checkpoint.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np


def write_checkpoint(path: str | Path, groups: dict[str, dict[str, np.ndarray]],
                     attrs: dict[str, float | int | str]) -> None:
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp.h5")
    with h5py.File(tmp, "w") as f:
        for k, v in attrs.items():
            f.attrs[k] = v
        for g, arrays in groups.items():
            grp = f.create_group(g)
            for k, a in arrays.items():
                grp.create_dataset(k, data=np.asarray(a))
        f.flush()
        os.fsync(f.id.get_vfd_handle())
    os.replace(tmp, path)


def read_checkpoint(path: str | Path) -> tuple[dict[str, dict[str, np.ndarray]], dict]:
    with h5py.File(path, "r") as f:
        attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in f.attrs.items()}
        groups = {g: {k: f[g][k][()] for k in f[g]} for g in f}
    return groups, attrs

"""HDF5 checkpoint files, written atomically and checked when read.

Layout: groups of arrays (`groups[name][key] -> ndarray`) and scalar attributes on the
root. Every array carries the SHA-256 of its dtype, shape and bytes (its `sha256`
attribute) and the root the SHA-256 of the other root attributes (`attrs_sha256`), so
reading detects a changed byte in the data or in the attributes. A truncated file, or
one whose HDF5 structure is damaged, fails to open or to read in h5py. Every such
problem, and a file without checksums, is raised as CorruptCheckpoint naming the file
and the array.

Arrays above COMPRESS_BYTES are stored gzip-compressed (level 1, byte shuffle): the
RVEs' neighbour tables are mostly padding, and a multiscale checkpoint shrinks by an
order of magnitude for a few seconds of compression (docs/case-files.md: checkpoints).

Written to `<name>.tmp.h5`, flushed and fsync'ed, then renamed onto the final name and
the folder fsync'ed, so an interrupted write never destroys the previous file. The file is
built in memory and written with plain writes (`write_h5_atomic`): a full disk or any
other write error is then one OSError naming the file (HDF5's own writes failing on a
full disk left h5py's objects half closed, and the process ended in a segmentation
fault). A file above IMAGE_BYTES of arrays is written directly, after a check that the
disk has room for its arrays uncompressed.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np

from grainscale.io import faults

ATTRS_DIGEST = "attrs_sha256"
COMPRESS_BYTES = 1 << 20  # arrays larger than this are compressed
IMAGE_BYTES = 1 << 30  # files with more array bytes are written directly, not built in memory


class CorruptCheckpoint(Exception):
    """A checkpoint file is missing, unreadable, or does not match its checksums."""


def array_digest(a: np.ndarray) -> str:
    """SHA-256 of an array's dtype, shape and bytes (hex)."""
    a = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes() if a.ndim == 0 else a.data)
    return h.hexdigest()


def _plain(v):
    return v.item() if hasattr(v, "item") else v


def attrs_digest(attrs: dict) -> str:
    """SHA-256 of scalar attributes (numbers, strings), independent of their order."""
    text = json.dumps({k: _plain(v) for k, v in attrs.items()}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _no_room(tmp: Path, need: int) -> None:
    """OSError(ENOSPC) naming `tmp` if its folder's disk has less than `need` bytes free."""
    free = shutil.disk_usage(tmp.parent).free
    if free < need:
        raise OSError(28, f"No space left on device ({need / 1e6:.1f} MB to write, "
                          f"{free / 1e6:.1f} MB free)", str(tmp))


def write_h5_atomic(path: Path, tmp: Path, fill: Callable[[h5py.File], None],
                    array_bytes: int = 0, fault: str | None = None) -> None:
    """Write the HDF5 file that `fill(f)` builds to `tmp`, fsync'ed, then rename it onto
    `path` (module docstring); a write error (a full disk) is an OSError naming the file,
    `tmp` removed and `path` untouched. `fault` names io/faults.py's points (tests)."""
    try:
        if array_bytes > IMAGE_BYTES:  # too large to hold twice: written as built
            _no_room(tmp, array_bytes)
            with h5py.File(tmp, "w") as f:
                fill(f)
                f.flush()
                os.fsync(f.id.get_vfd_handle())
        else:
            buffer = io.BytesIO()
            with h5py.File(buffer, "w") as f:
                fill(f)
            image = buffer.getbuffer()
            with open(tmp, "wb") as fh:
                fh.write(image[: len(image) // 2])
                if fault is not None and faults.ARMED:  # a temporary file cut short
                    fh.flush()
                    faults.point(f"{fault}.mid_write")
                fh.write(image[len(image) // 2:])
                fh.flush()
                os.fsync(fh.fileno())
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise OSError(err.errno, err.strerror, str(tmp)) from None
    if fault is not None:
        faults.point(f"{fault}.tmp_written")
    os.replace(tmp, path)
    if fault is not None:
        faults.point(f"{fault}.renamed")
    _fsync_dir(path.parent)


def write_checkpoint(path: str | Path, groups: dict[str, dict[str, np.ndarray]],
                     attrs: dict[str, float | int | str], fault: str = "h5") -> None:
    """Write arrays and attributes with their checksums to `path`, atomically.
    `fault` prefixes the names of the points io/faults.py can kill at (for tests)."""
    path = Path(path)
    plain = {k: _plain(v) for k, v in attrs.items()}

    def fill(f: h5py.File) -> None:
        for k, v in plain.items():
            f.attrs[k] = v
        f.attrs[ATTRS_DIGEST] = attrs_digest(plain)
        for g, arrays in groups.items():
            grp = f.create_group(g)
            for k, a in arrays.items():
                a = np.asarray(a)
                opts = (dict(compression="gzip", compression_opts=1, shuffle=True)
                        if a.nbytes > COMPRESS_BYTES else {})
                grp.create_dataset(k, data=a, **opts).attrs["sha256"] = array_digest(a)

    size = sum(np.asarray(a).nbytes for arrays in groups.values() for a in arrays.values())
    write_h5_atomic(path, path.with_name(path.stem + ".tmp.h5"), fill, size, fault)


def _read(path: Path, keep: bool) -> tuple[dict[str, dict[str, np.ndarray]], dict]:
    if not path.is_file():
        raise CorruptCheckpoint(f"{path}: missing")
    try:
        with h5py.File(path, "r") as f:
            attrs = {k: _plain(v) for k, v in f.attrs.items()}
            stored = attrs.pop(ATTRS_DIGEST, None)
            if stored is None:
                raise CorruptCheckpoint(f"{path}: no checksums (damaged, or written by a "
                                        "grainscale from before checkpoints had them)")
            if stored != attrs_digest(attrs):
                raise CorruptCheckpoint(f"{path}: its attributes do not match their checksum")
            groups = {}
            for g in f:
                for k in f[g]:
                    ds = f[g][k]
                    a = ds[()]
                    want = ds.attrs.get("sha256")
                    if want is None or array_digest(a) != _plain(want):
                        raise CorruptCheckpoint(f"{path}: array {g}/{k} does not match its "
                                                "checksum")
                    if keep:
                        groups.setdefault(g, {})[k] = a
    except CorruptCheckpoint:
        raise
    except Exception as err:  # truncated, or damaged HDF5 structure: h5py's many errors
        raise CorruptCheckpoint(f"{path}: unreadable ({type(err).__name__}: {err})") from None
    return groups, attrs


def read_checkpoint(path: str | Path) -> tuple[dict[str, dict[str, np.ndarray]], dict]:
    """The groups of arrays and the attributes of a checkpoint file, every checksum
    verified; CorruptCheckpoint if it is missing, unreadable or does not match."""
    return _read(Path(path), keep=True)


def verify_checkpoint(path: str | Path) -> dict:
    """Check every checksum of a checkpoint file (reading one array at a time); returns
    its attributes. CorruptCheckpoint as read_checkpoint."""
    return _read(Path(path), keep=False)[1]

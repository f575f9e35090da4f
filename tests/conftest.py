"""Test-run setup: a numba cache that cannot serve stale kernels.

numba's on-disk cache checks only the source file of the function it compiled; a kernel
whose callee in another file was edited is served from the cache as it was
(docs/architecture.md). The tests therefore use a cache folder of their own, keyed on a
hash of every source file of the installed (or editable) grainscale package: any edit
starts from a cold cache, and an unchanged tree reuses its compiled kernels. Set before
numba is imported, and inherited by the runs the tests start in subprocesses (mpiexec,
the CLI, the CUDA simulator).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import tempfile
from pathlib import Path


def _source_hash() -> str:
    spec = importlib.util.find_spec("grainscale")  # locates, does not import
    root = Path(next(iter(spec.submodule_search_locations)))
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


if "NUMBA_CACHE_DIR" not in os.environ:  # an explicit choice wins
    os.environ["NUMBA_CACHE_DIR"] = str(
        Path(tempfile.gettempdir()) / "grainscale-numba-cache" / _source_hash())

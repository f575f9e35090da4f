"""Test-run setup: a numba cache that cannot serve stale kernels, and packings generated
once per source tree.

numba's on-disk cache checks only the source file of the function it compiled; a kernel
whose callee in another file was edited is served from the cache as it was
(docs/architecture.md). The tests therefore use a cache folder of their own, keyed on a
hash of every source file of the installed (or editable) grainscale package: any edit
starts from a cold cache, and an unchanged tree reuses its compiled kernels. Set before
numba is imported, and inherited by the runs the tests start in subprocesses (mpiexec,
the CLI, the CUDA simulator).

The packings the runs generate from [rve] recipes go to one store per source tree
(GRAINSCALE_PACKING_STORE, coupling/materials.py), so each recipe is generated once, not
once per run folder; a source change starts a new store, as it may change generation.
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


# at least two numba threads, also on a one-core machine, so that the tests of thread
# independence compare one thread with two
os.environ.setdefault("NUMBA_NUM_THREADS", str(max(2, os.cpu_count() or 1)))
_HASH = _source_hash()
_TMP = Path(tempfile.gettempdir())
os.environ.setdefault("NUMBA_CACHE_DIR", str(_TMP / "grainscale-numba-cache" / _HASH))
os.environ.setdefault("GRAINSCALE_PACKING_STORE", str(_TMP / "grainscale-test-packings" / _HASH))

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
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest


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


_AHEAD: list[subprocess.Popen] = []


@pytest.hookimpl(trylast=True)  # after -m and -k have deselected
def pytest_collection_modifyitems(session, config, items):
    """Work that later tests need starts now, in one process in the background, on the
    machine's other core: the DEM kernels the selected modules name in COMPILE_AHEAD
    are compiled (tests/warm_kernels.py), then tests/dem/test_cuda_kernel.py's
    simulator runs start (single-threaded Python, minutes; they need those kernels too).
    tests/mpm, which needs none of them, runs first; test_cuda_kernel's tests run last."""
    compile_first = sorted({v for it in items
                            for v in getattr(getattr(it, "module", None), "COMPILE_AHEAD", ())})
    items.sort(key=lambda it: it.path.parent.name != "mpm")  # stable: the rest keep their order
    cuda = [it for it in items if hasattr(getattr(it, "module", None), "start_simulator_ahead")]
    wanted = {name for it in cuda for name in cuda[0].module.FIXTURE_PARTS
              if name in it.fixturenames
              and getattr(it, "callspec", None) is not None
              and it.callspec.params.get(name) == "simulator"}
    items[:] = [it for it in items if it not in cuda] + cuda
    if wanted:
        cuda[0].module.start_simulator_ahead(wanted, compile_first)
    elif compile_first:
        _AHEAD.append(subprocess.Popen([sys.executable, str(Path(__file__).with_name(
            "warm_kernels.py")), *compile_first], stdout=subprocess.DEVNULL))


def pytest_sessionfinish(session, exitstatus):
    for proc in _AHEAD:
        proc.kill()
        proc.wait()
    for it in getattr(session, "items", []):
        stop = getattr(getattr(it, "module", None), "stop_simulator_ahead", None)
        if stop is not None:
            stop()
            return

"""Threads over fixed chunks of points, with results independent of the thread count.

Every hot loop is a cached, GIL-free numba function `task(t, nt, *args)` that handles the
chunks t, t + nt, t + 2 nt, ... of `CHUNK` points; `parallel_for` runs it on nt threads
(the calling thread takes t = 0). The chunk boundaries never depend on nt, so the
floating-point work per point is identical whatever the thread count; scatters go to
per-thread buffers that are summed exactly (integers, see transfer.py).

Why not `prange`: numba's parallel kernels loaded from the on-disk cache ran 4-5x slower
than freshly compiled ones here (numba issue #8085), and compiling them afresh costs
seconds per kernel at every start. Serial `nogil` kernels cache well and threads give the
same parallelism.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba

CHUNK = 2048  # points per work item; fixed so results do not depend on the thread count

_pool: ThreadPoolExecutor | None = None


def n_threads() -> int:
    """Threads to use: numba's setting (numba.set_num_threads / NUMBA_NUM_THREADS)."""
    return numba.get_num_threads()


def parallel_for(task, *args, nt: int | None = None) -> None:
    """Run task(t, nt, *args) for t = 0 .. nt-1 concurrently and wait for all."""
    global _pool
    nt = n_threads() if nt is None else nt
    if nt <= 1:
        task(0, 1, *args)
        return
    if _pool is None or _pool._max_workers < nt - 1:
        _pool = ThreadPoolExecutor(max_workers=max(nt - 1, numba.config.NUMBA_NUM_THREADS))
    futures = [_pool.submit(task, t, nt, *args) for t in range(1, nt)]
    task(0, nt, *args)
    for f in futures:
        f.result()

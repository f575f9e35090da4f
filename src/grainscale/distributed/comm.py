"""The few collectives a distributed run needs, timed, with a serial shortcut.

Every collective used by the solver is here, so that the cost report can split a step
into computing, waiting and communicating: before each reduction a barrier absorbs the
load imbalance (timed as `wait_seconds`), and the reduction itself is then pure
communication (`comm_seconds`). With one rank every call is a no-op or a copy and no
MPI call is made.

Only exact operations are reduced during a step: maxima (order-independent) and sums of
int64 fixed-point values (associative), so no result depends on the number of ranks.
Floating-point sums over points are never reduced; outputs gather the points to rank 0
and sum there in global point order.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np


class Comm:
    """A communicator: `mpi` is an mpi4py communicator, or None for a serial run."""

    def __init__(self, mpi=None):
        self.mpi = mpi if mpi is not None and mpi.Get_size() > 1 else None
        self.rank = 0 if self.mpi is None else self.mpi.Get_rank()
        self.size = 1 if self.mpi is None else self.mpi.Get_size()
        self.wait_seconds = 0.0  # s, in barriers before reductions (load imbalance)
        self.comm_seconds = 0.0  # s, in the reductions themselves
        self.bytes_reduced = 0  # bytes this rank contributed to reductions

    @property
    def root(self) -> bool:
        return self.rank == 0

    def _allreduce(self, a: np.ndarray, op: str) -> None:
        """In place over ranks, after a barrier that takes the waiting out of the timing."""
        from mpi4py import MPI

        t = time.perf_counter()
        self.mpi.Barrier()
        t1 = time.perf_counter()
        self.mpi.Allreduce(MPI.IN_PLACE, a, op=getattr(MPI, op))
        self.wait_seconds += t1 - t
        self.comm_seconds += time.perf_counter() - t1
        self.bytes_reduced += a.nbytes

    def max(self, values) -> np.ndarray:
        """Element-wise maximum over ranks of a float64 vector (exact)."""
        a = np.array(values, dtype=np.float64)
        if self.mpi is not None:
            self._allreduce(a, "MAX")
        return a

    def sum_int(self, a: np.ndarray) -> None:
        """In-place sum over ranks of a contiguous int64 array (exact)."""
        if self.mpi is not None:
            self._allreduce(a, "SUM")

    def total(self, n: int) -> int:
        """Sum of an integer over ranks."""
        a = np.array([n], dtype=np.int64)
        self.sum_int(a)
        return int(a[0])

    def any(self, flag: bool) -> bool:
        """True on every rank if it is true on any."""
        return bool(self.max([1.0 if flag else 0.0])[0] > 0.0)

    def bcast(self, obj):
        return obj if self.mpi is None else self.mpi.bcast(obj, root=0)

    def gather(self, obj) -> list | None:
        """Objects of all ranks, in rank order, on rank 0 (None elsewhere)."""
        return [obj] if self.mpi is None else self.mpi.gather(obj, root=0)

    def barrier(self) -> None:
        if self.mpi is not None:
            self.mpi.Barrier()

    def abort(self, code: int = 1) -> None:
        """End every rank of the job now (a failure that the others cannot see)."""
        if self.mpi is not None:
            sys.stdout.flush()
            sys.stderr.flush()
            time.sleep(0.5)  # let the process manager forward the error before the kill
            self.mpi.Abort(code)

    def node_ranks(self) -> int:
        """Ranks sharing this rank's node (for the default thread count)."""
        return self._node()[1]

    def node_rank(self) -> int:
        """This rank's index among the ranks of its node (for its GPU)."""
        return self._node()[0]

    def _node(self) -> tuple[int, int]:
        if self.mpi is None:
            return 0, 1
        from mpi4py import MPI

        node = self.mpi.Split_type(MPI.COMM_TYPE_SHARED)
        try:
            return node.Get_rank(), node.Get_size()
        finally:
            node.Free()


def launched_by_mpi() -> bool:
    """True when a process manager started us (mpiexec, srun): importing mpi4py in a
    plain serial run would initialise MPI for nothing."""
    keys = ("PMI_RANK", "PMI_SIZE", "PMIX_RANK", "OMPI_COMM_WORLD_SIZE", "MPI_LOCALNRANKS",
            "HYDRA_CONTROL_FD")
    return any(k in os.environ for k in keys)


def world() -> Comm:
    """The job's communicator: MPI_COMM_WORLD under mpiexec/srun, serial otherwise.

    Refuses to run when Slurm started several tasks that MPI does not see as one job
    (`srun --mpi=none`, or an mpi4py built for another MPI): each would run the whole
    case into the same output folder."""
    comm = Comm(None)
    if launched_by_mpi():
        from mpi4py import MPI

        comm = Comm(MPI.COMM_WORLD)
    tasks = int(os.environ.get("SLURM_STEP_NUM_TASKS", "1") or 1)
    if tasks > 1 and comm.size != tasks:
        from grainscale.config.base import ConfigError

        raise ConfigError(f"srun started {tasks} tasks but MPI sees {comm.size} rank(s): "
                          "launch with srun --mpi=pmi2 (or pmix), and check that mpi4py "
                          "uses the cluster's MPI (docs/parallel.md)")
    return comm

"""Fault injection for tests: a run that kills itself with SIGKILL at a named point.

    GRAINSCALE_KILL_AT="NAME:N"      SIGKILL the Nth time (N >= 1) this process reaches
                                     point NAME (every MPI rank that gets there)
    GRAINSCALE_KILL_AT="NAME:N@R"    ... on MPI rank R only
    GRAINSCALE_KILL_AT="NAME:N/SIG"  ... another signal instead (TERM, INT, USR1, ...: a
                                     graceful stop's, tests/test_graceful_stop.py)
    GRAINSCALE_KILL_AT="NAME:N/ENOSPC"  raise OSError(ENOSPC) there instead: a full disk
                                     (tests/test_disk_full.py)

The variable is read once, when this module is first imported; `arm()` sets or clears
the target in a running process. Unset (every normal run), `point()` returns at once.
Nothing is flushed before the kill: files are left exactly as a `kill -9` (or a node's
scheduler) leaves them. An unknown NAME is an error, so a mistyped test cannot pass by
never killing. tests/test_kill_resume.py kills runs at every point and resumes them;
studies/unit_element/kill_resume.py does the same on the unit element.

The points, in the order a step reaches them (what a kill there leaves on disk):

    run.start                   outputs opened (a fresh history.csv holds its header; a
                                resumed one is cut back to its checkpoint), no step yet
    step.begin                  top of the step loop, before this step's outputs
    history.mid_row             half of a history row written and flushed (io/history.py)
    history.row                 a whole row written, before the frame
    vtu.tmp_written             a frame's .vtu complete under its temporary name (io/vtk.py)
    vtu.renamed                 ... renamed into place, not yet listed in the .pvd
    pvd.tmp_written             a .pvd series rewritten under its temporary name
    frame.written               the frame (and the rigid body's) written and listed
    checkpoint.begin            a checkpoint is due, nothing of it written
    checkpoint.part.mid_write   this rank's part: attributes and first group in the
                                temporary file (io/checkpoint.py)
    checkpoint.part.tmp_written ... temporary file complete and fsync'ed, not renamed
    checkpoint.part.renamed     ... renamed into place (folder not yet fsync'ed)
    checkpoint.parts_written    every rank's part on disk, no manifest names them
    checkpoint.rotated          rank 0: checkpoint.h5 renamed to checkpoint.prev.h5: no
                                checkpoint.h5 (a new run's first: none to rename; after
                                a resume that fell back to checkpoint.prev.h5: kept)
    checkpoint.manifest.mid_write    the new manifest: as for the part
    checkpoint.manifest.tmp_written
    checkpoint.manifest.renamed
    checkpoint.committed        rank 0: new manifest in place, old parts not yet removed
    checkpoint.cleanup          rank 0: after removing each part folder no manifest names
    checkpoint.done             the checkpoint complete on every rank
    step.advanced               after the MPM (and DEM) step: state advanced, nothing of it
                                written yet
    step.rebalanced             after moving points between ranks (rebalance_every)
    history.truncate_tmp        on resume: history.csv cut back under its temporary name
    run.end                     history.csv closed (final row written), before cost.json
"""

from __future__ import annotations

import errno
import os
import signal
import sys

ENV = "GRAINSCALE_KILL_AT"

POINTS = ("run.start", "step.begin", "history.mid_row", "history.row", "vtu.tmp_written",
          "vtu.renamed", "pvd.tmp_written", "frame.written", "checkpoint.begin",
          "checkpoint.part.mid_write", "checkpoint.part.tmp_written",
          "checkpoint.part.renamed", "checkpoint.parts_written", "checkpoint.rotated",
          "checkpoint.manifest.mid_write", "checkpoint.manifest.tmp_written",
          "checkpoint.manifest.renamed", "checkpoint.committed", "checkpoint.cleanup",
          "checkpoint.done", "step.advanced", "step.rebalanced", "history.truncate_tmp",
          "run.end")

ARMED = False  # a target is set: callers may skip work done only to expose a point
_name: str | None = None
_count = 0  # hits left before the kill
_rank: int | None = None
_signal = signal.SIGKILL  # or ENOSPC: raise a full disk's OSError instead
ENOSPC = "ENOSPC"


def arm(spec: str | None) -> None:
    """Set the target from a "NAME:N[@R][/SIG]" spec (None or "" clears it)."""
    global ARMED, _name, _count, _rank, _signal
    ARMED, _name, _count, _rank, _signal = False, None, 0, None, signal.SIGKILL
    if not spec:
        return
    try:
        spec_only, _, sig = spec.partition("/")
        name, _, rest = spec_only.rpartition(":")
        n, at, rank = rest.partition("@")
        count, rank_n = int(n), int(rank) if at else None
        sig_n = ENOSPC if sig == ENOSPC else (
            signal.Signals[f"SIG{sig}"] if sig else signal.SIGKILL)
    except (ValueError, KeyError):
        count = rank_n = name = None
    if name not in POINTS or count is None or count < 1:
        raise ValueError(f"{ENV}={spec!r}: expected NAME:N or NAME:N@RANK with N >= 1, "
                         f"optionally /SIG (TERM, INT, ...) or /ENOSPC, and NAME one of "
                         f"{', '.join(POINTS)}")
    ARMED, _name, _count, _rank, _signal = True, name, count, rank_n, sig_n


def _my_rank() -> int:
    mpi = sys.modules.get("mpi4py.MPI")  # imported by the run only under MPI
    return mpi.COMM_WORLD.Get_rank() if mpi is not None and mpi.Is_initialized() else 0


def point(name: str) -> None:
    """Signal this process (SIGKILL unless the spec names another) if it is the
    target's Nth arrival at `name`."""
    global _count
    if name != _name:  # always so when unarmed
        return
    if _rank is not None and _my_rank() != _rank:
        return
    _count -= 1
    if _count == 0:
        if _signal == ENOSPC:
            raise OSError(errno.ENOSPC, "No space left on device (injected at " + name + ")")
        os.kill(os.getpid(), _signal)


arm(os.environ.get(ENV))

"""Graceful stops: SIGINT (Ctrl-C), SIGTERM (what a batch scheduler sends at a job's time
limit) and SIGUSR1 end a run at the next step boundary, with a checkpoint from which
`--resume` continues as if the run had not stopped (docs/parallel.md, "Stopping a run").

A handler only records the signal; the step loop asks `requested` at the top of each
step, and under MPI every rank asks together (one reduction of one integer a step), so
all ranks stop at the same step even when the signal reached only some of them. A second
SIGINT while a stop is pending raises KeyboardInterrupt at once (the last checkpoint is
left as it was). Handlers are installed for the run only, and only from the main thread
(where Python allows it); the previous ones are restored afterwards.
"""

from __future__ import annotations

import signal
import threading

import numpy as np

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1)
EXIT_STOPPED = 3  # the exit code of a run stopped by a signal, its checkpoint written


class StopRequests:
    """Context manager that catches SIGNALS while a run steps."""

    def __init__(self):
        self.signum = 0  # the first signal received, 0: none
        self._previous: dict[int, object] = {}

    def __enter__(self) -> StopRequests:
        if threading.current_thread() is threading.main_thread():
            for sig in SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def _handle(self, signum, frame) -> None:
        if self.signum and signum == signal.SIGINT:  # a second Ctrl-C: stop at once
            raise KeyboardInterrupt
        self.signum = self.signum or signum

    def requested(self, comm) -> int:
        """The signal any rank received (0: none); collective under MPI."""
        if comm.size == 1:
            return self.signum
        return int(comm.max(np.array([float(self.signum)]))[0])


def name(signum: int) -> str:
    """'SIGTERM' for 15."""
    return signal.Signals(signum).name

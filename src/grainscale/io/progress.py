"""Progress of a long computation: a bar on a terminal or in a Jupyter notebook, plain
lines in a log.

Under a batch system (Slurm), or with stderr redirected to a file, a bar redrawn at
every update would write a line per update there (hundreds in seconds), so without a
terminal or a notebook the computation writes one plain line every `PLAIN_INTERVAL_S`
seconds of wall time instead, and one at the end:

    progress: step 1200, t = 0.1234 / 0.5474 s (22.5 %), 85 steps/s, ETA 0:04:58
    rve triaxial: axial strain = 0.05 / 0.2 (25.0 %), ETA 0:00:41

In a notebook the bar is tqdm's widget where ipywidgets is installed, else tqdm's text
bar redrawn in the cell's output.
"""

from __future__ import annotations

import sys
import time
from datetime import timedelta

PLAIN_INTERVAL_S = 30.0  # s of wall time between plain progress lines


def in_notebook() -> bool:
    """Whether this process is a Jupyter kernel (its stderr is no terminal, but the
    notebook redraws a bar in place)."""
    ipython = sys.modules.get("IPython")
    if ipython is None:
        return False
    shell = ipython.get_ipython() if hasattr(ipython, "get_ipython") else None
    return type(shell).__name__ == "ZMQInteractiveShell"


def _bar_class(stream):
    """tqdm's notebook widget inside a notebook with ipywidgets, else its text bar."""
    if in_notebook() and stream in (sys.stderr, sys.stdout):
        try:
            import ipywidgets  # noqa: F401
            from tqdm.notebook import tqdm
            return tqdm
        except ImportError:
            pass
    from tqdm import tqdm
    return tqdm


SETTLE_UPDATES = 5  # updates after the first before an ETA is shown
SETTLE_S = 5.0  # ... and seconds


class Progress:
    """A quantity (simulated time, strain, ...) advancing from t0 to t_end, by
    update(increment, step); `quantity` and `unit` name it in the bar and the lines,
    `label` starts each plain line. `step` None: no steps/s rate is shown."""

    def __init__(self, t0: float, t_end: float, time_now: float, step: int | None,
                 enabled: bool, stream=None, *, quantity: str = "t", unit: str = "s",
                 label: str = "progress"):
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.t0, self.t_end = t0, t_end
        self.quantity, self.unit, self.label = quantity, unit, label
        self.interactive = enabled and (self.stream.isatty() or in_notebook())
        self.bar = None
        if self.interactive:
            unit_text = f" {unit}" if unit else ""
            self.bar = _bar_class(self.stream)(
                total=t_end - t0, initial=time_now - t0, file=self.stream, unit=unit or "it",
                dynamic_ncols=True, desc=None if label == "progress" else label,
                bar_format="{l_bar}{bar}| " + quantity + "={n:.4g}/{total:.4g}" + unit_text
                           + " [{elapsed}<{remaining}{postfix}]")
        self.start = self.tick = self.last_line = time.perf_counter()
        self.start_time, self.start_step = time_now, step
        self.tick_step = step
        self.time, self.step = time_now, step
        # the rate for the ETA is measured from the end of the first update on: the first
        # holds numba's compilation (minutes where a step then takes milliseconds)
        self.warm: tuple[float, float, int, int] | None = None  # wall, quantity, updates,
        #                                                         and step there
        self.updates = 0

    def update(self, increment: float, step: int | None = None) -> None:
        self.time += increment
        self.step = step
        now = time.perf_counter()
        self.updates += 1
        if self.warm is None:
            self.warm = (now, self.time, self.updates, step or 0)
        if self.bar is not None:
            self.bar.update(min(increment, self.bar.total - self.bar.n))  # round-off
            if step is not None and now - self.tick > 1.0:
                rate = (step - self.tick_step) / (now - self.tick)
                self.bar.set_postfix_str(f"step {step}, {rate:.0f} steps/s", refresh=False)
                self.tick, self.tick_step = now, step
        elif self.enabled and now - self.last_line >= PLAIN_INTERVAL_S:
            self._line(now)

    def note(self, text: str) -> None:
        """A short status shown beside the bar (e.g. p and q/p of an element test)."""
        if self.bar is not None:
            self.bar.set_postfix_str(text, refresh=False)

    def _line(self, now: float) -> None:
        self.last_line = now
        span = self.t_end - self.t0
        done = (self.time - self.t0) / span if span > 0 else 1.0
        elapsed = now - self.start
        left = self.t_end - self.time
        eta = "?"  # until the rate has settled: a few updates and seconds after the first
        settled = (self.warm is not None and self.updates - self.warm[2] >= SETTLE_UPDATES
                   and now - self.warm[0] >= SETTLE_S)
        if settled:
            speed = (self.time - self.warm[1]) / (now - self.warm[0])
            eta = timedelta(seconds=round(left / speed)) if speed > 0 else "?"
        unit = f" {self.unit}" if self.unit else ""
        head = f"{self.label}: "
        rate = ""
        if self.step is not None:
            head += f"step {self.step}, "
            steps = ((self.step - self.warm[3]) / (now - self.warm[0]) if settled
                     else (self.step - self.start_step) / elapsed if elapsed > 0 else 0.0)
            rate = f", {steps:.0f} steps/s"
        print(f"{head}{self.quantity} = {self.time:.6g} / {self.t_end:.6g}{unit} "
              f"({100 * done:.1f} %){rate}, ETA {eta}", file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self.enabled:
            self._line(time.perf_counter())

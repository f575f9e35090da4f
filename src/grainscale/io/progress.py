"""Progress of a long run: a tqdm bar on a terminal, plain lines in a log.

Under a batch system (Slurm) stderr is a file; a bar redrawn at every update would write
a line per update there (hundreds in seconds), so without a terminal the run writes one
plain line every `PLAIN_INTERVAL_S` seconds of wall time instead, and one at the end:

    progress: step 1200, t = 0.1234 / 0.5474 s (22.5 %), 85 steps/s, ETA 0:04:58
"""

from __future__ import annotations

import sys
import time
from datetime import timedelta

from tqdm import tqdm

PLAIN_INTERVAL_S = 30.0  # s of wall time between plain progress lines


class Progress:
    """Simulated time t0 -> t_end, advanced by update(dt, step)."""

    def __init__(self, t0: float, t_end: float, time_now: float, step: int, enabled: bool,
                 stream=None):
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.t0, self.t_end = t0, t_end
        self.interactive = enabled and self.stream.isatty()
        self.bar = tqdm(total=t_end - t0, initial=time_now - t0, disable=not self.interactive,
                        file=self.stream, unit="s", dynamic_ncols=True,
                        bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} s [{elapsed}<"
                                   "{remaining}{postfix}]")
        self.start = self.tick = self.last_line = time.perf_counter()
        self.start_time, self.start_step = time_now, step
        self.tick_step = step
        self.time, self.step = time_now, step

    def update(self, dt: float, step: int) -> None:
        self.time += dt
        self.step = step
        now = time.perf_counter()
        if self.interactive:
            self.bar.update(dt)
            if now - self.tick > 1.0:
                rate = (step - self.tick_step) / (now - self.tick)
                self.bar.set_postfix_str(f"step {step}, {rate:.0f} steps/s", refresh=False)
                self.tick, self.tick_step = now, step
        elif self.enabled and now - self.last_line >= PLAIN_INTERVAL_S:
            self._line(now)

    def _line(self, now: float) -> None:
        self.last_line = now
        span = self.t_end - self.t0
        done = (self.time - self.t0) / span if span > 0 else 1.0
        elapsed = now - self.start
        rate = (self.step - self.start_step) / elapsed if elapsed > 0 else 0.0
        left = self.t_end - self.time
        speed = (self.time - self.start_time) / elapsed if elapsed > 0 else 0.0
        eta = timedelta(seconds=round(left / speed)) if speed > 0 else "?"
        print(f"progress: step {self.step}, t = {self.time:.6g} / {self.t_end:.6g} s "
              f"({100 * done:.1f} %), {rate:.0f} steps/s, ETA {eta}", file=self.stream,
              flush=True)

    def close(self) -> None:
        if self.interactive:
            self.bar.close()
        elif self.enabled:
            self._line(time.perf_counter())

"""Progress (io/progress.py): a bar where one is redrawn in place (a terminal, a Jupyter
notebook), a few plain lines in a log. Wall time comes from a fake clock, so what a log
gets does not depend on how fast (or how loaded) the machine is."""

import io
import sys
import types

import pytest

from grainscale.io import progress
from grainscale.io.progress import Progress


class Tty(io.StringIO):
    def isatty(self):
        return True


class Clock:
    """A stand-in for progress.py's time module: perf_counter() reads `now` [s]."""

    def __init__(self):
        self.now = 0.0

    def perf_counter(self):
        return self.now


@pytest.fixture
def clock(monkeypatch):
    fake = Clock()
    monkeypatch.setattr(progress, "time", fake)
    return fake


def drive(stream, clock, n=50, seconds_per_update=0.0, **kw):
    """n updates of 1/n from 0 to 1, each taking `seconds_per_update` of the fake clock."""
    bar = Progress(0.0, 1.0, 0.0, 0, enabled=True, stream=stream, **kw)
    for k in range(1, n + 1):
        clock.now += seconds_per_update
        bar.update(1.0 / n, k)
    bar.close()
    return stream.getvalue()


def test_a_log_gets_one_line_per_interval_and_one_at_the_end(clock):
    """A run shorter than PLAIN_INTERVAL_S: the final line only. One of 50 s, an update a
    second: a line at 30 s (30 of 50 steps: 60 %, 1 step/s, 20 s left) and the final."""
    text = drive(io.StringIO(), clock, quantity="axial strain", unit="", label="rve triaxial")
    assert text.count("\n") == 1 and "\r" not in text
    assert text.startswith("rve triaxial: step 50, axial strain = 1 / 1 (100.0 %)")
    assert progress.PLAIN_INTERVAL_S == 30.0
    text = drive(io.StringIO(), clock, seconds_per_update=1.0, quantity="axial strain",
                 unit="", label="rve triaxial")
    assert text.splitlines() == [
        "rve triaxial: step 30, axial strain = 0.6 / 1 (60.0 %), 1 steps/s, ETA 0:00:20",
        "rve triaxial: step 50, axial strain = 1 / 1 (100.0 %), 1 steps/s, ETA 0:00:00"]


def test_a_terminal_gets_a_bar_redrawn_in_place(clock):
    text = drive(Tty(), clock)
    assert "\r" in text and "t=" in text and "progress:" not in text


def test_a_notebook_kernel_gets_a_bar_although_its_stream_is_no_terminal(monkeypatch, clock):
    """A Jupyter kernel's stderr says it is no tty; the notebook still redraws a bar (the
    ipywidgets widget where installed, else tqdm's text bar), never plain lines."""
    ZMQInteractiveShell = type("ZMQInteractiveShell", (), {})
    fake = types.ModuleType("IPython")
    fake.get_ipython = lambda: ZMQInteractiveShell()
    monkeypatch.setitem(sys.modules, "IPython", fake)
    assert progress.in_notebook()
    text = drive(io.StringIO(), clock)
    assert "progress:" not in text and "\r" in text
    monkeypatch.setitem(sys.modules, "IPython", types.ModuleType("IPython"))
    assert not progress.in_notebook()


def test_disabled_is_silent():
    stream = Tty()
    bar = Progress(0.0, 1.0, 0.0, 0, enabled=False, stream=stream)
    bar.update(0.5, 1)
    bar.close()
    assert stream.getvalue() == ""


def test_the_eta_waits_for_the_rate_to_settle(clock):
    """A first update that takes 600 s (numba compiling) and then 0.1 s each: no ETA
    while the rate is the compile's, then the one of the steps that follow (60 updates
    of 1/100 and 6 s later: 0.39 left at 0.1 a second, 4 s), not the hour the first
    update's rate would give."""
    out = io.StringIO()
    bar = Progress(0.0, 1.0, 0.0, 0, enabled=True, stream=out)
    clock.now = 600.0
    bar.update(0.01, 1)
    bar._line(clock.now)
    assert out.getvalue().rstrip().endswith("ETA ?")
    for k in range(2, 62):
        clock.now += 0.1
        bar.update(0.01, k)
    bar._line(clock.now)
    assert out.getvalue().rstrip().endswith("10 steps/s, ETA 0:00:04")

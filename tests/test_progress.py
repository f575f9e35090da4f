"""Progress (io/progress.py): a bar where one is redrawn in place (a terminal, a Jupyter
notebook), a few plain lines in a log."""

import io
import sys
import types

from grainscale.io import progress
from grainscale.io.progress import Progress


class Tty(io.StringIO):
    def isatty(self):
        return True


def drive(stream, n=50, **kw):
    bar = Progress(0.0, 1.0, 0.0, 0, enabled=True, stream=stream, **kw)
    for k in range(1, n + 1):
        bar.update(1.0 / n, k)
    bar.close()
    return stream.getvalue()


def test_a_log_gets_one_line_per_interval_and_one_at_the_end():
    text = drive(io.StringIO(), quantity="axial strain", unit="", label="rve triaxial")
    assert text.count("\n") == 1 and "\r" not in text
    assert text.startswith("rve triaxial: step 50, axial strain = 1 / 1 (100.0 %)")


def test_a_terminal_gets_a_bar_redrawn_in_place():
    text = drive(Tty())
    assert "\r" in text and "t=" in text and "progress:" not in text


def test_a_notebook_kernel_gets_a_bar_although_its_stream_is_no_terminal(monkeypatch):
    """A Jupyter kernel's stderr says it is no tty; the notebook still redraws a bar (the
    ipywidgets widget where installed, else tqdm's text bar), never plain lines."""
    ZMQInteractiveShell = type("ZMQInteractiveShell", (), {})
    fake = types.ModuleType("IPython")
    fake.get_ipython = lambda: ZMQInteractiveShell()
    monkeypatch.setitem(sys.modules, "IPython", fake)
    assert progress.in_notebook()
    text = drive(io.StringIO())
    assert "progress:" not in text and "\r" in text
    monkeypatch.setitem(sys.modules, "IPython", types.ModuleType("IPython"))
    assert not progress.in_notebook()


def test_disabled_is_silent():
    stream = Tty()
    bar = Progress(0.0, 1.0, 0.0, 0, enabled=False, stream=stream)
    bar.update(0.5, 1)
    bar.close()
    assert stream.getvalue() == ""

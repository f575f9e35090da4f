"""The column's frame measures: flow_state.py's medians of one frame (against values
written out by hand for four points) and convergence.py's mass quantiles."""

import math

import numpy as np
import pytest

from example_scripts import load_example


def _flow_state():
    return load_example("column_collapse/flow_state.py")


@pytest.mark.parametrize("with_rves", [False, True])
def test_frame_state_of_four_points(with_rves):
    """Points 0-2 flow (speed 0.1-0.3 m/s), point 3 rests (0.01 m/s, excluded). Point 1
    carries no stress: 1/3 stress-free. p medians over 0, 100, 40 Pa: 40; sqrt(J2)/p
    (q / sqrt 3 / p) over the loaded two only: 0.5 and 0.8, median 0.65."""
    x = np.array([[0.10, 0, 0], [0.15, 0, 0], [0.21, 0, 0], [0.05, 0, 0]])
    fields = {
        "velocity": np.array([[0.1, 0, 0], [0.0, 0.2, 0], [0.0, 0, -0.3], [0.01, 0, 0]]),
        "p": np.array([100.0, 0.0, 40.0, 500.0]),
        "q": np.array([0.5 * 100 * math.sqrt(3), 0.0, 0.8 * 40 * math.sqrt(3), 9.0]),
        "eps_v": np.array([0.1, 0.3, 0.2, 0.0]),
    }
    if with_rves:
        fields["porosity"] = np.array([0.42, 0.60, 0.50, 0.40])
    r = _flow_state().frame_state(x, fields, 0.05)
    assert r["front"] == 0.21 and r["flowing"] == 3
    assert r["stress_free"] == pytest.approx(1 / 3, rel=1e-12)
    assert r["p"] == 40.0 and r["eps_v"] == pytest.approx(0.2)
    assert r["sqrt_j2_over_p"] == pytest.approx(0.65, rel=1e-12)
    assert ("porosity" in r) == with_rves
    if with_rves:
        assert r["porosity"] == pytest.approx(0.50)


def test_mass_runouts_of_the_last_frame(tmp_path):
    """convergence.py's mass measures read the last frame of a series: 100 points at
    x = 0.101 ... 0.200 m (L_i = 0.1 m). numpy's linear quantile of x at 0.95 and 0.99 is
    0.101 + 0.099 q: runout ratios 0.9505 and 0.9901 (1e-12); the first frame, all at
    the face, is not the one read."""
    from grainscale.io.vtk import PVDSeries, write_points_vtu

    conv = load_example("column_collapse/convergence.py")
    series = PVDSeries(tmp_path / "frames.pvd")
    for k, x in enumerate((np.full(100, 0.1), 0.1 + 0.001 * np.arange(1, 101))):
        pts = np.zeros((100, 3))
        pts[:, 0] = x
        write_points_vtu(tmp_path / f"frame_{k}.vtu", pts, {"p": np.zeros(100)})
        series.add(0.1 * k, tmp_path / f"frame_{k}.vtu")
    (tmp_path / "history.csv").write_text("time\n0.0\n0.1\n")  # a run's folder
    m = conv.mass_runouts(tmp_path)
    assert m["runout_mass95"] == pytest.approx((0.101 + 0.099 * 0.95 - 0.1) / 0.1, rel=1e-12)
    assert m["runout_mass99"] == pytest.approx((0.101 + 0.099 * 0.99 - 0.1) / 0.1, rel=1e-12)

"""The column-collapse history columns (coupling.outputs.history_values) on a known
arrangement of points."""

import pytest
from mpmutil import small_case

from grainscale.config.case import load_case
from grainscale.coupling.outputs import history_values
from grainscale.mpm.setup import build_state


def test_history_reports_the_thick_front(tmp_path):
    """A column at rest: runout_ratio_thick is 0 (the deposit is H_i thick up to its
    face); pushed out by a thin layer (one point row moved beyond the face), `front`
    follows the layer and `front_thick` (min_thickness above one row) does not."""
    path = small_case(tmp_path, grid="cells = [20, 2, 8]", hi="[0.5, 0.1, 0.6]",
                      solver="gravity = [0.0, 0.0, -9.81]",
                      extra='history = ["runout_ratio", "runout_ratio_thick", "front_thick"]\n'
                            "[output.column]\nlength = 0.5\nheight = 0.6\n"
                            "min_thickness = 0.06")
    case = load_case(path)
    s = build_state(case, tmp_path)
    row = history_values(case, s, s.points, {})
    assert row["runout_ratio"] == pytest.approx(0.0, abs=1e-12)
    assert row["runout_ratio_thick"] == pytest.approx(0.0, abs=1e-12)
    bottom = s.points.x[:, 2] < s.points.x[:, 2].min() + 1e-9  # one row, 2 l_p = 0.05 m
    s.points.x[bottom, 0] += 0.5
    row = history_values(case, s, s.points, {})
    assert row["runout_ratio"] == pytest.approx(1.0, abs=1e-12)
    assert row["front_thick"] == pytest.approx(0.5, abs=1e-12)

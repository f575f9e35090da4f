"""studies/column_collapse/measurement.py's failure surface and runout on synthetic
columns (the script itself reads runs: docs/validation.md §2.3)."""

import math

import numpy as np
import pytest

from example_scripts import load_example


@pytest.mark.parametrize("angle", [50.0, 60.0, 70.0])
def test_failure_surface_angle_of_a_sliding_wedge(angle):
    """A 100 x 60 mm column of points 2.5 mm apart whose wedge above the plane from the
    toe (x = L, z = 0) rising back at `angle` moves at 0.2 m/s and the rest is still:
    the fitted boundary's angle is the plane's within the point spacing's resolution
    (the boundary is found to one spacing per 5 mm layer: atan of a 2.5 mm error over
    the 60 mm height is ~2 deg); a point moving below the threshold does not count."""
    m = load_example("column_collapse/measurement.py")
    xs, zs = np.meshgrid(np.arange(1.25e-3, 0.1, 2.5e-3), np.arange(1.25e-3, 0.06, 2.5e-3))
    x0 = np.column_stack([xs.ravel(), np.full(xs.size, 0.005), zs.ravel()])
    above = x0[:, 0] > 0.1 - x0[:, 2] / math.tan(math.radians(angle))
    v = np.zeros_like(x0)
    v[above, 0] = 0.2
    v[~above, 0] = 0.05  # below the 0.1 sqrt(g H) threshold (0.077 m/s)
    s = m.failure_surface(x0, v, 0.1 * math.sqrt(9.81 * 0.06), 0.1, 0.06)
    assert s["angle_deg"] == pytest.approx(angle, abs=2.0)
    assert s["layers"] == 12  # every 5 mm layer has moving points
    assert m.failure_surface(x0, np.zeros_like(x0), 0.077, 0.1, 0.06) is None


def test_runout_at_reads_the_history_between_rows():
    m = load_example("column_collapse/measurement.py")
    h = {"t_over_tc": np.array([0.0, 1.0, 2.0, 6.995]),
         "runout_ratio": np.array([0.0, 0.2, 0.6, 1.0])}
    r = m.runout_at(h, (0.5, 2, 7, 8))
    assert r == {"0.5": 0.1, "2": 0.6, "7": 1.0, "8": None}

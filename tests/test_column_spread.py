"""studies/column_spread.py's per-layer measures: a slice two point layers thick is
measured layer by layer, each as a one-layer slice would be."""

import numpy as np
import pytest

from example_scripts import load_example

spread = load_example("column_spread.py")


def test_each_layer_is_measured_as_a_slice_of_its_own():
    spacing, length, height = 0.005, 0.1, 0.06
    x = np.linspace(0.0025, 0.1975, 100)  # 100 points of one layer, 2 mm apart
    z = np.full(100, 0.0025)
    z[0] = 0.0575  # the highest point, at the back
    near = np.column_stack([x, np.full(100, 0.0025), z])
    far = near + [0.01, 0.005, -0.01]  # the second layer: 10 mm further, 10 mm lower
    rows = spread.layer_measures(np.vstack([far, near]), length, height, spacing)
    assert len(rows) == 2
    one = spread.layer_measures(near, length, height, spacing)
    assert rows[0] == one[0]  # the near layer, whatever lies beside it
    # by hand: front = last centre + half a spacing; 99 % by linear interpolation
    assert rows[0]["front"] == pytest.approx((0.1975 + 0.0025 - 0.1) / 0.1)
    assert rows[1]["front"] == pytest.approx((0.2075 + 0.0025 - 0.1) / 0.1)
    q99 = 0.0025 + 0.99 * 99 * (0.195 / 99)
    assert rows[0]["mass99"] == pytest.approx(round((q99 - 0.1) / 0.1, 3))
    assert rows[0]["height_ratio"] == pytest.approx(1.0)
    assert rows[1]["height_ratio"] == pytest.approx(round(0.05 / 0.06, 3))

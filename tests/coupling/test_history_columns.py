"""The DEM columns of history.csv (coupling.outputs.history_values) on hand-made points:
volume-weighted over the DEM material's points, as the stress average is."""

import numpy as np
import pytest

from grainscale.config.case import load_case
from grainscale.coupling.outputs import history_values
from grainscale.coupling.rve_material import RVEMaterial
from grainscale.mpm.grid import Grid
from grainscale.mpm.materials import LinearElastic
from grainscale.mpm.points import make_points
from grainscale.mpm.step import MPMState

CASE = """
[grid]
cell_size = 0.1
cells = [2, 2, 2]
[time]
end = 1.0
[materials.m]
type = "linear_elastic"
density = 1000.0
youngs_modulus = 1e6
poisson_ratio = 0.3
[[bodies]]
shape = "box"
material = "m"
lo = [0, 0, 0]
hi = [0.1, 0.1, 0.1]
[output]
interval = 0.1
"""


class _Rves(RVEMaterial):
    """A DEM material without RVEs: history_values only asks whether a material is one
    (the per-point fields are given by hand)."""

    def __init__(self):
        pass


def test_dem_columns_are_volume_weighted(tmp_path):
    """Two DEM points of a graded grid, a fine one (initial volume 1 cm^3, now 1.1) and
    a coarse one (56 cm^3, now 50.4), and one elastic point (NaN fields, not counted).
    Expected sum V f / sum V over the DEM points with the current volumes, written out:
    porosity (1.1 * 0.35 + 50.4 * 0.45) / 51.5 = 0.447864..., where the point mean
    (0.40) describes the fine point as much as the coarse one, 46 times its volume, and
    the initial volumes would give 0.448246..."""
    (tmp_path / "case.toml").write_text(CASE)
    case = load_case(tmp_path / "case.toml")
    grid = Grid.make([0.0, 0.0, 0.0], 0.1, [2, 2, 2])
    x = np.array([[0.02, 0.02, 0.02], [0.07, 0.07, 0.07], [0.15, 0.15, 0.15]])
    pts = make_points(x, np.array([1e-6, 56e-6, 300e-6]), 1600.0, 0)
    pts.vol[:] = [1.1e-6, 50.4e-6, 290e-6]  # current: the fine point dilated, coarse compacted
    pts.mat[2] = 1
    elastic = LinearElastic("m", 1, density=1600.0, youngs_modulus=1e6, poisson_ratio=0.3)
    s = MPMState(grid=grid, points=pts, materials=[_Rves(), elastic],
                 mat_points=[np.array([0, 1]), np.array([2])])
    nan = np.nan
    fields = {"porosity": np.array([0.35, 0.45, nan]),
              "coordination": np.array([4.0, 6.0, nan]),
              "mean_rotation": np.array([0.30, 0.02, nan])}  # rad
    row = history_values(case, s, pts, fields)
    v1, v2 = 1.1, 50.4  # cm^3: the scale cancels
    for key, (f1, f2) in {"porosity": (0.35, 0.45), "coordination": (4.0, 6.0),
                          "mean_rotation": (0.30, 0.02)}.items():
        expected = (v1 * f1 + v2 * f2) / (v1 + v2)
        # a handful of operations on O(1) numbers: round-off only
        assert row[key] == pytest.approx(expected, rel=1e-14, abs=0.0), key
        # the point mean (the column before) is far off: the test has teeth
        assert abs(row[key] - 0.5 * (f1 + f2)) > 0.04 * abs(f2 - f1), key
    assert row["porosity"] == pytest.approx(0.4478640776699029, rel=1e-14)
    # the initial volumes would give 0.448246..., 4e-3 of |f2 - f1| away
    assert abs(row["porosity"] - (0.35 + 56 * 0.45) / 57) > 1e-4

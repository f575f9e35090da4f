"""Case keys that no other test reads, each checked for its effect: `output.axial_axis`
other than z, `output.column.front_quantile`, `shape = "file"` bodies, a per-axis
`grid.cell_size`."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from grainscale.analysis import read_columns
from grainscale.cli import main
from grainscale.config.case import load_case
from grainscale.mpm.setup import build_state

CUBE = """
title = "1 m elastic cube in one 2 m cell, pressed along x"
[grid]
cell_size = 2.0
cells = [1, 1, 1]
[solver]
shape = "linear"
[time]
end = 0.5
[materials.m]
type = "linear_elastic"
density = 1000.0
youngs_modulus = 1e6
poisson_ratio = 0.3
[[bodies]]
shape = "box"
material = "m"
lo = [0.0, 0.0, 0.0]
hi = [1.0, 1.0, 1.0]
[[boundaries]]
type = "roller"
face = "x-"
[[boundaries]]
type = "velocity"
face = "x+"
velocity = -0.02
[[boundaries]]
type = "roller"
face = "y-"
[[boundaries]]
type = "roller"
face = "y+"
[[boundaries]]
type = "roller"
face = "z-"
[[boundaries]]
type = "roller"
face = "z+"
[output]
interval = 0.1
axial_axis = "{axis}"
history = ["time", "axial_strain"]
"""


@pytest.mark.parametrize("axis", ["x", "z"])
def test_axial_strain_is_read_along_its_axis(tmp_path, axis):
    """The x+ nodes move at -0.02 m/s in a 2 m cell, all other faces on rollers: with
    linear shape functions the points strain homogeneously, F_xx = exp(-0.01 t) to first
    order in dt (1e-4 here) and F_zz = 1. `axial_axis = "x"` reports 1 - F_xx, 5e-3 at
    0.5 s; "z" reports 0."""
    case = tmp_path / "cube.toml"
    case.write_text(CUBE.format(axis=axis))
    assert main(["run", str(case), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    h = read_columns(tmp_path / "o" / "history.csv")
    expected = 1.0 - np.exp(-0.01 * h["time"]) if axis == "x" else 0.0 * h["time"]
    np.testing.assert_allclose(h["axial_strain"], expected, rtol=1e-3, atol=1e-12)


def test_front_quantile_reads_the_point_edges_quantile(tmp_path):
    """examples/column_collapse/mohr_coulomb.toml at its first row: 40 point edges along
    x (two points a 5 mm cell, edges 2.5 mm apart from 2.5 to 100 mm); front_quantile
    0.5 puts the front at their median, 51.25 mm, so runout_ratio = (0.05125 - 0.1)/0.1
    = -0.4875; the default 1 at the outermost edge, 0."""
    import tomllib

    import tomli_w

    base = tomllib.loads((Path(__file__).parents[1] / "examples" / "column_collapse" /
                          "mohr_coulomb.toml").read_text())
    for q, expected in ((0.5, -0.4875), (1.0, 0.0)):
        base["output"]["column"]["front_quantile"] = q
        path = tmp_path / f"q{q}.toml"
        path.write_text(tomli_w.dumps(base))
        out = tmp_path / f"q{q}"
        assert main(["run", str(path), "--out", str(out), "--max-steps", "1", "--quiet"]) == 0
        first = read_columns(out / "history.csv")["runout_ratio"][0]
        assert first == pytest.approx(expected, abs=1e-12)


def test_a_body_from_a_points_file(tmp_path):
    """`shape = "file"`: one point per `x y z volume` line of the file (relative to the
    case), its mass density x volume."""
    (tmp_path / "pts.txt").write_text("0.05 0.05 0.05 1e-4\n0.15 0.05 0.05 2e-4\n"
                                      "0.05 0.15 0.05 1.5e-4\n")
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent("""
        [grid]
        cell_size = 0.1
        cells = [2, 2, 2]
        [time]
        end = 0.01
        [materials.m]
        type = "linear_elastic"
        density = 2000.0
        youngs_modulus = 1e6
        poisson_ratio = 0.3
        [[bodies]]
        shape = "file"
        material = "m"
        path = "pts.txt"
        [output]
        interval = 0.01
        """))
    s = build_state(load_case(case), tmp_path)
    np.testing.assert_array_equal(s.points.x, [[0.05, 0.05, 0.05], [0.15, 0.05, 0.05],
                                               [0.05, 0.15, 0.05]])
    np.testing.assert_allclose(s.points.vol0, [1e-4, 2e-4, 1.5e-4], rtol=1e-15)
    np.testing.assert_allclose(s.points.m, 2000.0 * np.array([1e-4, 2e-4, 1.5e-4]),
                               rtol=1e-15)


def test_cell_size_per_axis(tmp_path):
    """grid.cell_size = [2.0, 3.0, 2.5]: the cube's single cell is 2 m along x, so the x+
    nodes at -0.02 m/s give F_xx = exp(-0.01 t) as in a cubic 2 m cell; were the sizes
    read in another order (hx = 2.5 or 3 m) the x+ face would sit at 2.5 or 3 m and the
    strain rate be 0.008 or 0.0067 /s."""
    case = tmp_path / "cube.toml"
    case.write_text(CUBE.format(axis="x").replace("cell_size = 2.0",
                                                  "cell_size = [2.0, 3.0, 2.5]"))
    s = build_state(load_case(case), tmp_path)
    np.testing.assert_array_equal(s.grid.cell_size, [2.0, 3.0, 2.5])
    assert main(["run", str(case), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    h = read_columns(tmp_path / "o" / "history.csv")
    np.testing.assert_allclose(h["axial_strain"], 1.0 - np.exp(-0.01 * h["time"]),
                               rtol=1e-3, atol=1e-12)

"""Filling shapes with points, reading them from a file."""

import numpy as np

from grainscale.mpm.grid import Grid
from grainscale.mpm.points import fill_box, fill_cylinder, read_points


def test_fill_box_volume_and_count():
    grid = Grid.make([0, 0, 0], 0.1, [10, 10, 10])
    x, vol = fill_box(grid, [0.1, 0.2, 0.0], [0.5, 0.4, 0.3], 2)
    assert len(x) == 4 * 2 * 3 * 8  # cells x 2^3
    np.testing.assert_allclose(vol.sum(), 0.4 * 0.2 * 0.3, rtol=1e-12)
    assert np.all((x > [0.1, 0.2, 0.0]) & (x < [0.5, 0.4, 0.3]))


def test_fill_cylinder_volume_converges():
    """Staircase volume of a cylinder: within 2 % of pi R^2 H at 20 points per radius."""
    grid = Grid.make([0, 0, 0], 0.05, [20, 20, 20])
    x, vol = fill_cylinder(grid, [0.5, 0.5, 0.1], 0.25, 0.5, axis=2, n=2)
    np.testing.assert_allclose(vol.sum(), np.pi * 0.25**2 * 0.5, rtol=0.02)
    r = np.hypot(x[:, 0] - 0.5, x[:, 1] - 0.5)
    assert r.max() <= 0.25 and x[:, 2].min() > 0.1 and x[:, 2].max() < 0.6


def test_read_points(tmp_path):
    p = tmp_path / "pts.txt"
    p.write_text("# x y z volume\n0.1 0.2 0.3 1e-3\n0.4 0.5 0.6 2e-3\n")
    x, vol = read_points(p)
    np.testing.assert_array_equal(x, [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    np.testing.assert_array_equal(vol, [1e-3, 2e-3])

"""Periodic grid axes: the nodal sums of a period are those of an infinite repetition,
and material leaving one end re-enters at the other."""

import numpy as np
import pytest
from mpmutil import elastic_box, small_case

from grainscale.config.base import ConfigError
from grainscale.mpm.grid import PAD, Grid
from grainscale.mpm.step import kinetic_energy, p2g, shape_functions, step


def test_a_full_period_layer_has_uniform_nodal_mass():
    """Points filling the period uniformly: every node of a row along the periodic axis
    gets the same mass, and the nodal masses of one period sum to the points' mass
    (without the fold, the end nodes would hold a fraction of the interior ones)."""
    grid = Grid.make([0, 0, 0], 0.1, [5, 3, 3], periodic=(True, False, False))
    s = elastic_box(grid, [0.0, 0.0, 0.0], [0.5 - 1e-9, 0.3, 0.3], n=2)
    assert s.points.x[:, 0].min() > 0 and s.points.x[:, 0].max() < 0.5
    shape_functions(s)
    p2g(s)
    m = s.mass.reshape(*grid.nodes[::-1])  # [k, j, i]
    rows = m[:, :, PAD:PAD + 5]  # one period of nodes
    np.testing.assert_allclose(rows, rows[:, :, :1] * np.ones((1, 1, 5)), rtol=1e-12)
    np.testing.assert_allclose(rows.sum(), s.points.m.sum(), rtol=1e-12)
    np.testing.assert_array_equal(m[:, :, PAD + 5], m[:, :, PAD])  # node N is node 0


@pytest.mark.parametrize("update", ["apic", "flip"])
def test_a_moving_layer_wraps_around(update):
    """A stress-free layer moving at uniform velocity along the periodic axis crosses the
    period several times unchanged: same velocity, no stress, positions those of a rigid
    translation taken modulo the period."""
    grid = Grid.make([0, 0, 0], 0.1, [4, 2, 2], periodic=(True, False, False))
    s = elastic_box(grid, [0.0, 0.0, 0.0], [0.4 - 1e-9, 0.2, 0.2], n=2,
                    velocity_update=update, flip=1.0)
    s.points.v[:, 0] = 3.0
    x0 = s.points.x.copy()
    e0 = kinetic_energy(s.points)
    dt = 0.5 * s.stable_dt()
    for _ in range(800):
        step(s, dt)
    travelled = 3.0 * s.time
    assert travelled > 3 * 0.4
    expected = np.mod(x0[:, 0] + travelled, 0.4)
    np.testing.assert_allclose(np.sort(s.points.x[:, 0]), np.sort(expected), atol=1e-9)
    np.testing.assert_allclose(s.points.v[:, 0], 3.0, rtol=1e-12)
    np.testing.assert_allclose(s.points.v[:, 1:], 0.0, atol=1e-12)
    assert np.abs(s.points.stress).max() < 1e-6
    assert kinetic_energy(s.points) == pytest.approx(e0, rel=1e-12)


def test_periodic_keys(tmp_path):
    from grainscale.config.case import load_case
    from grainscale.mpm.setup import build_state

    grid = 'cells = [4, 2, 2]\nperiodic = ["x"]'
    p = small_case(tmp_path, grid=grid, hi="[0.4, 0.1, 0.1]")
    s = build_state(load_case(p))
    assert s.points.x[:, 0].max() < 0.4 and s.grid.periodic.tolist() == [True, False, False]
    p = small_case(tmp_path, grid=grid, hi="[0.4, 0.1, 0.1]",
                   extra='[[boundaries]]\ntype = "roller"\nface = "x-"')
    with pytest.raises(ConfigError, match=r"boundaries\[0\].face = 'x-'.*periodic"):
        load_case(p)
    p = small_case(tmp_path, grid=grid, hi="[0.6, 0.1, 0.1]")  # beyond the period
    with pytest.raises(ConfigError, match="bodies"):
        build_state(load_case(p))

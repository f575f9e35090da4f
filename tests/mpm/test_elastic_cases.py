"""Analytic elastic cases: bar vibration, column under gravity, cube under traction."""

import numpy as np
import pytest
from mpmutil import elastic_box, rollers, run

from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid


@pytest.mark.parametrize("scheme", ["USF", "USL", "MUSL"])
def test_axial_bar_first_mode_period(scheme):
    """Fixed-free bar, nu = 0, first-mode initial velocity: T = 4 L / sqrt(E/rho).

    30 cells over L, so the spatial discretisation error of the first mode is far below
    0.1 %; 2 % (the issue's tolerance) leaves room for the time integrator only.
    """
    L, h, E, rho = 1.0, 1.0 / 30, 1e6, 1000.0
    grid = Grid.make([0, 0, 0], h, [30, 2, 2])
    s = elastic_box(grid, [0, 0, 0], [L, h, h], n=2, E=E, nu=0.0, rho=rho, cfl=0.3,
                    scheme=scheme, velocity_update="flip", flip=1.0)
    s.constraints = rollers(grid, ["y-", "y+", "z-", "z+"]) + [
        boundary.constraint(boundary.face_nodes(grid, "x-"), "fixed", None)]
    s.points.v[:, 0] = 0.01 * np.sin(np.pi * s.points.x[:, 0] / (2 * L))
    T = 4 * L / np.sqrt(E / rho)
    ts, ps = [], []
    run(s, 2.3 * T, record=lambda s: (ts.append(s.time), ps.append(s.points.m @ s.points.v[:, 0])))
    ts, ps = np.array(ts), np.array(ps)
    i = np.flatnonzero(np.sign(ps[:-1]) * np.sign(ps[1:]) < 0)
    crossings = ts[i] - ps[i] * (ts[i + 1] - ts[i]) / (ps[i + 1] - ps[i])
    assert len(crossings) >= 4
    period = 2 * np.mean(np.diff(crossings))
    assert abs(period / T - 1) < 0.02


def test_column_under_gravity_geostatic_stress():
    """Elastic column between frictionless walls (oedometric), damped to rest:
    sigma_zz = -rho g (H - z) within 2 % away from the ends (z in [0.2 H, 0.8 H]).

    Stiff (rho g H / E = 1e-4) so the column's settlement does not shift z measurably.
    """
    H, h, rho, g = 1.0, 0.1, 1000.0, 9.81
    grid = Grid.make([0, 0, 0], h, [2, 2, 12])
    s = elastic_box(grid, [0, 0, 0], [2 * h, 2 * h, H], n=2, E=1e8, nu=0.3, rho=rho,
                    gravity=np.array([0.0, 0.0, -g]), damping=0.7)
    s.constraints = rollers(grid, ["x-", "x+", "y-", "y+"]) + [
        boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None)]
    c = s.wave_speed()
    run(s, 40 * 4 * H / c)  # 40 periods of the column's first mode
    # The strain of a point whose domain lies inside one cell is the cell's (GIMP and
    # linear gradients are constant there), so the MPM stress is piecewise constant per
    # cell: compare the mean stress of each cell's points with the exact value at the
    # mean initial height of those points.
    z0 = s.points.x0[:, 2]
    cell = np.floor(z0 / h).astype(int)
    for k in range(int(0.2 * H / h), int(0.8 * H / h)):
        sel = cell == k
        expected = -rho * g * (H - z0[sel].mean())
        np.testing.assert_allclose(s.points.stress[sel, 2, 2].mean(), expected, rtol=0.02)
    from grainscale.mpm.step import kinetic_energy
    assert kinetic_energy(s.points) < 1e-8 * (rho * H * h * h) * g * H  # at rest


def test_cube_under_lateral_traction():
    """Cube on three frictionless symmetry planes, traction sigma on its +x face:
    uniaxial stress, eps_xx = sigma/E, eps_yy = eps_zz = -nu sigma/E within 1 %."""
    a, h, E, nu, sig = 0.2, 0.05, 1e7, 0.25, -1000.0
    grid = Grid.make([0, 0, 0], h, [6, 6, 6])
    s = elastic_box(grid, [0, 0, 0], [a, a, a], n=2, E=E, nu=nu, rho=1000.0, damping=0.7)
    s.constraints = rollers(grid, ["x-", "y-", "z-"])
    # the outer layer of points (within half a point spacing of the face)
    s.tractions = [boundary.make_traction(s.points.x, s.points.vol0, [a - h / 4, 0, 0],
                                          [a, a, a], [sig, 0.0, 0.0], "x+")]
    c = s.wave_speed()
    run(s, 30 * 4 * a / c)
    eps = s.points.F.mean(axis=0) - np.eye(3)
    np.testing.assert_allclose(eps[0, 0], sig / E, rtol=0.01)
    np.testing.assert_allclose(eps[1, 1], -nu * sig / E, rtol=0.01)
    np.testing.assert_allclose(eps[2, 2], -nu * sig / E, rtol=0.01)
    np.testing.assert_allclose(s.points.stress[:, 0, 0].mean(), sig, rtol=0.01)

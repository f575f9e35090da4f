"""One-sided walls with Coulomb friction (boundary.Wall) against analytic motions."""

import numpy as np
import pytest
from mpmutil import elastic_box, rollers, small_case

from grainscale.config.base import ConfigError, load_toml
from grainscale.config.case import Case
from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.step import step


def _block(gravity, floor, nu=0.3, rho=1000.0, H=0.05):
    """Elastic block 0.1 x 0.05 x H m on the z- face, geostatically pre-stressed (so the
    release shakes it little), side faces on rollers."""
    grid = Grid.make([0, 0, 0], 0.025, [24, 2, 4])
    s = elastic_box(grid, [0.05, 0, 0], [0.15, 0.05, H], n=2, E=1e6, nu=nu, rho=rho,
                    gravity=np.asarray(gravity, dtype=float))
    s.constraints = rollers(grid, ["y-", "y+"])
    floor(s, grid)
    szz = rho * min(gravity[2], 0.0) * (H - s.points.x[:, 2])
    s.points.stress[:, 2, 2] = szz
    s.points.stress[:, 0, 0] = s.points.stress[:, 1, 1] = nu / (1 - nu) * szz
    return s


def _mean_motion(s, t_end):
    M = s.points.m.sum()
    ts, vs, zs = [], [], []
    while s.time < t_end:
        step(s, s.stable_dt())
        ts.append(s.time)
        vs.append(s.points.m @ s.points.v / M)
        zs.append(s.points.m @ s.points.x[:, 2] / M)
    return np.array(ts), np.array(vs), np.array(zs)


@pytest.mark.parametrize("angle,mu", [(30.0, 0.3), (45.0, 0.5), (20.0, 0.3), (30.0, 0.0)])
def test_block_slides_down_a_frictional_incline(angle, mu):
    """Gravity tilted by the incline angle a: the block's centre of mass accelerates at
    g (sin a - mu cos a). Measured within 0.3 % (the elastic block rings a little while
    the friction acts on its base nodes); 1 % is the tolerance."""
    g, a = 9.81, np.radians(angle)
    s = _block([g * np.sin(a), 0.0, -g * np.cos(a)],
               lambda s, grid: s.walls.append(boundary.face_wall(grid, "z-", mu)))
    t, v, _ = _mean_motion(s, 0.3)
    late = t > 0.05
    acc = np.polyfit(t[late], v[late, 0], 1)[0]
    assert acc == pytest.approx(g * (np.sin(a) - mu * np.cos(a)), rel=0.01)


def test_block_sticks_below_the_friction_angle():
    """tan a < mu: static friction holds the block. Measured after 0.3 s: the centre of
    mass moved 9 um and its speed is 0.4 mm/s (the elastic block rings in shear as the
    friction loads its base), against 77 mm and 0.51 m/s for a frictionless slide."""
    g, a = 9.81, np.radians(10.0)
    s = _block([g * np.sin(a), 0.0, -g * np.cos(a)],
               lambda s, grid: s.walls.append(boundary.face_wall(grid, "z-", 0.3)))
    t, v, _ = _mean_motion(s, 0.3)
    free_slide = 0.5 * g * np.sin(a) * t[-1] ** 2
    moved = float(np.mean(s.points.x[:, 0] - s.points.x0[:, 0]))
    assert abs(moved) < 1e-3 * free_slide
    assert abs(v[-1, 0]) < 1e-2 * g * np.sin(a) * t[-1]


@pytest.mark.parametrize("separable", [True, False])
def test_block_lifts_off_a_one_sided_wall(separable):
    """Gravity pointing away from the floor: on a one-sided (separable) floor the block
    falls freely, z_c(t) = z_c(0) + g t^2 / 2; a bilateral roller holds it (the pull
    of the wall on the block that the flow-numerics issue warns about)."""
    g = 9.81

    def floor(s, grid):
        if separable:
            s.walls.append(boundary.face_wall(grid, "z-", 0.0))
        else:
            s.constraints.append(boundary.constraint(boundary.face_nodes(grid, "z-"),
                                                     "roller", 2))
    s = _block([0.0, 0.0, g], floor)
    t, v, z = _mean_motion(s, 0.04)
    if separable:
        np.testing.assert_allclose(v[:, 2], g * t, rtol=1e-9)
        # positions move with the end-of-step velocity: z_n = z_0 + sum dt_k g t_k
        dt = np.diff(np.concatenate([[0.0], t]))
        np.testing.assert_allclose(z - z[0], np.cumsum(dt * g * t) - dt[0] * g * t[0],
                                   rtol=1e-9, atol=1e-15)
    else:
        assert z[-1] - z[0] < 0.05 * 0.5 * g * t[-1] ** 2  # held: a fraction of free fall


@pytest.mark.parametrize("bc,message", [
    ('type = "friction"\nface = "z-"', "`friction`"),
    ('type = "roller"\nface = "z-"\nfriction = 0.3', "`friction`"),
    ('type = "friction"\nfriction = -0.1\nface = "z-"', "friction"),
    ('type = "fixed"\nface = "z-"\nseparable = true', "separable"),
    ('type = "friction"\nfriction = 0.3\nbox = { lo = [0, 0, 0], hi = [1, 1, 0] }', "face"),
])
def test_wall_keys_are_checked(tmp_path, bc, message):
    p = small_case(tmp_path, extra=f"[[boundaries]]\n{bc}")
    with pytest.raises(ConfigError, match=message):
        load_toml(p, Case)


def test_case_file_builds_walls(tmp_path):
    from grainscale.mpm.setup import build_state

    p = small_case(tmp_path, extra='[[boundaries]]\ntype = "friction"\nface = "z-"\n'
                   'friction = 0.4\n[[boundaries]]\ntype = "roller"\nface = "x-"\n'
                   'separable = true')
    s = build_state(load_toml(p, Case))
    assert [(w.axis, w.inward, w.friction) for w in s.walls] == [(2, 1.0, 0.4), (0, 1.0, 0.0)]
    assert not s.constraints


def test_points_that_crossed_a_wall_are_put_back_on_it():
    """The points' side of the contact: a point centre past a one-sided wall's plane
    (possible for a point at zero stress, carried by node velocities alone) returns to
    the plane and keeps only a velocity away from the wall; other points are untouched;
    a wall that has ended does nothing."""
    grid = Grid.make([0, 0, 0], 0.1, [4, 4, 4])
    x = np.array([[0.2, 0.2, -0.01], [0.2, 0.2, 0.05], [0.2, 0.2, -0.02], [0.2, 0.2, 0.41]])
    v = np.array([[1.0, 0.0, -2.0], [1.0, 0.0, -2.0], [0.0, 0.0, 3.0], [0.0, 0.0, 1.0]])
    walls = [boundary.face_wall(grid, "z-", 0.3), boundary.face_wall(grid, "z+", 0.0, 1.0)]
    boundary.keep_behind_walls(walls, 0.0, grid, x, v)
    np.testing.assert_array_equal(x[:, 2], [0.0, 0.05, 0.0, 0.4])
    np.testing.assert_array_equal(v[:, 2], [0.0, -2.0, 3.0, 0.0])
    np.testing.assert_array_equal(v[:, 0], [1.0, 1.0, 0.0, 0.0])
    x[3, 2] = 0.45
    boundary.keep_behind_walls(walls, 2.0, grid, x, v)  # the z+ wall ended at t = 1
    assert x[3, 2] == 0.45


@pytest.mark.parametrize("update", ["apic", "flip", "aflip"])
@pytest.mark.parametrize("floor", ["fixed", "wall"])
def test_the_wall_impulse_reaches_the_points(update, floor):
    """After G2P the points carry the grid's momentum, sum m_p v_p = sum m_I v_I, wall
    impulse included. FLIP's increment must be taken from the mapped grid velocity: from
    the velocity after the walls acted, a held node's increment is zero and the points
    at a wall keep the velocity the wall removed (a no-slip floor then ran a column out
    further than a frictional one)."""
    grid = Grid.make([0, 0, 0], 0.025, [8, 4, 8])
    s = elastic_box(grid, [0.05, 0.0, 0.0], [0.15, 0.1, 0.05], n=2, E=1e6,
                    velocity_update=update, flip=1.0)
    s.points.v[:] = [0.5, 0.0, -1.0]  # sliding into the floor
    if floor == "fixed":
        s.constraints = [boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None)]
    else:
        s.walls = [boundary.face_wall(grid, "z-", 0.3)]
    before = s.points.m @ s.points.v
    step(s, 0.5 * s.stable_dt())
    grid_momentum = s.mass @ s.v_new
    points = s.points.m @ s.points.v
    np.testing.assert_allclose(points, grid_momentum, atol=1e-12 * s.points.m.sum())
    assert points[2] > before[2] + 0.1 * s.points.m.sum()  # the floor took a real impulse

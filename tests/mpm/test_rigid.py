"""Rigid body: imposes its velocity, reports its reaction."""

import numpy as np
from mpmutil import elastic_box, rollers, run

from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.points import fill_box
from grainscale.mpm.rigid import RigidBody
from grainscale.mpm.step import step


def _plate(grid, lo, hi, v, ramp):
    x, vol = fill_box(grid, lo, hi, 2)
    return RigidBody(x=x, lp=0.5 * np.cbrt(vol), velocity=np.asarray(v, dtype=float),
                     ramp_time=ramp)


def test_rigid_body_in_empty_grid():
    """Far from the material: covered nodes move with the body, the reaction is zero."""
    grid = Grid.make([0, 0, 0], 0.1, [10, 6, 6])
    s = elastic_box(grid, [0.8, 0.0, 0.0], [1.0, 0.2, 0.2])  # material far away
    s.rigid = _plate(grid, [0.1, 0.2, 0.2], [0.3, 0.4, 0.4], [0.5, 0.0, -0.2], ramp=0.0)
    x0 = s.rigid.x.copy()
    dt = 1e-3
    for _ in range(20):
        step(s, dt)
        assert np.all(s.rigid.force == 0.0)
        np.testing.assert_array_equal(s.v_new[s.rigid_nodes], np.tile([0.5, 0.0, -0.2],
                                                                      (len(s.rigid_nodes), 1)))
    assert len(s.rigid_nodes) > 0
    np.testing.assert_allclose(s.rigid.x - x0, np.tile([0.5 * 0.02, 0, -0.2 * 0.02],
                                                       (len(x0), 1)), atol=1e-15)
    np.testing.assert_allclose(s.points.v, 0.0)  # the material did not notice


def test_rigid_plate_pushing_elastic_block_matches_oedometer_stiffness():
    """A plate covering the top of a laterally confined elastic block, pushed down slowly:
    F = M A d / H with the oedometric modulus M = E(1-nu)/((1+nu)(1-2nu)), within 2 %.

    Quasi-static: a 0.3 s ramp (about 55 wave transits of the block) and light local
    damping; the residual dynamic part of the force is below 1 % at this depth.
    """
    H, a, h, E, nu = 0.2, 0.2, 0.05, 1e6, 0.3
    grid = Grid.make([0, 0, 0], h, [4, 4, 6])
    s = elastic_box(grid, [0, 0, 0], [a, a, H], n=2, E=E, nu=nu, rho=1000.0, damping=0.3)
    s.constraints = rollers(grid, ["x-", "x+", "y-", "y+"]) + [
        boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None)]
    v = 2e-3
    s.rigid = _plate(grid, [0, 0, H], [a, a, H + h], [0, 0, -v], ramp=0.3)
    run(s, 0.45)
    d = -s.rigid.displacement[2]
    assert 5e-4 < d < 7e-4  # small depth: 0.3 % strain
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    expected = M * a * a * d / H
    np.testing.assert_allclose(s.rigid.force[2], expected, rtol=0.02)
    assert abs(s.rigid.force[0]) < 1e-6 * expected and abs(s.rigid.force[1]) < 1e-6 * expected


def test_musl_drucker_prager_indentation_runs_and_yields():
    """The other code paths together (MUSL, PIC blend, Drucker-Prager, rigid body): a
    punch into a cohesionless layer under gravity yields below the punch, stays finite,
    and the layer pushes back on the punch."""
    from grainscale.mpm.materials import DruckerPrager

    grid = Grid.make([0, 0, 0], 0.05, [8, 4, 6])
    s = elastic_box(grid, [0, 0, 0], [0.4, 0.2, 0.2], n=2, scheme="MUSL",
                    velocity_update="flip", flip=0.9,
                    gravity=np.array([0.0, 0.0, -9.81]))
    s.materials = [DruckerPrager("dp", s.points.n, density=1000.0, youngs_modulus=1e6,
                                 poisson_ratio=0.3, friction_angle=30.0)]
    s.constraints = rollers(grid, ["x-", "x+", "y-", "y+"]) + [
        boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None)]
    s.rigid = _plate(grid, [0.0, 0.0, 0.2], [0.1, 0.2, 0.25], [0, 0, -0.05], ramp=0.01)
    run(s, 0.15)
    assert np.all(np.isfinite(s.points.stress)) and np.all(np.isfinite(s.points.x))
    under = s.points.x0[:, 0] < 0.1
    assert s.materials[0].eps_p[under].max() > 0
    assert s.rigid.force[2] > 0

"""Rigid body: imposes its velocity, reports its reaction."""

import numpy as np
from mpmutil import elastic_box, impulse_errors, rollers, run

from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.points import fill_box, sub_cell_half_widths
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
    # the prescribed ramp and hold, d = v (t - ramp/2) = 0.6 mm (0.3 % strain); the
    # steps sample the ramp's velocity at their starts, which loses at most v dt / 2
    # (1e-7 m at dt ~ 1e-4 s): 1e-3 relative. A body moving at any other speed or ramp
    # fails (mutation tried: the ramp ignored in RigidBody.velocity_at gives 0.9 mm).
    np.testing.assert_allclose(d, v * (s.time - 0.15), rtol=1e-3)
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    expected = M * a * a * d / H
    np.testing.assert_allclose(s.rigid.force[2], expected, rtol=0.02)
    assert abs(s.rigid.force[0]) < 1e-6 * expected and abs(s.rigid.force[1]) < 1e-6 * expected


def test_rigid_plate_carries_the_weight_and_balances_momentum():
    """The other code paths together (MUSL, FLIP/PIC blend, Drucker-Prager, gravity): a
    layer on a rigid plate between frictionless lateral rollers.

    1. Settled under local damping, the plate carries the layer's whole weight: vertical
       equilibrium with frictionless sides gives F = (0, 0, -m g) exactly; 2e-3 m g
       bounds the residual oscillation after 0.3 s of damping (measured +-4e-4 over the
       last 20 % of it, 2e-5 at its end), and a reaction without the weight of the
       material mapped onto the plate's nodes (~1/8 of it) is far outside.
    2. Undamped, with the plate then pushing up: the material's momentum changes each
       step by the impulse of gravity and of the plate, P_z(n+1) - P_z(n) = -dt (m g +
       F_z) (rollers act horizontally only; internal forces sum to zero), up to the
       fixed-point rounding of the nodal sums (measured 3e-12 m g dt; bound 1e-9). A
       reaction that leaves out the momentum the plate takes from the material at the
       nodes it covers (as it once did) is off by up to 5e-2 m g dt a step here.
    """
    from grainscale.mpm.materials import DruckerPrager

    h = 0.05
    grid = Grid.make([0, 0, 0], h, [8, 4, 6])
    s = elastic_box(grid, [0, 0, h], [0.4, 0.2, h + 0.2], n=2, scheme="MUSL",
                    velocity_update="flip", flip=0.9, gravity=np.array([0.0, 0.0, -9.81]),
                    damping=0.3, damping_end=0.3)
    s.materials = [DruckerPrager("dp", s.points.n, density=1000.0, youngs_modulus=1e6,
                                 poisson_ratio=0.3, friction_angle=30.0)]
    s.constraints = rollers(grid, ["x-", "x+", "y-", "y+"])
    s.rigid = _plate(grid, [0.0, 0.0, 0.0], [0.4, 0.2, h], [0, 0, 0.05], ramp=0.02)
    s.rigid.start_time = 0.3
    weight = s.points.m.sum() * 9.81
    run(s, 0.3)
    assert abs(s.rigid.force[2] / weight + 1.0) < 2e-3, s.rigid.force[2] / weight
    assert np.all(np.abs(s.rigid.force[:2]) < 1e-9 * weight)
    errors = impulse_errors(s, 0.4, weight)
    assert s.rigid.displacement[2] > 0.004  # the plate did push
    assert np.abs(errors).max() < 1e-9, np.abs(errors).max()


def test_nodes_contact_finds_the_same_nodes_on_node_lists_and_on_a_graded_grid():
    """The nodes a body covers (`contact = "nodes"`): on a uniform grid given as node
    lists, those of the uniform grid; on a graded grid, exactly the nodes within every
    body point's domain box |X_I - x_p| <= l_p (brute force over all nodes)."""
    h = 0.1
    uniform = Grid.make([0, 0, 0], h, [10, 6, 6])
    listed = Grid.rectilinear([h * np.arange(11), h * np.arange(7), h * np.arange(7)])
    body = _plate(uniform, [0.1, 0.2, 0.2], [0.3, 0.4, 0.4], [0.5, 0.0, -0.2], ramp=0.0)
    body.x += 0.013  # off the lattice
    np.testing.assert_array_equal(body.covered_nodes(listed), body.covered_nodes(uniform))
    ax = [np.array([0.0, 0.05, 0.1, 0.15, 0.25, 0.35, 0.55]), h * np.arange(7),
          np.array([0.0, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.6])]
    graded = Grid.rectilinear(ax)
    body = _plate(graded, [0.05, 0.1, 0.1], [0.35, 0.4, 0.3], [0.0, 0.0, -0.1], ramp=0.0)
    body.lp = sub_cell_half_widths(graded, body.x, 2)  # box domains, as a case's body
    X = graded.node_positions()
    inside = np.zeros(len(X), dtype=bool)
    for x, lp in zip(body.x, body.lp, strict=True):
        inside |= np.all(np.abs(X - x) <= lp + 1e-12, axis=1)
    got = body.covered_nodes(graded)
    assert len(got) > 10
    np.testing.assert_array_equal(got, np.flatnonzero(inside))

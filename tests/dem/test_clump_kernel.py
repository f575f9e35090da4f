"""Clumps in the DEM kernel (dem/rigid.py, kernel.contact_pass with Clumps): the
rigid-body step against conservation laws and the spheres' own path, the stress against
an independent Love-Weber sum, the list without a clump's inner pairs.

In the validation tier: the clumped kernel variant is a compile of its own (~30 s cold).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grainscale.dem import clump, engine, generate
from grainscale.dem.quaternion import matrix
from grainscale.dem.state import from_clumps, from_packing
from grainscale.io.packing import read_packing
from grainscale.io.rve_vtk import contact_list

DATA = Path(__file__).resolve().parents[1] / "data"
pytestmark = pytest.mark.validation

DENSITY = 2650.0


def linear(friction=0.5, damping=0.0, **kw) -> engine.ContactParams:
    return engine.ContactParams(young=1e8, stiffness_ratio=0.5, friction=friction,
                                damping=damping, skin=2e-4, **kw)


def pair_of_rods(side=0.04):
    """Two three-sphere rods (aspect 2.5, members of radius 1.5 mm) flying at each other
    off-centre and spinning, in a cell large enough that neither meets an image."""
    rod = clump.scaled(clump.template("elongated", aspect=2.5, spheres=3), 1.5e-3)
    h = np.eye(3) * side
    centres = np.array([[0.5, 0.5, 0.5], [0.5 + 0.009 / side, 0.5 + 0.002 / side, 0.5]]) * side
    q = np.array([[1.0, 0.0, 0.0, 0.0], [np.cos(0.6), 0.2 * np.sin(0.6), 0.0, np.sin(0.6)]])
    b = from_clumps(h, centres, q, [rod, rod], DENSITY, capacity=8)
    b.bv[0, 0] = [0.3, 0.05, -0.02]
    b.bv[0, 1] = [-0.25, 0.0, 0.04]
    b.bl[0, 0] = 1e-9 * np.array([1.0, -2.0, 0.5])
    b.bl[0, 1] = 1e-9 * np.array([0.0, 1.0, 3.0])
    return b


def collide(b, cp, dt):
    """Step the pair in calls of 10 steps until it has touched and parted (the contact
    lasts ~30 steps, about 2700 steps after the start)."""
    touched = False
    for _ in range(1000):
        engine.advance(b, 10, dt, cp, engine.rate_control(1))
        if b.ncontact[0] > 0:
            touched = True
        elif touched:
            return
    raise AssertionError("the rods did not collide and part")


def momenta(b):
    """Total momentum (3,) and angular momentum about the origin (3,) of the bodies,
    sum M X x V' + Pi (no mean field: V' is the lab velocity)."""
    x = b.bs[0] @ b.h[0].T
    p = b.bm[0][:, None] * b.bv[0]
    return p.sum(axis=0), (np.cross(x, p) + b.bl[0]).sum(axis=0)


def kinetic(b):
    """(1/2) M V'^2 + (1/2) omega . I omega of the bodies, from their state [J]."""
    e = 0.5 * np.sum(b.bm[0] * np.sum(b.bv[0] ** 2, axis=1))
    rot = np.empty((3, 3))
    for k in range(b.n_bodies):
        matrix(b.bq[0, k], rot)
        e += 0.5 * np.sum(b.bj[0, k] * (rot.T @ b.bw[0, k]) ** 2)
    return e


def test_a_collision_of_clumps_keeps_both_momenta():
    """Forces and torques of a contact act at one point, equal and opposite, so the
    bodies' momentum and angular momentum are conserved by every step exactly (the
    leapfrog's X_(n+1) x V_(n+1/2) + Pi_(n+1/2) changes by dt sum (x_i x F_i + T_i), zero
    when the members sit at X + R rho): to round-off (measured 2e-16 and 7e-13 of the
    largest term; bounds 1e-12 and 1e-11), through a collision with friction that makes
    them slide and spin. The lever r_i x F_i left out of the reduction (rigid.reduce)
    moves the angular momentum by 0.17 of it (and the energy of the frictionless
    collision below by 9 %)."""
    b = pair_of_rods()
    cp = linear(friction=0.5)
    dt = engine.critical_dt(b, cp)
    p0, l0 = momenta(b)
    collide(b, cp, dt)
    p1, l1 = momenta(b)
    scale_p = np.abs(b.bm[0][:, None] * b.bv[0]).max()
    scale_l = np.abs(np.cross(b.bs[0] @ b.h[0].T, b.bm[0][:, None] * b.bv[0])).max()
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-12 * scale_p)
    np.testing.assert_allclose(l1, l0, rtol=0, atol=1e-11 * scale_l)
    assert np.abs(b.bl[0]).max() > 10 * 3e-9  # the collision spun them up


def test_a_frictionless_elastic_collision_of_clumps_keeps_its_energy():
    """Without friction, dashpot or damping the contact is a linear spring: the kinetic
    energy after the collision is the energy before, to the leapfrog's O(dt^2) error
    (measured 4.4e-5 at the safety-factor step; 1e-3 allows for contacts opened and
    closed between steps). The kernel's own kinetic energy (out[2]: translation plus
    rotation about the mean-field spin) is the bodies' (measured 2e-16; bound 1e-12)."""
    b = pair_of_rods()
    cp = linear(friction=0.0)
    dt = engine.critical_dt(b, cp)
    engine.advance(b, 1, dt, cp, engine.rate_control(1))
    e0 = kinetic(b)
    collide(b, cp, dt)
    assert kinetic(b) == pytest.approx(e0, rel=1e-3)
    assert b.kinetic[0] == pytest.approx(kinetic(b), rel=1e-12)


def spheres_as_clumps(packing):
    """The 150-sphere triaxial packing twice: as spheres, and as one-sphere clumps whose
    mass and inertia are the spheres' (the template's voxel volume replaced)."""
    h, centres, radii = read_packing(packing)
    spheres = from_packing(h, centres, radii, DENSITY)
    one = clump.template("sphere")
    grains = [clump.scaled(one, r) for r in radii]
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(radii), 1))
    clumps = from_clumps(h, centres, q, grains, DENSITY)
    clumps.bm[0] = spheres.mass[0]
    clumps.mass[0] = spheres.mass[0]
    clumps.bj[0] = spheres.inertia[0][:, None]
    clumps.inertia[0] = spheres.inertia[0]
    return spheres, clumps


def test_one_sphere_clumps_follow_the_spheres():
    """A packing of one-sphere clumps is the sphere packing: under a drained shear with
    servos, damping and a dashpot, 400 steps apart by round-off only (the body step
    rounds differently: s = S + image, w = Pi/J), far below the stress and a grain's
    motion (measured 1e-13 of p, 8e-14 of a radius, 8e-11 of the largest spin; bounds
    1e-7, 1e-9 and 1e-7, for the packing's growth of round-off). The SLLOD term of the
    body step dropped moves the stress by 1.6e-6 of p and the grains by 5e-6 of a radius,
    the damping of its rotation the stress by 1.1e-4 of p and the spins by 25 %."""
    spheres, clumps = spheres_as_clumps(DATA / "triaxial_150" / "packing.txt")
    cp = linear(friction=0.5, damping=0.2, restitution=0.5)
    dt = engine.critical_dt(spheres, cp)
    shear = np.zeros((3, 3))
    shear[0, 0] = -0.5
    shear[0, 1] = 0.3
    for b in (spheres, clumps):
        ctl = engine.rate_control(1, l_ctrl=shear, servo={1: -1e5, 2: -1e5})
        engine.advance(b, 400, dt, cp, ctl)
    p = -np.trace(spheres.stress[0]) / 3
    np.testing.assert_allclose(clumps.stress[0], spheres.stress[0], rtol=0, atol=1e-7 * p)
    ds = clumps.s[0] - spheres.s[0]
    ds -= np.round(ds)
    assert np.abs(ds @ spheres.h[0].T).max() < 1e-9 * spheres.radius.min()
    np.testing.assert_allclose(clumps.w[0], spheres.w[0], rtol=0,
                               atol=1e-7 * np.abs(spheres.w[0]).max())


@pytest.fixture(scope="module")
def packed_rods():
    """120 two-sphere clumps (aspect 1.6) consolidated to equilibrium at 100 kPa."""
    rng = np.random.default_rng(3)
    shape = clump.template("elongated", aspect=1.6, spheres=2)
    h, pos, q, grains = generate.insert_clumps(120, 1e-3, 1.4e-3, shape, 0.75, rng)
    b = from_clumps(h, pos, q, grains, DENSITY)
    cp = linear(friction=0.3, damping=0.3)
    dt = engine.critical_dt(b, cp)
    generate.consolidate(b, cp, 1e5, dt, 5.0, 0.05, 1e-4)
    return b, cp


def test_clump_stress_is_the_love_weber_sum_between_body_centres(packed_rods):
    """The kernel's stress is (1/V) sum_c (X_j - X_i) (x) f - (1/V) sum M V' (x) V', the
    branch vector between the clumps' centres of mass (contact_pass), computed here
    from the contact list of rve_vtk and the bodies' orientations (1e-9 of p: the
    sums' order). In equilibrium it is symmetric (each clump's moments balance; 1e-4 of
    p at the packing's unbalanced force), which the sum between member centres, the
    spheres' formula, is not: no clump holds its members together in that sum."""
    b, cp = packed_rods
    engine.refresh(b, cp)
    i, j, d, fn, ft = contact_list(b, cp)
    assert np.all(b.body[0, i] != b.body[0, j])  # no contact inside a clump
    rot = np.empty((3, 3))
    off = np.empty_like(b.rho[0])
    for k in range(b.n_particles):
        matrix(b.bq[0, b.body[0, k]], rot)
        off[k] = rot @ b.rho[0, k]
    n = d / np.linalg.norm(d, axis=1)[:, None]
    force = ft - fn[:, None] * n  # on member i
    branch = d - off[j] + off[i]
    vol = np.linalg.det(b.h[0])
    kin = np.einsum("b,ba,bc->ac", b.bm[0], b.bv[0], b.bv[0])
    love = (np.einsum("ca,cb->ab", branch, force) - kin) / vol
    p = -np.trace(love) / 3
    assert p == pytest.approx(1e5, rel=0.02)
    np.testing.assert_allclose(b.stress[0], love, rtol=0, atol=1e-9 * p)
    assert np.abs(love - love.T).max() < 1e-4 * p
    members = np.einsum("ca,cb->ab", d, force) / vol
    assert np.abs(members - members.T).max() > 1e-3 * p


def test_no_pair_inside_a_clump_is_listed(packed_rods):
    """Members of one clump overlap by construction; the list holds none of their pairs
    (rigid.after_build), and every listed pair of members of two clumps stays."""
    b, _ = packed_rods
    for i in range(b.n_particles):
        js = b.nbr_j[0, i, :b.nbr_count[0, i]]
        assert np.all(b.body[0, js] != b.body[0, i])
    assert b.ncontact[0] > 2 * b.n_bodies  # a jammed packing of clumps


def sheared(b, cp, steps, threads=None):
    """`steps` steps of a drained shear with servos on every RVE of b, in calls of 50."""
    import numba

    before = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(threads)
    try:
        shear = np.zeros((3, 3))
        shear[0, 0] = -0.5
        shear[0, 1] = 0.3
        dt = engine.critical_dt(b, cp)
        ctl = engine.rate_control(b.n_rve, l_ctrl=shear, servo={1: -1e5, 2: -1e5})
        for _ in range(steps // 50):
            engine.advance(b, 50, dt, cp, ctl)
    finally:
        numba.set_num_threads(before)
    return b


def test_clumped_rves_do_not_depend_on_batch_threads_or_a_saved_state(packed_rods, tmp_path):
    """Three copies of the clumped packing, perturbed differently, advanced together on
    one thread and on two, and one of them alone, end bitwise equal; so does a run
    written to a .h5 state halfway (io/rve_h5: the clump arrays with it) and read back,
    against the run that went on. The kernel's arithmetic for an RVE depends on nothing
    but that RVE."""
    from grainscale.dem.state import concatenate
    from grainscale.io.rve_h5 import read_rve_state, write_rve_state

    base, cp = packed_rods
    copies = []
    for k in range(3):
        c = base.copy()
        c.bv[0] += 1e-6 * np.random.default_rng(k).standard_normal(c.bv[0].shape)
        copies.append(c)
    one = sheared(concatenate([c.copy() for c in copies]), cp, 300, threads=1)
    two = sheared(concatenate([c.copy() for c in copies]), cp, 300, threads=2)
    alone = sheared(copies[1].copy(), cp, 300)
    for name in ("s", "v", "w", "stress", "bs", "bv", "bq", "bl", "ft"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name), err_msg=name)
        np.testing.assert_array_equal(getattr(one, name)[1], getattr(alone, name)[0],
                                      err_msg=name)
    whole = sheared(copies[2].copy(), cp, 300)
    half = sheared(copies[2].copy(), cp, 150)
    write_rve_state(tmp_path / "half.h5", half)
    resumed, _ = read_rve_state(tmp_path / "half.h5")
    assert resumed.clumped
    sheared(resumed, cp, 150)
    for name in ("s", "v", "w", "stress", "bs", "bv", "bq", "bl", "ft"):
        np.testing.assert_array_equal(getattr(resumed, name), getattr(whole, name),
                                      err_msg=name)


@pytest.mark.parametrize("k", [0, 2])
def test_a_doubled_cell_of_clumps_is_the_same_periodic_system(packed_rods, k):
    """retile.double_cell of a clumped RVE (bodies copied, each member assigned to the
    body copy its periodic image lies in): every member's placement s_i = S_b +
    h^-1 R rho_i + image_i holds exactly in the new cell, per member the forces and the
    stress are the original's at the instant of doubling, and under the same shear the
    two copies keep them so. Tolerances as tests/dem/test_retile.py's (same sums in
    another order, then round-off growing chaotically over 150 steps: measured < 1e-10 of
    the stress). A member assigned to the wrong body copy is placed a cell away: O(1)."""
    from grainscale.dem.retile import double_cell

    b, cp = packed_rods
    b = sheared(b.copy(), cp, 200)
    assert np.abs(b.image[0]).max() > 0  # some members lie across the cell's faces
    n = b.n_particles
    c = double_cell(b, 0, k)
    assert c.n_bodies == 2 * b.n_bodies and c.n_particles == 2 * n
    rot = np.empty((c.n_bodies, 3, 3))
    for q in range(c.n_bodies):
        matrix(c.bq[0, q], rot[q])
    off = np.einsum("nab,nb->na", rot[c.body[0]], c.rho[0])
    placed = c.bs[0, c.body[0]] + np.linalg.solve(c.h[0], off.T).T + c.image[0]
    np.testing.assert_allclose(placed, c.s[0], rtol=0, atol=1e-12)  # fractional
    engine.refresh(b, cp)
    engine.refresh(c, cp)
    assert c.ncontact[0] == 2 * b.ncontact[0]
    p = -np.trace(b.stress[0]) / 3
    np.testing.assert_allclose(c.stress[0], b.stress[0], rtol=0, atol=1e-12 * p)
    fmax = np.abs(b.force).max()
    for copy in (0, 1):
        np.testing.assert_allclose(c.force[0, copy * n:(copy + 1) * n], b.force[0], rtol=0,
                                   atol=1e-12 * fmax)
    shear = np.array([[0.0, 60.0, 0.0], [0.0, 0.0, 20.0], [-30.0, 0.0, 0.0]])
    dt = engine.critical_dt(b, cp)
    for _ in range(3):
        for x in (b, c):
            engine.advance(x, 50, dt, cp, engine.rate_control(1, l_ctrl=shear, max_rate=100.0))
        np.testing.assert_allclose(c.stress[0], b.stress[0], rtol=0, atol=1e-8 * p)
        assert c.ncontact[0] == 2 * b.ncontact[0]


def test_clumps_are_generated_to_a_target_porosity():
    """[rve.preparation] porosity with clumps: the compaction-friction stages (as for
    spheres) bring 150 rods of aspect 1.5, 0.437 at the real friction, to 0.39 within its
    tolerance 0.005, at 100 kPa within the consolidation's 1 %; the porosity is the
    bodies' (the union of each clump's members, not their sum)."""
    from grainscale.config.rve import RVEParams

    params = RVEParams(particles=150, radius_min=2e-3, radius_max=3e-3, density=DENSITY,
                       young_modulus=1e8, stiffness_ratio=0.8, friction=0.5, damping=0.2,
                       seed=1, clump={"template": "elongated", "aspect": 1.5, "spheres": 2},
                       preparation={"pressure": 1e5, "porosity": 0.39,
                                    "porosity_tolerance": 0.005})
    b = generate.generate(params)
    assert b.clumped and b.n_bodies == 150
    assert abs(b.porosity()[0] - 0.39) <= 0.005
    spheres = 1.0 - (4.0 / 3.0) * np.pi * np.sum(b.radius[0] ** 3) / b.volume()[0]
    assert spheres < b.porosity()[0] - 0.02  # the members overlap: their sum is more solid
    assert -np.trace(b.stress[0]) / 3 == pytest.approx(1e5, rel=0.01)

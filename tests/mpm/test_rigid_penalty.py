"""Rigid body with penalty contact: exact shapes, the contact law, its reaction."""

import numpy as np
import pytest
from mpmutil import elastic_box, impulse_errors, rollers, run

from example_scripts import load_example
from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.points import fill_box
from grainscale.mpm.rigid import BOX, CYLINDER, RigidBody, signed_distance


def _surface_samples(kind, geom, n=200):
    """Dense points on the surface of a box or a z-axis cylinder (an independent
    description of the shape: the distance to the solid is the distance to them, or
    minus it inside)."""
    u = np.linspace(0.0, 1.0, n)
    a, b = np.meshgrid(u, u, indexing="ij")
    a, b = a.ravel(), b.ravel()
    faces = []
    if kind == BOX:
        lo, hi = geom[:3], geom[3:6]
        for ax in range(3):
            o1, o2 = [k for k in range(3) if k != ax]
            for side in (lo[ax], hi[ax]):
                f = np.empty((a.size, 3))
                f[:, ax] = side
                f[:, o1] = lo[o1] + a * (hi[o1] - lo[o1])
                f[:, o2] = lo[o2] + b * (hi[o2] - lo[o2])
                faces.append(f)
    else:
        c, radius, height = geom[:3], geom[6], geom[7]
        th = 2 * np.pi * a
        faces.append(np.c_[c[0] + radius * np.cos(th), c[1] + radius * np.sin(th),
                           c[2] + height * b])
        for z in (c[2], c[2] + height):
            r = radius * np.sqrt(b)
            faces.append(np.c_[c[0] + r * np.cos(th), c[1] + r * np.sin(th),
                               np.full(a.size, z)])
    return np.vstack(faces)


def _inside(kind, geom, x):
    if kind == BOX:
        return bool(np.all(x > geom[:3]) and np.all(x < geom[3:6]))
    c = geom[:3]
    return bool(np.hypot(x[0] - c[0], x[1] - c[1]) < geom[6] and c[2] < x[2] < c[2] + geom[7])


@pytest.mark.parametrize("kind, geom", [
    (BOX, np.array([0.1, -0.2, 0.3, 0.5, 0.4, 0.6, 0.0, 0.0])),
    (CYLINDER, np.array([0.2, 0.1, 0.0, 0.0, 0.0, 1.0, 0.3, 0.5])),
])
def test_signed_distance_matches_a_sampled_surface(kind, geom):
    """At random points inside and out, |phi| equals the distance to a dense sampling of
    the surface (within its spacing: 200 samples per edge, so <= 1/200 of the size, and
    the sampled distance can only be larger), the sign tells inside from outside, and
    the normal points from the nearest surface sample to x (outside) or from x to it
    (inside)."""
    rng = np.random.default_rng(3)
    surf = _surface_samples(kind, geom)
    n = np.empty(3)
    spacing = 0.7 / 200 * 2 * np.pi  # the coarsest: the cylinder's circumference
    for x in rng.uniform(-0.4, 1.0, size=(300, 3)):
        phi = signed_distance(kind, geom, x, n)
        d = np.linalg.norm(surf - x, axis=1)
        k = int(np.argmin(d))
        assert (phi < 0) == _inside(kind, geom, x)
        assert -1e-12 <= d[k] - abs(phi) <= spacing
        assert abs(np.linalg.norm(n) - 1.0) < 1e-12
        if d[k] > 0.05:  # away from edges the nearest sample fixes the direction
            toward = (x - surf[k]) / d[k] * np.sign(phi)
            assert np.dot(n, toward) > 0.95


def _penalty_plate(lo, hi, v, ramp, **kw):
    grid_like = Grid.make([0, 0, 0], 0.05, [4, 4, 8])
    x, vol = fill_box(grid_like, [0, 0, 0], [0.1, 0.1, 0.1], 2)  # frames only
    return RigidBody(x=x, lp=0.5 * np.cbrt(vol), velocity=np.asarray(v, dtype=float),
                     ramp_time=ramp, kind=BOX, geom=np.r_[lo, hi, 0.0, 0.0],
                     contact="penalty", **kw)


def test_penalty_plate_on_elastic_block_gives_the_series_stiffness():
    """A plate covering a laterally confined elastic block, pushed down slowly: the block
    (oedometric modulus M) and the contact springs of its top layer of points act in
    series, F = d / ((H - l_p)/(M A) + 1/(N k_p)), N the points under the plate and
    k_p = kappa m_p (c / 2 l_p)^2. The material's length is H - l_p: a uGIMP domain
    translates with its point, so the load on the top face reaches the material at the
    top points' centres. Within 1 % (measured 0.05 %; the residual dynamic part of a
    0.3 s ramp with light damping). Mapping the contact force from x_p instead of the
    face gave 5 % excess. Also: the reaction is normal (frictionless plate)."""
    H, a, h, E, nu, rho = 0.2, 0.2, 0.05, 1e6, 0.3, 1000.0
    grid = Grid.make([0, 0, 0], h, [4, 4, 6])
    s = elastic_box(grid, [0, 0, 0], [a, a, H], n=2, E=E, nu=nu, rho=rho, damping=0.3)
    s.constraints = rollers(grid, ["x-", "x+", "y-", "y+"]) + [
        boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None)]
    v = 2e-3
    s.rigid = _penalty_plate([-0.1, -0.1, H], [a + 0.1, a + 0.1, H + h], [0, 0, -v], 0.3)
    run(s, 0.45)
    d = -s.rigid.displacement[2]
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    c = np.sqrt(M / rho)
    assert s.rigid.wave_speed_ref == pytest.approx(c)
    lp = h / 4
    m_p = rho * (2 * lp) ** 3
    k_p = m_p * (c / (2 * lp)) ** 2
    N = (a / (2 * lp)) ** 2
    assert s.rigid.in_contact == N
    expected = d / ((H - lp) / (M * a * a) + 1.0 / (N * k_p))
    np.testing.assert_allclose(s.rigid.force[2], expected, rtol=0.01)
    assert np.all(np.abs(s.rigid.force[:2]) < 1e-9 * abs(s.rigid.force[2]))


@pytest.mark.parametrize("z_nodes, H", [
    ([0.0, 0.1, 0.15, 0.2, 0.25, 0.3], 0.2),
    ([0.0, 1.6, 2.4, 2.8, 3.0, 3.1, 3.15, 3.175, 3.1875, 3.2, 3.225, 3.275], 3.2)])
def test_penalty_plate_on_a_graded_grid_gives_the_series_stiffness(z_nodes, H):
    """The same plate and block on a rectilinear grid: x and y cells of 0.05, 0.05 and
    0.1 m, z cells growing downward from the top, so the points under the plate have box
    domains (half-widths 0.0125-0.025 m across, l_z along z) and three masses. The
    contact springs take the half-extent along the normal, l_z, so
    k_p = kappa m_p (c / 2 l_z)^2 per point and F = d / ((H - l_z)/(M A) + 1/sum k_p),
    within 1 % as on the uniform grid. In the second grid the heaviest point is 512
    times the lightest under the plate: the contact zone's light-node rule (no force on
    nodes under 1 % of a point) must measure "a point" locally (MPMState.m_point_ref),
    or every node under the plate counts as light and the plate meets no resistance."""
    from grainscale.mpm.materials import LinearElastic
    from grainscale.mpm.points import make_points, sub_cell_half_widths
    from grainscale.mpm.step import MPMState

    a, E, nu, rho = 0.2, 1e6, 0.3, 1000.0
    xy = [0.0, 0.05, 0.1, 0.2]
    grid = Grid.rectilinear([xy, xy, z_nodes])
    x, vol = fill_box(grid, [0, 0, 0], [a, a, H], 2)
    pts = make_points(x, vol, rho, 0, lp=sub_cell_half_widths(grid, x, 2))
    mat = LinearElastic("m", pts.n, density=rho, youngs_modulus=E, poisson_ratio=nu)
    s = MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None], damping=0.3)
    s.constraints = rollers(grid, ["x-", "x+", "y-", "y+"]) + [
        boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None)]
    s.rigid = _penalty_plate([-0.1, -0.1, H], [a + 0.1, a + 0.1, H + 0.05], [0, 0, -2e-3],
                             0.3)
    top = pts.x[:, 2] == pts.x[:, 2].max()
    assert len(np.unique(pts.m[top])) == 3  # 0.05 x 0.05, 0.05 x 0.1 and 0.1 x 0.1 cells
    run(s, 0.45)
    d = -s.rigid.displacement[2]
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    c = np.sqrt(M / rho)
    lz = 0.25 * (H - z_nodes[z_nodes.index(H) - 1])
    np.testing.assert_allclose(pts.lp[top, 2], lz)
    k_p = pts.m[top] * (c / (2 * lz)) ** 2
    assert s.rigid.in_contact == top.sum()
    expected = d / ((H - lz) / (M * a * a) + 1.0 / k_p.sum())
    np.testing.assert_allclose(s.rigid.force[2], expected, rtol=0.01)


def test_penalty_reaction_is_the_impulse_the_material_receives():
    """Undamped layer under gravity on a rising penalty plate, frictionless rollers at
    the sides: the material's momentum changes each step by the impulse of gravity and
    of the plate, P(n+1) - P(n) = -dt (m g + F) (internal forces sum to zero), up to the
    forces withheld from the contact zone's nodes lighter than 1 % of a point
    (mpm/step.py; measured 1.2e-4 m g dt, bound 1e-3). A reaction that missed the weight
    mapped onto one node plane (~1/8 of it here) would be off by ~1e-1."""
    h = 0.05
    grid = Grid.make([0, 0, 0], h, [8, 4, 6])
    s = elastic_box(grid, [0, 0, h], [0.4, 0.2, h + 0.2], n=2,
                    gravity=np.array([0.0, 0.0, -9.81]), damping=0.3, damping_end=0.3)
    s.constraints = rollers(grid, ["x-", "x+", "y-", "y+"])
    s.rigid = _penalty_plate([-0.1, -0.1, -0.1], [0.5, 0.3, h], [0, 0, 0.05], 0.02,
                             damping_ratio=0.3)
    s.rigid.start_time = 0.3
    weight = s.points.m.sum() * 9.81
    run(s, 0.3)
    # settled: the plate carries the weight (2e-3: the residual oscillation after 0.3 s
    # of damping, as for the nodes contact)
    assert abs(s.rigid.force[2] / weight + 1.0) < 2e-3, s.rigid.force[2] / weight
    errors = impulse_errors(s, 0.4, weight)
    assert s.rigid.displacement[2] > 0.003
    assert np.abs(errors).max() < 1e-3, np.abs(errors).max()


def test_penalty_contact_never_pulls_and_friction_opposes_slip():
    """A point leaving the body feels nothing; one sliding along a rough face feels
    mu f_n against its slip (or the force that stops it in one step, if smaller)."""
    from grainscale.mpm.rigid import penalty_kernel

    geom = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0])  # unit box
    x = np.array([[0.5, 0.5, 1.05], [0.5, 0.5, 1.2], [0.5, 0.5, 1.05]])  # above the top
    v = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [2.0, 0.0, 0.0]])
    m = np.ones(3)
    lp = np.full((3, 3), 0.1)  # cubes: half-width 0.1 m on every axis
    ids, out, where = np.empty(3, dtype=np.int64), np.empty((3, 3)), np.empty((3, 3))
    dt = 0.01
    n = penalty_kernel(BOX, geom, np.zeros(3), x, v, m, lp, 4.0, 0.0, 0.5, dt, ids, out, where)
    assert n == 2 and list(ids[:2]) == [0, 2]  # point 1 approaches but does not touch
    fn = 4.0 / 0.1 ** 2 * 0.05  # k_p g, g = l_p - phi = 0.05: 20 N
    np.testing.assert_allclose(out[0], [0.0, 0.0, fn])
    np.testing.assert_allclose(where[0], [0.5, 0.5, 0.95])  # the point's face
    np.testing.assert_allclose(out[1], [-0.5 * fn, 0.0, fn])  # m |v_t| / dt = 200 N
    # slow slip: the friction force only stops it (m |v_t| / dt = 5 N < mu f_n)
    v[2] = [0.05, 0.0, 0.0]
    penalty_kernel(BOX, geom, np.zeros(3), x, v, m, lp, 4.0, 0.0, 0.5, dt, ids, out, where)
    np.testing.assert_allclose(out[1], [-5.0, 0.0, fn])


def test_penalty_contact_of_a_box_domain_uses_its_extent_along_the_normal():
    """A point with a box domain (a graded grid's sub-cell, half-widths 0.2, 0.2, 0.06 m)
    at 0.05 m above a face: along z it reaches 0.06 m (in contact by 0.01 m, its spring
    m omega2 / 0.06^2), not its 0.2 m in x and y; beside a side face (normal x) at
    0.15 m it reaches 0.2 m. An oblique normal n gets sqrt(sum (l_a n_a)^2)
    (points.half_extent), which is l for a cube."""
    from grainscale.mpm.points import half_extent
    from grainscale.mpm.rigid import penalty_kernel

    geom = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0])  # unit box
    x = np.array([[0.5, 0.5, 1.05], [1.15, 0.5, 0.5]])  # above the top, beside x+
    lp = np.array([[0.2, 0.2, 0.06], [0.2, 0.2, 0.06]])
    ids, out, where = np.empty(2, dtype=np.int64), np.empty((2, 3)), np.empty((2, 3))
    n = penalty_kernel(BOX, geom, np.zeros(3), x, np.zeros((2, 3)), np.ones(2), lp, 4.0,
                       0.0, 0.0, 0.01, ids, out, where)
    assert n == 2
    np.testing.assert_allclose(out[0], [0.0, 0.0, 4.0 / 0.06 ** 2 * 0.01])
    np.testing.assert_allclose(where[0], [0.5, 0.5, 0.99])
    np.testing.assert_allclose(out[1], [4.0 / 0.2 ** 2 * 0.05, 0.0, 0.0])
    d = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
    np.testing.assert_allclose(half_extent(lp[:1], d), np.sqrt((0.04 + 0.0036) / 2))
    assert half_extent(np.full((1, 3), 0.1), d)[0] == 0.1


def test_cross_section_and_its_radius():
    """S inside the grid and R: a quarter cylinder on the corner (S = pi R^2 / 4, R its
    radius), a quarter box (the seed's R_e = sqrt(4 S / pi)), a box inside the grid
    (sqrt(S / pi)), and a cylinder lying across the motion (a rectangle)."""
    from grainscale.mpm.rigid import cross_section

    glo, ghi = np.zeros(3), np.array([2.5, 2.5, 3.0])
    cyl = np.array([0.0, 0.0, 2.0, 0.0, 0.0, 1.0, 0.5, 1.0])
    S, R = cross_section(CYLINDER, cyl, 2, glo, ghi)
    assert S == pytest.approx(np.pi * 0.25 / 4, rel=1e-7) and R == 0.5
    box = np.array([0.0, 0.0, 2.0, 0.4, 0.4, 3.0, 0.0, 0.0])
    S, R = cross_section(BOX, box, 2, glo, ghi)
    assert S == pytest.approx(0.16) and R == pytest.approx(np.sqrt(4 * 0.16 / np.pi))
    box = np.array([1.0, 1.0, 2.0, 1.4, 1.2, 3.0, 0.0, 0.0])
    S, R = cross_section(BOX, box, 2, glo, ghi)
    assert S == pytest.approx(0.08) and R == pytest.approx(np.sqrt(0.08 / np.pi))
    lying = np.array([1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.5, 1.0])  # axis x, moving along z
    S, R = cross_section(CYLINDER, lying, 2, glo, ghi)
    assert S == pytest.approx(1.0 * 1.0) and R == pytest.approx(np.sqrt(1.0 / np.pi))



@pytest.mark.parametrize("extra, words", [
    ({"friction": 0.3}, ["friction = 0.3", "contact = 'penalty'"]),
    ({"contact": "penalty", "penalty": 5.0}, ["penalty", "4"]),
    ({"contact": "penalty", "damping_ratio": -0.1}, ["damping_ratio"]),
    ({"contact": "glue"}, ["contact", "nodes", "penalty"]),
])
def test_rigid_contact_keys_are_checked(extra, words):
    """Bad contact keys are refused with the key, the value and what is valid."""
    from pydantic import ValidationError

    from grainscale.config.case import RigidBoxCfg

    with pytest.raises(ValidationError) as err:
        RigidBoxCfg(shape="box", lo=[0, 0, 0], hi=[1, 1, 1], velocity=[0, 0, -1], **extra)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


@pytest.mark.validation
def test_penalty_reaction_has_no_grid_ripple():
    """studies/intrusion/ripple.py's elastic strip punch (plane strain, 0.05 m cells)
    pushed 0.12 m (2.4 cells) into the bed: with the penalty contact the reaction departs
    from a quadratic in depth by at most 5 % of its mean (measured 1.2 % to 0.14 m), while
    the nodes contact steps at every node plane (measured 6.4 %, over 5 times the
    penalty's). Deeper, the bed's corner flow (a large-strain elastic wedge) adds its own
    jumps, so the test stops at 2.4 cells."""
    ripple = load_example("intrusion/ripple.py")
    r = {c: ripple.ripple(ripple.punch("elastic", c, 0.05, 0.12)[0], 0.05)
         for c in ("penalty", "nodes")}
    assert r["penalty"]["max_percent"] < 5.0, r
    assert r["nodes"]["max_percent"] > 2.0 * r["penalty"]["max_percent"], r


@pytest.mark.validation
def test_flat_punch_on_elastic_half_space_gives_boussinesq_stiffness():
    """studies/intrusion/flat_punch.py: a frictionless rigid circular punch (quarter
    model, penalty contact) on an elastic cube of side 5 a and 7 a. With the contact
    springs taken out of the series, the cube's stiffness extrapolated to an infinite
    cube (K = K_inf + c/L) is Boussinesq's 2 a_eff E / (1 - nu^2) within 5 % (the
    issue's tolerance; measured 0.8 %, and 0.3 % from cubes of 6 a and 9 a at 2.6 times
    the cost), a_eff the radius of the disc the punch's contact points cover (6 % above
    a at 3 cells over the radius). Without the extrapolation the cubes are 28 % and 20 %
    too stiff."""
    fp = load_example("intrusion/flat_punch.py")
    rows = [fp.punch(size, 3) for size in (5.0, 7.0)]
    a_eff = rows[0]["spacing"] * np.sqrt(4.0 * rows[0]["in_contact"] / np.pi)
    assert abs(a_eff / fp.RADIUS - 1.0) < 0.1  # the disc is resolved
    ratio = fp.extrapolate(rows) / fp.boussinesq(a_eff)
    assert abs(ratio - 1.0) < 0.05, ratio


def test_the_penalty_stiffness_is_fixed_at_the_runs_first_step():
    """c_ref, the wave speed the penalty springs are scaled by, is taken at the run's
    first step, before the plate (0.1 m above the block, still) touches anything, and
    kept after the material's stiffness changes: what mpm/rigid.py and docs/mpm.md say."""
    from grainscale.mpm.step import step

    h = 0.05
    grid = Grid.make([0, 0, 0], h, [4, 4, 8])
    s = elastic_box(grid, [0, 0, 0], [0.2, 0.2, 0.2], n=2)
    s.rigid = _penalty_plate([-0.1, -0.1, 0.3], [0.3, 0.3, 0.35], [0, 0, 0], 0.0)
    c0 = s.wave_speed()
    step(s, s.stable_dt())
    assert s.rigid.in_contact == 0 and s.rigid.wave_speed_ref == c0 > 0.0
    s.materials[0].E *= 4.0  # a stiffer material later: c_ref stays
    assert s.wave_speed() == pytest.approx(2.0 * c0)
    step(s, s.stable_dt())
    assert s.rigid.wave_speed_ref == c0

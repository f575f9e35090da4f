"""Clump templates (dem/clump.py) and the rotation of rigid grains (dem/quaternion.py)
against exact solutions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grainscale.dem import clump, quaternion


def test_one_sphere_has_its_exact_volume_and_inertia():
    """The voxel integration of one unit sphere: V = 4/3 pi, J = 8/15 pi about any axis.
    The midpoint rule's error at 48 cells a radius is ~1e-4 (measured 3e-5 and 1e-4);
    2e-3 fails a template built from the members' sum (a lens counted twice, below)."""
    t = clump.template("sphere")
    assert t.volume == pytest.approx(4.0 / 3.0 * math.pi, rel=2e-3)
    np.testing.assert_allclose(t.inertia, 8.0 / 15.0 * math.pi, rtol=2e-3)
    np.testing.assert_allclose(t.offsets, 0.0, atol=1e-3)


def test_two_overlapping_spheres_count_their_lens_once():
    """Two unit spheres at centre distance d: union volume 2 (4/3 pi) - pi (4 + d)(2 - d)^2
    / 12 (the lens), centre of mass midway, members at +-d/2 along the long principal
    axis, the first (its moment the smallest: two spheres' 2 x 8/15 pi less the lens's
    share); the template's ends are the clump's: aspect (d + 2)/2."""
    t = clump.template("elongated", aspect=1.7, spheres=2)
    d = 2.0 * 0.7
    lens = math.pi * (4.0 + d) * (2.0 - d) ** 2 / 12.0
    assert t.volume == pytest.approx(8.0 / 3.0 * math.pi - lens, rel=2e-3)
    assert abs(t.offsets[:, 0]).tolist() == pytest.approx([d / 2, d / 2], abs=1e-3)
    np.testing.assert_allclose(t.offsets[:, 1:], 0.0, atol=1e-3)
    assert t.inertia[0] < 2 * 8.0 / 15.0 * math.pi  # the lens is counted once
    assert t.inertia[1] == pytest.approx(t.inertia[2], rel=2e-3)  # axisymmetric
    span = t.offsets[:, 0].max() - t.offsets[:, 0].min() + 2.0
    assert span / 2.0 == pytest.approx(1.7, rel=1e-9)


def test_touching_spheres_follow_the_parallel_axis_theorem():
    """Two unit spheres just touching (d = 2, elongated aspect 2): V = 8/3 pi and the
    transverse moment 2 (8/15 pi + 4/3 pi) by Steiner, the axial 2 x 8/15 pi."""
    t = clump.template("elongated", aspect=2.0 - 1e-9, spheres=2)
    assert t.volume == pytest.approx(8.0 / 3.0 * math.pi, rel=2e-3)
    assert t.inertia[0] == pytest.approx(16.0 / 15.0 * math.pi, rel=2e-3)
    np.testing.assert_allclose(t.inertia[1:], 2 * (8.0 / 15.0 + 4.0 / 3.0) * math.pi,
                               rtol=2e-3)


def test_tetrahedral_clump_is_isotropic_and_scales():
    """A regular tetrahedron of spheres has cubic symmetry: three equal principal moments;
    scaled by s its volume goes as s^3 and its moments as s^5."""
    t = clump.template("tetrahedral")
    assert np.ptp(t.inertia) < 2e-3 * t.inertia.mean()
    np.testing.assert_allclose(np.linalg.norm(t.offsets, axis=1),
                               1.6 * math.sqrt(3.0 / 8.0), rtol=1e-3)
    s = clump.scaled(t, 2e-3)
    assert s.volume == pytest.approx(t.volume * 8e-9, rel=1e-12)
    np.testing.assert_allclose(s.inertia, t.inertia * 3.2e-14, rtol=1e-12)


@pytest.mark.parametrize("kw,match", [({"aspect": 5.0}, "aspect = 5.0"),
                                      ({"aspect": 3.5, "spheres": 2}, "would not overlap"),
                                      ({"spheres": 1}, "spheres = 1")])
def test_bad_templates_name_the_parameter(kw, match):
    with pytest.raises(ValueError, match=match):
        clump.template("elongated", **kw)
    with pytest.raises(ValueError, match="valid names"):
        clump.template("cube")


def run(J, L, steps, dt, q=None):
    """Torque-free rotation: (orientations (steps+1,4), energies (steps,))."""
    q = np.array([1.0, 0.0, 0.0, 0.0]) if q is None else np.array(q, float)
    L = np.array(L, float)
    J = np.array(J, float)
    omega = np.empty(3)
    qs, energies = [q.copy()], []
    for _ in range(steps):
        quaternion.advance(q, L, J, np.zeros(3), dt, omega)
        qs.append(q.copy())
        energies.append(0.5 * float(L @ omega))
    return np.array(qs), np.array(energies)


def test_a_symmetric_top_precesses_at_L_over_J1():
    """Torque-free symmetric top (J1 = J2 = 1, J3 = 2) with L at 30 deg to its symmetry
    axis: the axis precesses about L at Omega_p = |L|/J1 keeping its angle (Landau &
    Lifshitz §33). With |omega| dt = 0.01 the second-order scheme's phase error after
    one turn is ~1e-5 rad and its cone angle creeps by 2e-6 deg; 1e-4 of a turn and 1e-5
    deg fail a first-order update (errors ~1e-2)."""
    J = [1.0, 1.0, 2.0]
    tilt = math.radians(30.0)
    Lvec = [math.sin(tilt), 0.0, math.cos(tilt)]
    dt = 0.01
    period = 2.0 * math.pi / 1.0  # |L| = 1, J1 = 1
    steps = int(round(period / dt))
    qs, _ = run(J, Lvec, steps, dt)
    rot = np.empty((3, 3))
    axes = []
    for q in qs:
        quaternion.matrix(q, rot)
        axes.append(rot[:, 2].copy())
    axes = np.array(axes)
    cone = np.degrees(np.arccos(axes @ np.array(Lvec)))
    assert np.ptp(cone) < 1e-5 and cone[0] == pytest.approx(30.0, abs=1e-9)
    # azimuth of the axis about L
    e1 = np.cross([0.0, 1.0, 0.0], Lvec)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(Lvec, e1)
    phi = np.unwrap(np.arctan2(axes @ e2, axes @ e1))
    assert (phi[-1] - phi[0]) / (2 * math.pi) == pytest.approx(steps * dt / period, abs=1e-4)


def test_an_asymmetric_top_keeps_its_energy_and_momentum():
    """J = (1, 2, 3) turning near its unstable middle axis (tumbling, Dzhanibekov): L is
    constant by construction and the energy (1/2) L . omega must not drift: over 20,000
    steps at |omega| dt = 0.005 it oscillates by O(dt^2) ~ 1e-5 relative; a first-order
    update drifts by ~1e-2. Each quaternion stays of unit norm (1e-14), and the grain
    does tumble: its middle axis turns over (the flips recur, so the run's last state
    may lie near the start's)."""
    qs, e = run([1.0, 2.0, 3.0], [0.02, 1.0, 0.01], 20_000, 0.01)
    assert np.ptp(e) < 1e-4 * e.mean()
    assert abs(e[-2000:].mean() - e[:2000].mean()) < 2e-5 * e.mean()
    np.testing.assert_allclose(np.linalg.norm(qs, axis=1), 1.0, atol=1e-14)
    rot = np.empty((3, 3))
    n = np.array([0.02, 1.0, 0.01]) / np.linalg.norm([0.02, 1.0, 0.01])
    middle = []
    for q in qs[::50]:
        quaternion.matrix(q, rot)
        middle.append(rot[:, 1] @ n)
    assert min(middle) < -0.9  # flipped


def test_a_constant_torque_spins_a_sphere_up_exactly():
    """J equal (a sphere), torque T about a fixed axis from rest: L = T t, the angle
    T t^2 / (2 J). The leapfrog's angle is exact for constant acceleration up to its
    half-step start (L = 0 at t = -dt/2): (T/J) dt^2 n (n + 1) / 2 after n steps, to
    round-off."""
    J = np.full(3, 0.4)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    L = np.zeros(3)
    T = np.array([0.0, 0.0, 0.2])
    omega = np.empty(3)
    dt, n = 0.01, 300
    for _ in range(n):
        quaternion.advance(q, L, J, T, dt, omega)
    angle = 2.0 * math.atan2(q[3], q[0])
    assert L[2] == pytest.approx(0.2 * n * dt, rel=1e-12)
    assert angle == pytest.approx(0.5 * 0.2 / 0.4 * dt * dt * n * (n + 1), rel=1e-9)


def test_a_quaternion_is_recovered_from_its_rotation():
    """clump.quaternion_of inverts quaternion.matrix (sign fixed by w >= 0) to round-off
    for random rotations, including the branch near a half-turn (trace ~ -1)."""
    rng = np.random.default_rng(0)
    rot = np.empty((3, 3))
    qs = list(rng.standard_normal((50, 4))) + [np.array([1e-9, 1.0, 0.0, 0.0]),
                                               np.array([0.0, 0.6, 0.0, 0.8])]
    for q in qs:
        q = q / np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        quaternion.matrix(q, rot)
        np.testing.assert_allclose(clump.quaternion_of(rot), q, atol=1e-12)


def test_a_clump_packing_survives_the_exchange_format(tmp_path):
    """Clumps written as member spheres with their clump's id (io/packing.py's fifth
    column) and read back (state.from_members) are the same grains: members at the same
    places (1e-12 of a radius, those crossing the cell's faces included: a clump's
    members are taken to one image), masses, moments and centres of mass as the voxel
    integration gives them on a grid turned with the grain (its ~1e-4 error: measured
    3e-4, and 2e-4 of a radius), orientations that place the members (the template's
    principal frame may come back turned by a symmetry)."""
    from grainscale.dem.state import from_clumps, from_members, member_positions
    from grainscale.io.packing import read_members, read_packing, write_packing

    rng = np.random.default_rng(2)
    side = 0.02
    shapes = [clump.scaled(clump.template("elongated", aspect=2.0, spheres=3), 2e-3),
              clump.scaled(clump.template("tetrahedral"), 1.5e-3)]
    grains = [shapes[k % 2] for k in range(6)]
    centres = rng.uniform(0, side, (6, 3))
    centres[0] = [0.0005, 0.0195, 0.01]  # straddles two faces
    quats = rng.standard_normal((6, 4))
    b = from_clumps(np.eye(3) * side, centres, quats, grains, 2650.0)
    x = member_positions(b)
    path = tmp_path / "clumps.txt"
    write_packing(path, b.h[0], x, b.radius[0], bodies=b.body[0])
    h, xc, radii, bodies = read_members(path)
    back = from_members(h, xc, radii, bodies, 2650.0)
    np.testing.assert_allclose(member_positions(back), x, rtol=0, atol=1e-12 * 1.5e-3)
    np.testing.assert_allclose(back.bm, b.bm, rtol=1e-3)
    np.testing.assert_allclose(back.bj, b.bj, rtol=2e-3)
    np.testing.assert_allclose(back.bs, b.bs, rtol=0, atol=1e-3 * 1.5e-3 / side)
    np.testing.assert_array_equal(back.body, b.body)
    with pytest.raises(Exception, match="a packing of clumps"):
        read_packing(path)
    path.write_text(path.read_text().replace(" 5\n", "\n", 1))
    with pytest.raises(Exception, match="4 and of 5 numbers mixed"):
        read_members(path)


@pytest.mark.parametrize(("table", "match"), [
    ({"template": "cube"}, "template"),
    ({"template": "elongated"}, "needs aspect"),
    ({"template": "elongated", "aspect": 5.0}, "aspect"),
    ({"template": "sphere", "aspect": 2.0}, "aspect = 2.0 has no effect"),
    ({"template": "tetrahedral", "spheres": 3}, "spheres = 3 has no effect"),
    ({"template": "elongated", "aspect": 4.0, "spheres": 2}, "would not overlap"),
])
def test_bad_clump_tables_name_the_key(table, match):
    """[rve.clump] refuses what it cannot build, naming the key and its valid range."""
    from grainscale.config.rve import RVEParams

    with pytest.raises(ValueError, match=match):
        RVEParams(clump=table)


@pytest.mark.parametrize("k,m", [(0, 2), (2, 3)])
def test_a_clumped_cell_taken_m_times_places_every_member_exactly(k, m):
    """retile.multiply_cell of a clumped RVE: m copies of every body, each member given
    to the body copy its periodic image lies in, so that s_i = S_b + h^-1 R rho_i +
    image_i holds with integer images in the new cell (1e-12: one rounding of the
    fractional coordinates); a member given to its own copy's body would be 1/m of a cell
    off. The padded checkpoint table of the original (to the copy's sphere and clump
    counts) reads back to the original's arrays."""
    from grainscale.dem import generate
    from grainscale.dem.quaternion import matrix
    from grainscale.dem.retile import multiply_cell
    from grainscale.dem.state import from_clumps, padded, state_arrays, unpadded

    rng = np.random.default_rng(5)
    shape = clump.template("elongated", aspect=1.6, spheres=2)
    h, pos, q, grains = generate.insert_clumps(120, 1e-3, 1.4e-3, shape, 0.75, rng)
    b = from_clumps(h, pos, q, grains, 2650.0)
    b.s[0] += 0.37  # members across the faces: their images differ from their body's
    b.bs[0] += 0.37
    assert np.abs(b.image[0]).max() == 0
    b.image[0] -= np.floor(b.s[0])
    b.s[0] -= np.floor(b.s[0])
    assert np.abs(b.image[0]).max() > 0
    c = multiply_cell(b, 0, k, m)
    assert (c.n_particles, c.n_bodies) == (m * b.n_particles, m * b.n_bodies)
    np.testing.assert_array_equal(np.bincount(c.body[0]), np.tile(np.bincount(b.body[0]), m))
    for x in (b, c):
        rot = np.empty((x.n_bodies, 3, 3))
        for j in range(x.n_bodies):
            matrix(x.bq[0, j], rot[j])
        off = np.einsum("nab,nb->na", rot[x.body[0]], x.rho[0])
        placed = x.bs[0, x.body[0]] + np.linalg.solve(x.h[0], off.T).T + x.image[0]
        np.testing.assert_allclose(placed, x.s[0], rtol=0, atol=1e-12)
    assert c.solid_volume()[0] == pytest.approx(m * b.solid_volume()[0], rel=1e-12)
    table = padded(state_arrays(b), c.n_particles, b.capacity, c.n_bodies)
    assert table["bm"].shape[1] == c.n_bodies and table["body"].shape[1] == c.n_particles
    back = unpadded(table, b.n_particles, b.n_bodies)
    for name, v in state_arrays(b).items():
        np.testing.assert_array_equal(back[name], v, err_msg=name)

"""Prescribed-velocity boundaries and tractions on the deformed surface: the set-up of
the unit element test (validation case 1) on an elastic cube."""

import numpy as np
import pytest
from mpmutil import rollers, run

from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.materials import LinearElastic
from grainscale.mpm.points import make_points
from grainscale.mpm.shape import LINEAR
from grainscale.mpm.step import MPMState


def confined_cube(area: str, v_top: float = -0.05, p: float = 1e4,
                  t_load: float = 4.0) -> MPMState:
    """A 1 m cube in one 2 m cell (linear shape functions: the velocity field is exactly
    trilinear, so the 8 points deform homogeneously), on three symmetry planes, pressed
    by a prescribed velocity of the top nodes until t_load, then held by a roller, with
    pressure p on its x+ and y+ sides."""
    grid = Grid.make([0, 0, 0], 2.0, [1, 1, 1])
    c = np.array([0.25, 0.75])
    x = np.array([[a, b, z] for a in c for b in c for z in c])
    pts = make_points(x, np.full(8, 0.125), 1000.0, 0)
    mat = LinearElastic("m", 8, density=1000.0, youngs_modulus=1e6, poisson_ratio=0.3)
    s = MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None], shape=LINEAR,
                 damping=0.7)
    s.constraints = rollers(grid, ["x-", "y-", "z-", "z+"])
    # applied after the roller, so it wins while active
    s.constraints.append(boundary.constraint(boundary.face_nodes(grid, "z+"), "velocity", 2,
                                             end_time=t_load, velocity=v_top))
    for face, lo in (("x+", [0.5, 0, 0]), ("y+", [0, 0.5, 0])):
        axis = boundary.FACES[face][0]
        t = np.zeros(3)
        t[axis] = -p
        s.tractions.append(boundary.make_traction(s.points.x, s.points.vol0, lo, [1, 1, 1], t,
                                                  face, current_area=area == "current"))
    return s


def test_velocity_boundary_drives_the_top_and_pressure_follows_the_surface():
    p = 1e4
    s = confined_cube("current", p=p)
    run(s, 4.0)
    # the velocity boundary: nodal velocity -0.05 m/s at z = 2 m over fixed grid nodes is
    # a constant true strain rate of 0.025 /s in the cube: F_zz = exp(-0.1); the explicit
    # update F <- (I + dt L) F differs by O(dt L) = 2e-4 relative over the run
    assert s.points.F[:, 2, 2].mean() == pytest.approx(np.exp(-0.1), rel=1e-3)
    run(s, 14.0)  # held: the roller keeps the top, damping brings the cube to rest
    assert s.points.F[:, 2, 2].mean() == pytest.approx(np.exp(-0.1), rel=1e-3)
    assert np.abs(s.points.v).max() < 1e-4
    # Cauchy traction on the deformed faces: in equilibrium the lateral stress is -p.
    # The face area changed by ~7 % (height -10 %, width +~3 %), so a nominal traction
    # would be off by ~7 %; 0.5 % is the residual motion after 10 s of damping.
    assert s.points.stress[:, 0, 0].mean() == pytest.approx(-p, rel=0.005)
    assert s.points.stress[:, 1, 1].mean() == pytest.approx(-p, rel=0.005)


def test_nominal_traction_keeps_the_initial_area():
    p = 1e4
    s = confined_cube("initial", p=p)
    run(s, 14.0)
    F = s.points.F.mean(axis=0)
    # nominal: force = p A0, so sigma_xx = -p A0/a with a/A0 = F_zz F_yy (for this
    # diagonal F, Nanson's formula), applied at the undeformed offset x_p + l_p: the
    # lever of the load on the x = 2 m nodes is (0.75 F_xx + 0.25)/F_xx of the surface's
    ratio = F[2, 2] * F[1, 1] * F[0, 0] / (0.75 * F[0, 0] + 0.25)
    assert s.points.stress[:, 0, 0].mean() == pytest.approx(-p / ratio, rel=0.005)
    assert abs(ratio - 1.0) > 0.05  # the check above really distinguishes the two


def test_area_ratio_is_nanson_and_defined_for_a_crushed_point():
    """a/A0 = J |F^-T N| (Nanson) for random deformations (J > 0) and three normals, to
    round-off; where F is singular the cofactor form still answers: squeezing a point to
    zero thickness along z keeps the area of its z face, squeezing it along x removes
    that face's area, and neither raises (the inverse-based form stopped a run with
    LinAlgError)."""
    rng = np.random.default_rng(1)
    F = np.eye(3) + 0.3 * rng.standard_normal((50, 3, 3))
    J = np.linalg.det(F)
    assert (J > 0).all()
    for n in (np.array([0.0, 0.0, 1.0]), np.array([-1.0, 0.0, 0.0]),
              np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0)):
        inv_t = np.linalg.solve(np.swapaxes(F, 1, 2), np.broadcast_to(n, (50, 3))[..., None])
        ref = J * np.linalg.norm(inv_t[..., 0], axis=1)
        np.testing.assert_allclose(boundary.area_ratio(F, n), ref, rtol=1e-12)
    crushed = np.array([np.diag([1.0, 1.0, 0.0]), np.diag([0.0, 1.0, 1.0])])
    np.testing.assert_array_equal(boundary.area_ratio(crushed, np.array([0.0, 0.0, 1.0])),
                                  [1.0, 0.0])


def test_a_traction_acts_between_its_start_and_end_times(tmp_path):
    """`[[tractions]]` with start_time and end_time on a free elastic block (no gravity,
    no boundary): its momentum is zero before the window, then grows by the nominal
    force F = t A0 per step whose start lies in [start_time, end_time) times that step,
    and stays at that impulse after the window (the internal forces sum to zero), within
    1e-6 of it: the nodes lighter than MASS_TOL carry no velocity, which drops up to
    ~1e-8 of the impulse in a step with APIC and GIMP (tests/mpm/test_transfer.py;
    measured 1.8e-7 in all). A window read off by one step changes it by ~8 %."""
    from mpmutil import run

    from grainscale.config.case import load_case
    from grainscale.mpm.setup import build_state

    case = tmp_path / "case.toml"
    case.write_text("""
[grid]
cell_size = 0.05
cells = [8, 4, 4]
[time]
end = 0.02
[materials.m]
type = "linear_elastic"
density = 1000.0
youngs_modulus = 1e6
poisson_ratio = 0.3
[[bodies]]
shape = "box"
material = "m"
lo = [0.15, 0.05, 0.05]
hi = [0.25, 0.15, 0.15]
[[tractions]]
lo = [0.225, 0.0, 0.0]
hi = [0.25, 0.2, 0.2]
surface = "x+"
traction = [-2000.0, 0.0, 0.0]
area = "initial"
start_time = 0.004
end_time = 0.012
[output]
interval = 0.01
""")
    s = build_state(load_case(case), tmp_path)
    (t,) = s.tractions
    force = t.force[:, 0].sum()  # N, -2000 Pa on 0.01 m^2
    assert force == pytest.approx(-20.0, rel=1e-12)
    impulse, rows = 0.0, []

    def record(state):
        rows.append((state.time, state.points.m @ state.points.v[:, 0], impulse))

    def step_impulse(state):
        nonlocal impulse
        t_start = state.time - state.last_dt
        if 0.004 <= t_start < 0.012:
            impulse += force * state.last_dt
        record(state)

    run(s, 0.02, record=step_impulse)
    times = np.array([r[0] for r in rows])
    momentum = np.array([r[1] for r in rows])
    expected = np.array([r[2] for r in rows])
    assert np.all(momentum[times <= 0.004] == pytest.approx(0.0, abs=1e-12))
    assert impulse == pytest.approx(-20.0 * 0.008, rel=0.1)
    np.testing.assert_allclose(momentum, expected, rtol=0, atol=1e-6 * abs(impulse))

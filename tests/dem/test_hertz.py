"""The Hertz-Mindlin contact law (dem/hertz.py) against Hertz's and Mindlin's solutions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dem_helpers import contact_interval

from grainscale.config.rve import RVEParams
from grainscale.dem import engine, hertz
from grainscale.dem.state import from_packing
from grainscale.io.rve_vtk import contact_list

COMPILE_AHEAD = ("hertz",)  # tests/warm_kernels.py compiles its kernel variant early

DENSITY = 2500.0
YOUNG = 70e9  # glass
NU = 0.22
R1, R2 = 1.0e-3, 1.5e-3


def law(**kw) -> engine.ContactParams:
    return engine.ContactParams(**{"young": YOUNG, "stiffness_ratio": 0.8, "friction": 0.5,
                                   "damping": 0.0, "skin": 0.2e-3,
                                   "contact_law": "hertz_mindlin", "poisson": NU, **kw})


def two_spheres(x1, x2, side=10e-3):
    return from_packing(np.eye(3) * side, np.array([x1, x2], float), np.array([R1, R2]),
                        DENSITY, capacity=4)


def gap(b) -> float:
    ds = b.s[0, 1] - b.s[0, 0]
    ds -= np.round(ds)
    return float(np.linalg.norm(b.h[0] @ ds)) - (R1 + R2)


def collide(p, v0, dt):
    """Head-on collision at approach speed v0 [m/s] with zero total momentum: (contact
    duration by interpolated gap crossings [s], -v_rel,out / v_rel,in, steps in contact)."""
    b = two_spheres([3e-3, 5e-3, 5e-3], [3e-3 + R1 + R2 + 1e-7, 5e-3, 5e-3])
    m1, m2 = b.mass[0]
    b.v[0, 0, 0] = v0 * m2 / (m1 + m2)
    b.v[0, 1, 0] = -v0 * m1 / (m1 + m2)
    ctrl = engine.rate_control(1)
    gaps = [gap(b)]
    for _ in range(100_000):
        engine.advance(b, 1, dt, p, ctrl)
        gaps.append(gap(b))
        if min(gaps) < 0 and gaps[-1] > 1e-7:
            break
    t_in, t_out, k0, k1 = contact_interval(gaps)
    vout = b.v[0, 1, 0] - b.v[0, 0, 0]  # separating: > 0
    assert abs(b.mass[0] @ b.v[0, :, 0]) < 1e-12 * m1 * v0  # momentum kept
    return (t_out - t_in) * dt, vout / v0, k1 - k0


@pytest.mark.parametrize("v0", [0.05, 0.5])
def test_collision_lasts_hertz_time_and_keeps_its_energy(v0):
    """Elastic collision: Hertz's duration t_c = 2.94328 delta_max / v0 with delta_max =
    (15 m* v0^2 / (16 E* sqrt(R*)))^(2/5) (hertz.contact_time), which falls as
    v0^(-1/5), and no energy lost (rebound speed = impact speed).

    ~800 steps a contact: leapfrog's phase error is O((omega dt)^2) ~ 1e-5 and the
    interpolated crossings O(dt^2), so 0.2 % on t_c is wide; a linear spring of any
    stiffness gives a duration independent of v0 (the tenfold speed would then fail one
    of the two cases by 37 %), and E for E* moves t_c by 24 %. Energy: the leapfrog is
    symplectic, so the rebound speed returns to ~(omega dt)^2 = 1e-5; 1e-4 allows it."""
    p = law()
    b = two_spheres([0, 0, 0], [0.005, 0, 0])
    m1, m2 = b.mass[0]
    tc = hertz.contact_time(YOUNG, NU, R1, R2, m1, m2, v0)
    duration, ratio, steps = collide(p, v0, tc / 800)
    assert steps > 700
    assert duration == pytest.approx(tc, rel=2e-3)
    assert ratio == pytest.approx(1.0, abs=1e-4)


@pytest.mark.parametrize("e", [0.3, 0.6, 0.9])
def test_restitution_of_the_hertzian_dashpot_at_two_speeds(e):
    """c_n = 2 beta sqrt(m* k_n), k_n the tangent stiffness: the rebound ratio is e at
    impact speeds a decade apart (the dashpot's point: a linear one would restitute
    differently on a Hertzian spring at each speed). The leapfrog's dashpot lags dt/2;
    at ~800 steps a contact the linear law's same lag costs < 0.4 % (test_contact_law),
    so 1 %; beta without sqrt(5/6) (the linear gamma) gives 0.26, 0.56, 0.89."""
    p = law(restitution=e)
    b = two_spheres([0, 0, 0], [0.005, 0, 0])
    m1, m2 = b.mass[0]
    for v0 in (0.05, 0.5):
        tc = hertz.contact_time(YOUNG, NU, R1, R2, m1, m2, v0)
        _, ratio, _ = collide(p, v0, tc / 800)
        assert ratio == pytest.approx(e, rel=0.01)


def _restitution(beta: float) -> float:
    """e of x'' = -(2/3) x^(3/2) - 2 beta x^(1/4) x', x(0) = 0, x'(0) = 1 (units m* =
    k_n / sqrt(delta) = v0 = 1, in which e depends on beta alone): RK4, 1e-4 steps."""
    def acc(x, u):
        xp = max(x, 0.0)
        return -(2.0 / 3.0) * xp**1.5 - 2.0 * beta * xp**0.25 * u

    x, u, h = 0.0, 1.0, 1e-4
    while True:
        k1 = (u, acc(x, u))
        k2 = (u + 0.5 * h * k1[1], acc(x + 0.5 * h * k1[0], u + 0.5 * h * k1[1]))
        k3 = (u + 0.5 * h * k2[1], acc(x + 0.5 * h * k2[0], u + 0.5 * h * k2[1]))
        k4 = (u + h * k3[1], acc(x + h * k3[0], u + h * k3[1]))
        xn = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        un = u + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        if xn <= 0.0:
            return -(u + (un - u) * x / (x - xn))
        x, u = xn, un


@pytest.mark.parametrize("e", [0.1, 0.5, 0.95])
def test_tsuji_ratio_restitutes_e_in_the_continuous_collision(e):
    """beta = sqrt(5/6) gamma (engine.ContactParams.gamma of the Hertzian law) against an
    independent integration of the collision it damps: RK4 converges as h^4 but the x^(1/4) term
    is not smooth at the ends, which leaves ~3e-6 at h = 1e-4; 1e-4 is the bound, and a
    5 % error in beta moves e by > 5e-3."""
    assert _restitution(law(restitution=e).gamma) == pytest.approx(e, rel=1e-4)


def test_tangential_loading_follows_mindlin_to_first_order():
    """Constant overlap, tangential sliding imposed (both spheres spun, centres held, as
    test_contact_law's stick-slip): the force rises with Mindlin's initial stiffness
    k_t = 8 G* a and stops at mu f_n, f_n = (4/3) E* sqrt(R*) delta^(3/2).

    Mindlin's solution with micro-slip (Johnson §7.2), f_t = mu f_n [1 - (1 - u/u_s)^(3/2)],
    u_s = 3 mu f_n / (16 G* a), has the same slope at u = 0 and the same limit; in
    between the no-micro-slip law (YADE's Law2_ScGeom_MindlinPhys_Mindlin) lies above it,
    by u / (4 u_s) to first order: within 1.5 % at u < u_s / 20, and never below it. The
    steps' increments are exact springs, so the slope is checked to 1e-9."""
    delta = 2e-6
    x1 = np.array([4e-3, 5e-3, 5e-3])
    b = two_spheres(x1, x1 + [R1 + R2 - delta, 0.0, 0.0])
    s0 = b.s.copy()
    mu = 0.3
    p = law(friction=mu)
    rs = R1 * R2 / (R1 + R2)
    a = math.sqrt(rs * delta)
    es = hertz.effective_modulus(YOUNG, NU)
    gs = hertz.effective_shear_modulus(YOUNG, NU)
    fn = 4.0 / 3.0 * es * math.sqrt(rs) * delta**1.5
    kt = 8.0 * gs * a
    dt = 1e-7
    omega = 2.0  # rad/s: slides (R1 + R2 - delta) omega dt a step
    slide = (R1 + R2 - delta) * omega * dt
    ctrl = engine.rate_control(1)
    ft = []
    for _ in range(int(1.5 * mu * fn / (kt * slide))):
        b.s[:] = s0
        b.v[:] = 0.0
        b.w[:] = 0.0
        b.w[0, :, 2] = omega
        engine.advance(b, 1, dt, p, ctrl)
        b.s[:] = s0
        b.v[:] = 0.0
        engine.refresh(b, p)
        assert b.force[0, 0, 0] == pytest.approx(-fn, rel=1e-9)
        ft.append(-b.force[0, 0, 1])
    ft = np.array(ft)
    u = slide * np.arange(1, len(ft) + 1)
    us = 3.0 * mu * fn / (16.0 * gs * a)
    mindlin = mu * fn * (1.0 - (1.0 - np.minimum(u / us, 1.0)) ** 1.5)
    assert ft[0] / u[0] == pytest.approx(kt, rel=1e-9)
    small = u < us / 20
    assert small.sum() > 5
    np.testing.assert_allclose(ft[small], mindlin[small], rtol=0.015)
    assert np.all(ft >= mindlin * (1 - 1e-12))
    assert ft[-1] == pytest.approx(mu * fn, rel=1e-12)


def test_moduli_are_the_tangent_network_stiffness():
    """The moduli the kernel stores for the MPM (CFL bound, adaptive predictor) are
    (1/V) sum |d|^2 [kn n_a^2 n_b^2 + kt (...)] plus the turning bound |d| n_a^2 (|f_n| +
    |f_t|), with kn, kt the Hertzian tangent stiffnesses at the current overlap: for one
    contact along x in a cubic cell C_xxxx = (kn |d|^2 + |d| f_n) / V, C_yyyy = 0 (the
    secant stiffness, 2/3 kn, would fail by 33 % of the first term); the stress is
    -f_n |d| / V. Same sums in one order: 1e-9."""
    delta = 3e-6
    x1 = np.array([4e-3, 5e-3, 5e-3])
    b = two_spheres(x1, x1 + [R1 + R2 - delta, 0.0, 0.0])
    p = law()
    engine.refresh(b, p)
    rs = R1 * R2 / (R1 + R2)
    kn = 2.0 * hertz.effective_modulus(YOUNG, NU) * math.sqrt(rs * delta)
    d = R1 + R2 - delta
    vol = 1e-6
    fn = 2.0 / 3.0 * kn * delta
    assert b.stress[0, 0, 0] == pytest.approx(-fn * d / vol, rel=1e-9)
    assert b.stiffness[0, 0, 0] == pytest.approx((kn * d * d + d * fn) / vol, rel=1e-9)
    assert b.stiffness[0, 1, 1] == 0.0


def test_a_frictionless_packing_keeps_its_hertzian_energy():
    """27 spheres on a squeezed cubic lattice (overlaps up to ~4 % of R*) with random
    velocities, no damping, no friction: kinetic plus elastic energy, sum (2/5) f_n delta
    (the Hertz potential, whose derivative is f_n = (4/3) E* sqrt(R*) delta^(3/2)),
    stays constant while the grains exchange most of it. The leapfrog's velocities lag
    the positions by dt/2, so they are brought to the positions' time, v + (dt/2) F/m,
    before the kinetic energy is taken (as test_kinematics does): the total then holds
    to ~4e-5 (measured); 1e-3. A force inconsistent with the potential (k_n delta for
    (2/3) k_n delta) breaks the balance by tens of %."""
    rng = np.random.default_rng(3)
    spacing = 1.98e-3
    g = np.arange(3) * spacing + 1e-3
    pos = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    radii = rng.uniform(0.995e-3, 1.0e-3, len(pos))
    b = from_packing(np.eye(3) * 3 * spacing, pos, radii, DENSITY, capacity=12)
    b.v[0] = rng.normal(0.0, 0.05, (len(pos), 3))
    p = law(friction=0.0, max_overlap=0.2)
    dt = engine.critical_dt(b, p, 0.05)
    ctrl = engine.rate_control(1)

    def energies():
        v = b.v[0].copy()
        engine.refresh(b, p)  # forces of the current positions, v left as it is
        v += 0.5 * dt * b.force[0] / b.mass[0][:, None]
        i, j, d, fn, _ = contact_list(b, p)
        delta = b.radius[0][i] + b.radius[0][j] - np.linalg.norm(d, axis=1)
        return 0.5 * float(b.mass[0] @ (v**2).sum(1)), 0.4 * float(fn @ delta)

    kin0, pot0 = energies()
    assert pot0 > 0.2 * kin0
    total = []
    kinetic = []
    for _ in range(40):
        engine.advance(b, 50, dt, p, ctrl)
        k, u = energies()
        total.append(k + u)
        kinetic.append(k)
    assert np.ptp(total) < 1e-3 * (kin0 + pot0)
    assert abs(np.mean(total) - (kin0 + pot0)) < 1e-3 * (kin0 + pot0)
    assert np.ptp(kinetic) > 0.2 * (kin0 + pot0)  # the grains did exchange it


def test_an_overlap_past_the_bound_stops_the_run():
    """The time step is set for overlaps up to rve.numerics.max_overlap of R*; a larger
    one is an error naming the key, not a silent instability."""
    delta = 3e-5  # delta / R* = 0.05
    x1 = np.array([4e-3, 5e-3, 5e-3])
    b = two_spheres(x1, x1 + [R1 + R2 - delta, 0.0, 0.0])
    with pytest.raises(engine.RVEError, match="max_overlap = 0.01"):
        engine.refresh(b, law())
    engine.refresh(b, law(max_overlap=0.1))


def test_time_step_follows_the_hertzian_bound():
    """critical_dt = safety sqrt(m_min / (E* r_max sqrt(max_overlap))) (engine.py)."""
    b = two_spheres([0, 0, 0], [0.005, 0, 0])
    p = law(max_overlap=0.04)
    es = hertz.effective_modulus(YOUNG, NU)
    expected = 0.3 * math.sqrt(b.mass[0].min() / (es * R2 * 0.2))
    assert engine.critical_dt(b, p, 0.3) == pytest.approx(expected, rel=1e-12)


def test_case_keys_of_the_law():
    """contact_law = 'hertz_mindlin' needs poisson_ratio and refuses stiffness_ratio; the
    linear law refuses poisson_ratio; a linear table's packing recipe has no new keys."""
    with pytest.raises(ValueError, match="needs poisson_ratio"):
        RVEParams(contact_law="hertz_mindlin")
    with pytest.raises(ValueError, match="stiffness_ratio = 0.5 has no effect"):
        RVEParams(contact_law="hertz_mindlin", poisson_ratio=0.2, stiffness_ratio=0.5)
    with pytest.raises(ValueError, match="poisson_ratio = 0.2 has no effect"):
        RVEParams(poisson_ratio=0.2)
    with pytest.raises(ValueError, match="poisson_ratio"):
        RVEParams(contact_law="hertz_mindlin", poisson_ratio=0.5)
    with pytest.raises(ValueError, match="numerics.max_overlap = 0.02 has no effect"):
        RVEParams(numerics={"max_overlap": 0.02})
    key = RVEParams().recipe()
    assert "contact_law" not in key and "max_overlap" not in key["numerics"]
    hz = RVEParams(contact_law="hertz_mindlin", poisson_ratio=0.2).recipe()
    assert hz["contact_law"] == "hertz_mindlin" and "stiffness_ratio" not in hz


def test_a_hertzian_packing_is_generated_at_its_pressure():
    """generate() with the Hertz-Mindlin law: a static packing at the target pressure
    (each stress component within the servo's 1 % of it, as consolidate() requires) whose
    largest overlap is the Hertzian one of that pressure (hertz.largest_overlap within a
    factor 2: 100 spheres scatter more than 800), far below max_overlap."""
    from grainscale.dem.generate import contact_params, generate

    params = RVEParams(particles=100, contact_law="hertz_mindlin", young_modulus=70e9,
                       poisson_ratio=0.25, preparation={"pressure": 50e3})
    b = generate(params)
    assert np.allclose(b.stress[0], -50e3 * np.eye(3), atol=0.01 * 50e3)
    cp = contact_params(params)
    i, j, d, _, _ = contact_list(b, cp)
    ri, rj = b.radius[0][i], b.radius[0][j]
    ovl = ((ri + rj - np.linalg.norm(d, axis=1)) * (ri + rj) / (ri * rj)).max()
    est = hertz.largest_overlap(50e3, 70e9, 0.25)
    assert 0.5 * est < ovl < 2.0 * est
    assert ovl < 0.3 * cp.max_overlap
    # the contacts the VTK snapshot writes (rve_vtk.contact_list) are the kernel's:
    # (1/V) sum d (x) f of them is its Love-Weber stress once the grains are at rest
    b.v[:] = 0.0
    b.w[:] = 0.0
    engine.refresh(b, cp)
    i, j, d, fn, ft = contact_list(b, cp)
    n = d / np.linalg.norm(d, axis=1)[:, None]
    f = ft - fn[:, None] * n  # the force on i
    sigma = np.einsum("ca,cb->ab", d, f) / np.linalg.det(b.h[0])
    np.testing.assert_allclose(sigma, b.stress[0], rtol=0, atol=1e-9 * 50e3)

"""The mu(I) rheology (mpm/materials/mu_i.py): driven point by point, then in a case.

Glass beads of Jop, Forterre & Pouliquen 2006: mu_s = tan 20.9 deg, mu_2 = tan 32.76 deg,
I_0 = 0.279, d = 0.53 mm, rho_s = 2450 kg/m^3, bulk density 0.6 rho_s. E = 1e7 Pa makes
the elastic shear strain tau/G ~ 1e-4 at p = 1 kPa.
"""

import math
import textwrap

import numpy as np
import pytest
from mpmutil import run

from grainscale.config.base import ConfigError
from grainscale.config.case import load_case
from grainscale.io.checkpoint import read_checkpoint, write_checkpoint
from grainscale.mpm.materials import KINDS, MuI
from grainscale.mpm.setup import build_state

MU_S, MU_2, I_0 = math.tan(math.radians(20.9)), math.tan(math.radians(32.76)), 0.279
D, RHO_S = 0.53e-3, 2450.0
RHO = 0.6 * RHO_S
E, NU = 1e7, 0.3
P0 = 1e3


def _mat(n=1, separation="reset"):
    return MuI("beads", n, density=RHO, youngs_modulus=E, poisson_ratio=NU, mu_s=MU_S,
               mu_2=MU_2, I_0=I_0, grain_diameter=D, grain_density=RHO_S,
               separation=separation)


def _mu(I):
    """Jop et al. (2006) Eq. 2, written out here independently of the material."""
    return MU_S + (MU_2 - MU_S) / (I_0 / I + 1.0)


def _p_tau(stress):
    """p = -tr/3 and tau = sqrt(s:s/2), the shear stress of simple shear (Pa)."""
    p = -np.trace(stress, axis1=-2, axis2=-1) / 3.0
    s = stress + p[..., None, None] * np.eye(3)
    return p, np.sqrt(0.5 * np.einsum("...ij,...ij->...", s, s))


def _simple_shear(mat, gdot, p0=P0, dgamma=1e-5, steps=200):
    """Simple shear v_x = gdot z from an isotropic pressure p0: dH[0, 2] = gdot dt, the
    shear strain dgamma per step, 2e-3 in all. Loading to yield takes tau/G ~ 2e-4 of
    it and the plastic relaxation towards steady flow less, so the last steps are steady.
    Returns the final stress and the tau history."""
    dt = dgamma / gdot
    stress = np.tile(-p0 * np.eye(3), (mat.eps_p.size, 1, 1))
    dH = np.zeros_like(stress)
    dH[:, 0, 2] = gdot * dt
    taus = []
    for _ in range(steps):
        mat.update(dH, dt, stress)
        taus.append(_p_tau(stress)[1][0])
    return stress, np.array(taus)


def _gdot_of(I, p=P0):
    """The shear rate that gives inertial number I at pressure p: I sqrt(p/rho_s)/d."""
    return I * math.sqrt(p / RHO_S) / D


@pytest.mark.parametrize("I", [0.01, 0.1, 1.0])
def test_steady_simple_shear_follows_mu_of_I(I):
    """tau/p = mu(I), I = gdot d sqrt(rho_s/p) from the imposed rate, within 1e-3.

    The backward-Euler return makes steady flow exact (plastic rate = imposed rate) up to
    the Jaumann rotation terms, O((tau/G)^2) ~ 1e-8, so 1e-3 is loose; yet the conventions
    matter at that level: a factor sqrt(2) in gdot or tau (sqrt(2 D':D') vs |D'|) shifts
    mu(I) by 1 % at I = 0.01, 4 % at 0.1 and 8 % at 1.
    """
    mat = _mat()
    gdot = _gdot_of(I)
    stress, taus = _simple_shear(mat, gdot)
    p, tau = _p_tau(stress)
    np.testing.assert_allclose(p, P0, rtol=1e-12)  # constant-pressure return, no dilatancy
    assert abs(taus[-1] - taus[-20]) < 1e-9 * taus[-1]  # steady
    I_meas = gdot * D * math.sqrt(RHO_S / p[0])
    np.testing.assert_allclose(tau[0] / p[0], _mu(I_meas), rtol=1e-3)
    np.testing.assert_allclose(mat.point_fields()["inertial_number"], I_meas, rtol=1e-3)
    # plastic shear strain = imposed shear strain - elastic tau/G (2e-3 - 1e-4 or so)
    gamma = 200 * 1e-5
    np.testing.assert_allclose(mat.eps_p[0], gamma - tau[0] / mat.G, rtol=1e-3)
    # and the stress stays a simple shear (xz) plus the small normal stresses of rotation
    assert abs(stress[0, 0, 2]) > 0.999 * tau[0]


@pytest.mark.parametrize("dt", [1e-9, 1e-15, 1e-22])
def test_tiny_step_keeps_the_rate(dt):
    """One step of any length, at the rate of a steady flow, leaves I at the flow's value
    (1e-6). For tiny steps the root of a gdot^2 - b gdot - c = 0 (a = G dt) is 2c/(root - b)
    with b < 0; the textbook (b + root)/(2a) cancels to noise, then 0, as 4ac/b^2 ~ (G/p)
    gdot dt nears the rounding of b^2 (5e-17 at dt = 1e-22 s here, where it fails)."""
    mat = _mat()
    gdot = _gdot_of(0.1)
    stress, _ = _simple_shear(mat, gdot)
    I_flow = mat.inertial[0]
    dH = np.zeros((1, 3, 3))
    dH[0, 0, 2] = gdot * dt
    mat.update(dH, dt, stress)
    np.testing.assert_allclose(mat.inertial[0], I_flow, rtol=1e-6)
    np.testing.assert_allclose(mat.inertial[0], 0.1, rtol=1e-3)


def test_rate_independent_and_fast_limits():
    """gdot -> 0: tau/p -> mu_s; I -> infinity: tau/p -> mu_2.

    At I = 1e-7 the law sits (mu_2 - mu_s) I/I_0 ~ 1e-7 above mu_s, at I = 1e5 it sits
    (mu_2 - mu_s) I_0/I ~ 7e-7 below mu_2: a relative 1e-5 tolerance separates both limits
    from a neighbouring rate (I = 1e-3 is 2e-3 above mu_s, I = 1e2 is 1.1e-3 below mu_2).
    """
    ratios = []
    for I in [1e-3, 1e-5, 1e-7]:
        stress, _ = _simple_shear(_mat(), _gdot_of(I))
        p, tau = _p_tau(stress)
        ratios.append(tau[0] / p[0])
    assert ratios[0] > ratios[1] > ratios[2]
    assert abs(ratios[-1] / MU_S - 1) < 1e-5
    assert ratios[0] / MU_S - 1 > 1e-3
    for I, tol in [(1e2, None), (1e5, 1e-5)]:
        stress, _ = _simple_shear(_mat(), _gdot_of(I))
        p, tau = _p_tau(stress)
        if tol is None:
            assert 1 - tau[0] / p[0] / MU_2 > 1e-3
        else:
            assert abs(tau[0] / p[0] / MU_2 - 1) < tol


def test_below_the_cone_is_hooke():
    """Strain increments that keep tau <= mu_s p: stress increment = lam tr(de) I + 2G de
    to round-off (1e-12), no plastic strain, I = 0."""
    rng = np.random.default_rng(7)
    n = 200
    mat = _mat(n)
    sig0 = np.tile(-P0 * np.eye(3), (n, 1, 1))
    # random deviatoric directions (no spin: the rotation is the identity), compressions
    # -tr(de) from -5e-5 to 1e-4 (p from ~580 Pa to ~1830 Pa), scaled to tau = r mu_s p
    dev = rng.normal(size=(n, 3, 3))
    dev = 0.5 * (dev + dev.transpose(0, 2, 1))
    dev -= np.trace(dev, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
    ev = rng.uniform(-5e-5, 1e-4, n)
    K = mat.lam + 2 * mat.G / 3
    r = rng.uniform(0.1, 0.99, n)
    alpha = r * MU_S * (P0 + K * ev) / (2 * mat.G * _p_tau(dev)[1])
    de = alpha[:, None, None] * dev - ev[:, None, None] * np.eye(3) / 3
    expected = sig0 + mat.lam * np.trace(de, axis1=1, axis2=2)[:, None, None] * np.eye(3) \
        + 2 * mat.G * de
    p, tau = _p_tau(expected)
    np.testing.assert_allclose(tau / (MU_S * p), r, rtol=1e-9)  # the set-up is as meant
    out = sig0.copy()
    mat.update(de, 1e-3, out)
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12 * P0)
    assert np.all(mat.eps_p == 0) and np.all(mat.inertial == 0)


def test_no_tension_and_recompression():
    """Extension (or shear) from zero stress leaves zero stress; a separated point that is
    compressed again builds its stress by Hooke's law (1e-12)."""
    mat = _mat(3)
    stress = np.zeros((3, 3, 3))
    dH = np.zeros((3, 3, 3))
    dH[0] = np.diag([1e-4, 1e-4, 1e-4])  # isotropic extension
    dH[1] = np.diag([0.0, 0.0, 1e-4])  # uniaxial extension: p_tr < 0 but a deviator
    dH[2, 0, 1] = 1e-4  # pure shear: p_tr = 0, separated too
    mat.update(dH, 1e-3, stress)
    assert np.all(stress == 0.0)
    # compressed again (the points keep no memory of having separated)
    de = np.diag([-1e-4, -1e-4, -1e-4]) + 1e-6 * np.array([[0, 1, 0], [1, 0, 0], [0, 0, 0]])
    dH = np.tile(de, (3, 1, 1))
    mat.update(dH, 1e-3, stress)
    expected = mat.lam * np.trace(de) * np.eye(3) + 2 * mat.G * de
    np.testing.assert_allclose(stress, np.tile(expected, (3, 1, 1)), rtol=1e-12)
    p, _ = _p_tau(stress)
    assert np.all(p > 0)


def test_recompact_stays_open_until_the_opened_volume_is_closed():
    """separation = "recompact": from p0 = 1 kPa an isotropic extension of volumetric
    strain 3e (3eK > p0) opens the point by phi = 3e - p0/K; shear while open leaves it
    open (tr = 0); compression in equal steps carries nothing until phi is closed, then
    p = K (compression beyond phi) exactly (1e-12), where "reset" would already carry
    K times the whole compression. The opening is shown among the point fields."""
    mat, reset = _mat(1, "recompact"), _mat(1)
    K = mat.lam + 2 * mat.G / 3
    e = 1e-3
    stresses = [np.tile(-P0 * np.eye(3), (1, 1, 1)) for _ in range(2)]
    for m, s in zip((mat, reset), stresses, strict=True):
        m.update(np.diag([e, e, e])[None], 1e-4, s)
        assert np.all(s == 0.0)
    phi = 3 * e - P0 / K
    np.testing.assert_allclose(mat.point_fields()["opening"], [phi], rtol=1e-12)
    shear = np.zeros((1, 3, 3))
    shear[0, 0, 2] = 1e-3
    for m, s in zip((mat, reset), stresses, strict=True):
        m.update(shear, 1e-4, s)
    assert np.all(stresses[0] == 0.0) and np.all(stresses[1] == 0.0)  # p_tr = 0: open
    c = phi / 10.5  # volumetric compression per step: closes within the 11th step
    step = np.diag([-c / 3] * 3)[None]
    for n in range(1, 15):
        for m, s in zip((mat, reset), stresses, strict=True):
            m.update(step, 1e-4, s)
        p_recompact, p_reset = _p_tau(stresses[0])[0][0], _p_tau(stresses[1])[0][0]
        assert p_reset == pytest.approx(K * n * c, rel=1e-12)
        if n * c < phi:
            assert np.all(stresses[0] == 0.0) and mat.opening[0] > 0.0
        else:
            assert p_recompact == pytest.approx(K * (n * c - phi), rel=1e-12)
            assert mat.opening[0] == 0.0


@pytest.mark.parametrize("flowing", [False, True])
def test_rigid_rotation_keeps_invariants(flowing):
    """A pure spin increment changes the stress invariants no more than no increment at
    all (1e-12): inside the cone the stress only rotates; on a flowing point both relax
    at zero strain rate by the same amount."""
    mat_a, mat_b = _mat(), _mat()
    if flowing:
        sig, _ = _simple_shear(_mat(), _gdot_of(0.1))
    else:
        sig = np.array([[[-3.0, 0.3, 0.2], [0.3, -2.5, 0.1], [0.2, 0.1, -2.0]]]) * 1e3
    w = 0.05
    spin = np.array([[[0.0, -w, 0.3 * w], [w, 0.0, -0.5 * w], [-0.3 * w, 0.5 * w, 0.0]]])
    a, b = sig.copy(), sig.copy()
    mat_a.update(spin, 1e-4, a)
    mat_b.update(np.zeros_like(spin), 1e-4, b)
    np.testing.assert_allclose(np.linalg.eigvalsh(a), np.linalg.eigvalsh(b), rtol=1e-12,
                               atol=1e-12 * P0)
    assert not np.allclose(a, b)  # it did rotate
    p, tau = _p_tau(sig)
    if flowing:  # the flowing point relaxed (towards mu_s p) in both cases
        assert _p_tau(b)[1][0] < tau[0] * (1 - 1e-3)
        assert mat_a.eps_p[0] == mat_b.eps_p[0] > 0


def test_zero_step_keeps_a_flowing_stress():
    """dt = 0, dH = 0 leaves the stress of a flowing point (tau > mu_s p) as it was (no time
    for relaxation, 1e-12); dt = 0 with a shear increment caps tau at mu_2 p."""
    mat = _mat()
    sig, _ = _simple_shear(mat, _gdot_of(0.5))
    eps, I = mat.eps_p.copy(), mat.inertial.copy()
    out = sig.copy()
    mat.update(np.zeros((1, 3, 3)), 0.0, out)
    np.testing.assert_allclose(out, sig, rtol=1e-12, atol=1e-12 * P0)
    assert mat.eps_p[0] == eps[0] and mat.inertial[0] == I[0]
    dH = np.zeros((1, 3, 3))
    dH[0, 0, 2] = 1e-2  # tau_tr ~ G 1e-2 >> mu_2 p
    mat.update(dH, 0.0, out)
    p, tau = _p_tau(out)
    np.testing.assert_allclose(tau / p, MU_2, rtol=1e-12)


def _roundtrip_h5(tmp_path, state):
    write_checkpoint(tmp_path / "c.h5", {"material_0": state}, {"step": 0})
    groups, _ = read_checkpoint(tmp_path / "c.h5")
    return groups["material_0"]


@pytest.mark.parametrize("separation", ["reset", "recompact"])
def test_checkpoint_round_trip(tmp_path, separation):
    """state() through an HDF5 checkpoint into a fresh material: the continued runs are
    bitwise identical, and the point fields (with "recompact", the opening) come back."""
    n = 4
    gdots = np.array([_gdot_of(I) for I in [0.0, 0.01, 0.1, 1.0]])
    dt = 1e-6
    mat = _mat(n, separation)
    stress = np.tile(-P0 * np.eye(3), (n, 1, 1))
    dH = np.zeros((n, 3, 3))
    dH[:, 0, 2] = gdots * dt
    dH[0] = np.diag([1e-4, 0, 0])  # this one separates
    for _ in range(100):
        mat.update(dH, dt, stress)
    assert np.all(mat.eps_p[1:] > 0) and np.all(mat.inertial[1:] > 0)
    saved = _roundtrip_h5(tmp_path, mat.state())
    own = {"opening"} if separation == "recompact" else set()
    assert set(saved) == {"plastic_strain", "inertial_number"} | own
    if own:
        assert saved["opening"][0] > 0  # the separated point is open
    other = _mat(n, separation)
    other.load_state(saved)
    for k, v in mat.point_fields().items():
        assert np.array_equal(other.point_fields()[k], v), k
    s1, s2 = stress.copy(), stress.copy()
    dH[:, 0, 2] *= 0.5  # slow down: I and the stress change
    for _ in range(20):
        mat.update(dH, dt, s1)
        other.update(dH, dt, s2)
    assert np.array_equal(s1, s2)
    assert np.array_equal(mat.eps_p, other.eps_p)
    assert np.array_equal(mat.inertial, other.inertial)


CASE = """
[grid]
cell_size = 0.1
cells = [2, 2, 12]

[solver]
gravity = [0.0, 0.0, -9.81]

[time]
end = 1.0

[materials.beads]
type = "mu_i"
density = 1470.0
youngs_modulus = 1e7
poisson_ratio = 0.3
mu_s = 0.382
mu_2 = 0.643
I_0 = 0.279
grain_diameter = 0.53e-3
grain_density = 2450.0

[[bodies]]
shape = "box"
material = "beads"
lo = [0.0, 0.0, 0.0]
hi = [0.2, 0.2, 1.0]

[[boundaries]]
type = "roller"
face = "x-"
[[boundaries]]
type = "roller"
face = "x+"
[[boundaries]]
type = "roller"
face = "y-"
[[boundaries]]
type = "roller"
face = "y+"
[[boundaries]]
type = "fixed"
face = "z-"

[damping]
alpha = 0.7

[output]
interval = 0.1
"""


def _load(tmp_path, text):
    p = tmp_path / "case.toml"
    p.write_text(textwrap.dedent(text))
    return build_state(load_case(p), tmp_path)


@pytest.mark.parametrize("separation", ["reset", "recompact"])
def test_column_settles_to_lithostatic_stress(tmp_path, separation):
    """A 1 m column of beads between frictionless walls on a fixed floor, damped to rest:
    sigma_zz = -rho g (H - z) within 1 % in every cell below 0.8 H, the base included,
    with either way of touching again after a separation (the case key reaches the law).

    The weight above a material point does not change as the column settles, so only the
    discretisation errs (1e-4 here; per-cell means as in test_elastic_cases.py, whose
    elastic column meets 2 %). Oedometric elasticity would give
    tau/p = sqrt(3) (1 - K0)/(1 + 2 K0) = 0.53 > mu_s (K0 = nu/(1 - nu) = 0.43), so the
    column must yield while it loads: every point has plastic strain, and at rest no point
    lies above the mu_s cone (the lateral stress rose to K >= 0.54 sigma_zz) or flows.
    """
    key = f'grain_density = 2450.0\nseparation = "{separation}"'
    s = _load(tmp_path, CASE.replace("grain_density = 2450.0", key))
    mat = s.materials[0]
    assert isinstance(mat, KINDS["mu_i"]) and mat.recompact == (separation == "recompact")
    H, h, rho, g = 1.0, 0.1, 1470.0, 9.81
    c = s.wave_speed()
    run(s, 40 * 4 * H / c)  # 40 periods of the column's first mode
    z0 = s.points.x0[:, 2]
    cell = np.floor(z0 / h).astype(int)
    for k in range(0, int(0.8 * H / h)):
        sel = cell == k
        expected = -rho * g * (H - z0[sel].mean())
        np.testing.assert_allclose(s.points.stress[sel, 2, 2].mean(), expected, rtol=0.01)
    p, tau = _p_tau(s.points.stress)
    low = z0 < 0.8 * H
    assert np.all(mat.eps_p[low] > 0)
    assert np.all(tau[low] <= mat.mu_s * p[low] * (1 + 1e-9))
    assert np.all(mat.point_fields()["inertial_number"] == 0)  # at rest: nothing flows


@pytest.mark.parametrize("old,new,words", [
    ("mu_2 = 0.643", "mu_2 = 0.3", ["materials.beads.mu_2", "0.3", "mu_s = 0.382"]),
    ("mu_2 = 0.643", "mu_2 = 0.382", ["materials.beads.mu_2", "0.382", "> mu_s"]),
    ("I_0 = 0.279", "I_0 = 0.0", ["materials.beads.I_0", "0.0", "greater than 0"]),
    ("grain_density = 2450.0", "grain_density = 1000.0",
     ["materials.beads.grain_density", "1000.0", "density = 1470.0"]),
    ("grain_diameter = 0.53e-3", "grain_diameter = -1.0",
     ["materials.beads.grain_diameter", "-1.0"]),
    ("mu_s = 0.382", "mus = 0.382", ["materials.beads.mus", "unknown key"]),
    ("mu_s = 0.382", 'mu_s = 0.382\nseparation = "memory"',
     ["materials.beads.separation", "memory", "reset", "recompact"]),
])
def test_bad_mu_i_input_is_named(tmp_path, old, new, words):
    assert old in CASE
    with pytest.raises(ConfigError) as err:
        _load(tmp_path, CASE.replace(old, new))
    msg = str(err.value)
    for w in words:
        assert w in msg, (w, msg)

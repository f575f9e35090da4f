"""Materials driven directly through the batched interface (no grid)."""

import math

import numpy as np
import pytest

from grainscale.mpm.materials import DruckerPrager, LinearElastic, MohrCoulomb
from grainscale.stress import p_q

E, NU = 1e7, 0.3


def _mc_f(stress, phi, c=0.0):
    """Mohr-Coulomb yield function of each stress (tension positive), Pa."""
    s = np.sort(np.linalg.eigvalsh(stress), axis=-1)[..., ::-1]
    sp = math.sin(math.radians(phi))
    return (s[..., 0] - s[..., 2]) + (s[..., 0] + s[..., 2]) * sp - 2 * c * math.cos(
        math.radians(phi))


def test_elastic_rigid_rotation_keeps_stress_invariants():
    """A pure spin increment rotates the stress (Hughes-Winget) without changing it."""
    mat = LinearElastic("e", 1, density=1000.0, youngs_modulus=E, poisson_ratio=NU)
    sig = np.array([[[-3.0, 1.0, 0.5], [1.0, -2.0, 0.2], [0.5, 0.2, -1.0]]]) * 1e3
    w = 0.05
    dH = np.array([[[0.0, -w, 0.0], [w, 0.0, 0.0], [0.0, 0.0, 0.0]]])
    out = sig.copy()
    mat.update(dH, 1e-3, out)
    np.testing.assert_allclose(np.linalg.eigvalsh(out), np.linalg.eigvalsh(sig), rtol=1e-12)
    assert not np.allclose(out, sig)  # it did rotate


def test_elastic_increment_is_hooke():
    mat = LinearElastic("e", 1, density=1000.0, youngs_modulus=E, poisson_ratio=NU)
    de = np.diag([1e-5, -2e-5, 3e-6])[None]
    out = np.zeros((1, 3, 3))
    mat.update(de, 1e-3, out)
    lam, G = mat.lam, mat.G
    np.testing.assert_allclose(out[0], lam * np.trace(de[0]) * np.eye(3) + 2 * G * de[0],
                               rtol=1e-12)


@pytest.mark.parametrize("cohesion", [0.0, 5e3])
def test_mohr_coulomb_trial_outside_returns_onto_surface(cohesion):
    """Random large strain increments from a compressed state: every returned stress lies
    on the yield surface (|f| below 1e-9 of the stress scale) or inside it."""
    rng = np.random.default_rng(4)
    n = 500
    mat = MohrCoulomb("mc", n, density=1000.0, youngs_modulus=E, poisson_ratio=NU,
                      friction_angle=30.0, dilation_angle=5.0, cohesion=cohesion,
                      tension_cutoff=0.0)
    stress = np.tile(-1e5 * np.eye(3), (n, 1, 1))
    dH = rng.normal(scale=5e-3, size=(n, 3, 3))
    trial = stress + mat.lam * np.trace(dH, axis1=1, axis2=2)[:, None, None] * np.eye(3) + \
        mat.G * (dH + dH.transpose(0, 2, 1))
    mat.update(dH, 1e-3, stress)
    f_trial = _mc_f(trial, 30.0, cohesion)
    f = _mc_f(stress, 30.0, cohesion)
    outside = f_trial > 0
    assert outside.sum() > 100  # the test does exercise the return
    scale = np.abs(np.linalg.eigvalsh(trial)).max(axis=1)
    assert np.all(f <= 1e-9 * scale)
    # trial stresses outside the surface end on it, unless cut off in tension
    s_max = np.linalg.eigvalsh(stress)[:, -1]
    on = outside & (s_max < -1e-9 * scale)
    np.testing.assert_allclose(f[on] / scale[on], 0.0, atol=1e-9)
    assert np.all(s_max <= 1e-9 * scale)  # tension cut-off T = 0
    assert np.all(mat.eps_p[outside] > 0) and np.all(mat.eps_p[~outside] == 0)


@pytest.mark.parametrize("psi", [10.0, 25.0])
@pytest.mark.parametrize("cohesion", [0.0, 5e3])
def test_mohr_coulomb_plastic_flow_follows_the_dilatant_potential(psi, cohesion):
    """Non-associated flow, psi > 0: the plastic strain of a return, d eps_p = d eps -
    C^-1 d sigma, follows g = (s1 - s3) + (s1 + s3) sin(psi) (tension positive):

    - on the main plane, d eps_p = dlambda (1 + sin psi, 0, -(1 - sin psi)) in the
      trial stress's principal axes (descending): the dilatancy
      d eps_v^p / (d eps_1^p - d eps_3^p) = sin(psi);
    - on an edge as well, d eps_v^p = 2 sin(psi) dlambda, dlambda = la + lb the
      multiplier sum the material accumulates (`eps_p`): each plane's b has trace
      2 sin(psi).
    Returns to the apex or to the tension cut-off follow neither and are left out.
    Random symmetric increments (no spin) from -100 kPa isotropic; phi = 30 deg.

    Tolerance 1e-8 dlambda: d eps_p is recovered from strains ~5e-3 and stress changes
    ~1e5 Pa in float64 through the material's closed-form eigen-decomposition (measured
    3.5e-10). Associated flow (psi -> phi) would be off by 2 (sin phi - sin psi) dlambda
    >= 0.15 dlambda; psi taken as 0 by 2 sin(psi) dlambda."""
    rng = np.random.default_rng(6)
    n = 2000
    mat = MohrCoulomb("mc", n, density=1000.0, youngs_modulus=E, poisson_ratio=NU,
                      friction_angle=30.0, dilation_angle=psi, cohesion=cohesion,
                      tension_cutoff=0.0)
    stress0 = np.tile(-1e5 * np.eye(3), (n, 1, 1))
    dH = rng.normal(scale=5e-3, size=(n, 3, 3))
    de = 0.5 * (dH + dH.transpose(0, 2, 1))
    tr = np.trace(de, axis1=1, axis2=2)[:, None, None] * np.eye(3)
    trial = stress0 + mat.lam * tr + 2 * mat.G * de
    stress = stress0.copy()
    mat.update(de, 1e-3, stress)
    ds = stress - stress0
    tr_ds = np.trace(ds, axis1=1, axis2=2)[:, None, None] * np.eye(3)
    de_p = de - (ds - mat.lam / (3 * mat.lam + 2 * mat.G) * tr_ds) / (2 * mat.G)
    dl = mat.eps_p
    s = np.linalg.eigvalsh(stress)  # ascending: s3, s2, s1
    gap = 1e-9 * 1e5
    plastic = (dl > 0) & (s[:, 2] - s[:, 0] > gap) & (s[:, 2] < -gap)  # not apex / cut-off
    sp = math.sin(math.radians(psi))
    vol = np.trace(de_p, axis1=1, axis2=2)
    np.testing.assert_allclose(vol[plastic] / dl[plastic], 2 * sp, rtol=0, atol=1e-8)
    # main-plane returns: distinct principal stresses; the direction itself
    plane = plastic & (s[:, 2] - s[:, 1] > 1e-6 * 1e5) & (s[:, 1] - s[:, 0] > 1e-6 * 1e5)
    _, vecs = np.linalg.eigh(trial)
    de_p_principal = np.einsum("pia,pij,pjb->pab", vecs, de_p, vecs)
    direction = np.diag([-(1 - sp), 0.0, 1 + sp])  # ascending order of the axes
    err = np.abs(de_p_principal[plane] / dl[plane, None, None] - direction).max()
    assert err < 1e-8, err
    # the test does exercise plane and edge returns
    assert plane.sum() > 300 and (plastic & ~plane).sum() > 100


def _drained_triaxial(mat, confining=1e5, steps=400, d_axial=2e-4):
    """Axial compression (z) with the lateral stress held at -confining: the lateral
    strain increment of each step is solved by the secant method on copies."""
    stress = np.array([-confining * np.eye(3)])
    path = []
    for _ in range(steps):
        def trial(de_lat, commit=False, stress=stress):
            dH = np.diag([de_lat, de_lat, -d_axial])[None]
            s = stress.copy()
            st = mat.state()
            saved = {k: v.copy() for k, v in st.items()}
            mat.update(dH, 1e-3, s)
            if not commit:
                mat.load_state(saved)
            return s
        x0, x1 = 0.0, NU * d_axial
        r0 = trial(x0)[0, 0, 0] + confining
        r1 = trial(x1)[0, 0, 0] + confining
        for _ in range(30):
            if abs(r1) < 1e-9 * confining or r1 == r0:
                break
            x0, x1, r0 = x1, x1 - r1 * (x1 - x0) / (r1 - r0), r1
            r1 = trial(x1)[0, 0, 0] + confining
        stress = trial(x1, commit=True)
        p, q = p_q(stress)
        path.append((p[0], q[0]))
    return np.array(path)


@pytest.mark.parametrize("kind", [MohrCoulomb, DruckerPrager])
@pytest.mark.parametrize("phi", [20.0, 30.0])
def test_drained_triaxial_reaches_critical_stress_ratio(kind, phi):
    """Cohesionless, perfectly plastic: q/p -> M = 6 sin(phi)/(3 - sin(phi)) within 1 %
    (Drucker-Prager is matched to Mohr-Coulomb in triaxial compression)."""
    mat = kind("m", 1, density=1000.0, youngs_modulus=E, poisson_ratio=NU,
               friction_angle=phi, dilation_angle=0.0)
    path = _drained_triaxial(mat)
    s = math.sin(math.radians(phi))
    M = 6 * s / (3 - s)
    p, q = path[-1]
    assert abs(p - (1e5 + q / 3)) < 1e-6 * p  # lateral stress held: dp = dq/3
    np.testing.assert_allclose(q / p, M, rtol=0.01)
    assert np.all(path[:, 1] / path[:, 0] <= M * (1 + 1e-9))  # never above the surface


def test_drucker_prager_returns_onto_cone():
    rng = np.random.default_rng(5)
    n = 300
    mat = DruckerPrager("dp", n, density=1000.0, youngs_modulus=E, poisson_ratio=NU,
                        friction_angle=25.0, dilation_angle=0.0, cohesion=1e3)
    stress = np.tile(-5e4 * np.eye(3), (n, 1, 1))
    dH = rng.normal(scale=5e-3, size=(n, 3, 3))
    mat.update(dH, 1e-3, stress)
    p, q = p_q(stress)
    f = q - mat.M * p - mat.k
    assert np.all(f <= 1e-9 * np.abs(stress).max())
    assert (mat.eps_p > 0).sum() > 50


def test_mohr_coulomb_simple_shear_is_rate_and_step_independent():
    """Simple shear (x-z) of a non-dilatant Mohr-Coulomb point from isotropic 500 Pa to a
    shear of 0.2: the steady shear stress is s_xz = p sin(phi) (plane-strain, psi = 0: the
    velocity characteristics carry tau/sigma_n = sin phi), whatever the number of
    increments, 100 or 10,000 (the return is exact per increment; 1e-9 relative covers
    round-off), so a column's dependence on the MPM step is not the material's."""
    def shear(n):
        m = MohrCoulomb("m", 1, density=1500.0, youngs_modulus=2e6, poisson_ratio=0.3,
                        friction_angle=22.0)
        sig = -500.0 * np.eye(3)[None].copy()
        dH = np.zeros((1, 3, 3))
        dH[0, 0, 2] = 0.2 / n
        for _ in range(n):
            m.update(dH, 1e-3, sig)
        return sig[0]

    coarse, fine = shear(100), shear(10_000)
    np.testing.assert_allclose(coarse, fine, rtol=1e-9, atol=1e-9 * 500.0)
    p = -np.trace(fine) / 3.0
    assert p == pytest.approx(500.0, rel=1e-9)
    assert fine[0, 2] == pytest.approx(p * np.sin(np.radians(22.0)), rel=1e-6)

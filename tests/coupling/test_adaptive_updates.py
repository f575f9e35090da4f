"""Adaptive RVE updates (materials.NAME.update_tolerance, coupling/rve_material.py): a
quasi-static RVE whose accumulated increment is below the tolerance is not stepped; its
stress is the last update's turned with the accumulated spin, and the whole increment
reaches its DEM when the tolerance (or the bound on deferred steps) is reached."""

import math

import numpy as np
import pytest

from grainscale.config.rve import RVEParams
from grainscale.coupling.predictor import affine_tangent, polar_rotation, predicted_stress
from grainscale.coupling.rve_material import RVEMaterial
from grainscale.dem import homogenise
from grainscale.dem.generate import generate

COMPILE_AHEAD = ("rve",)  # tests/warm_kernels.py compiles the DEM kernels while tests/mpm runs


@pytest.fixture(scope="module")
def packing():
    """A 150-sphere medium-dense packing at 100 kPa (unit-element grains)."""
    params = RVEParams(particles=150, preparation={"pressure": 100e3, "porosity": 0.38,
                                                   "porosity_tolerance": 0.005})
    return params, generate(params)


def material(packing, n=3, **kw) -> RVEMaterial:
    """Quasi-static RVEs of the packing, every one stepped every MPM step unless
    update_tolerance is given (the case file's default is strain_per_substep)."""
    params, pack = packing
    kw.setdefault("update_tolerance", 0.0)
    return RVEMaterial("sand", params, [pack], n_points=n, mode="quasi_static",
                       retile_width=0.0, **kw)


def increments(n_steps: int, n_points: int = 3, size: float = 1e-5, seed: int = 0):
    """Small mixed increments (compression, shear, spin) of at most `size` per component,
    a different one for each point and step."""
    rng = np.random.default_rng(seed)
    out = rng.uniform(-size, size, (n_steps, n_points, 3, 3))
    out[:, :, 2, 2] = -size  # every point compressed along z: a stress path, not jiggle
    return out


def rotation(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def affine_moduli(n: np.ndarray, weight: np.ndarray, ratio: float) -> np.ndarray:
    """(3,3,3,3) affine stiffness of contacts with normals n (c,3) and weights
    kn |d|^2 / V (c,) [Pa], built directly from the springs: the relative displacement
    of a contact under a strain eps is |d| eps n, its force kn (n n + ratio (I - n n))
    times that, and the stress (1/V) sum d (x) f; sym over ab, as the MPM reads it."""
    eye = np.eye(3)
    spring = n[:, :, None] * n[:, None, :] + ratio * (eye - n[:, :, None] * n[:, None, :])
    c = np.einsum("k,ka,kbc,kd->abcd", weight, n, spring, n)  # d_a f_b per eps_cd
    return 0.5 * (c + np.swapaxes(c, 0, 1))


@pytest.mark.parametrize("ratio", [0.0, 0.25, 1.0])
def test_the_predictor_is_the_affine_stiffness_of_the_contact_network(ratio):
    """affine_tangent, from the six stored C_aabb alone, against the affine stiffness
    summed spring by spring (affine_moduli) for a fabric with the cell's axes as its
    principal axes (each normal with its 8 sign flips: no mixed moments n_a^3 n_b), for
    12 random symmetric strains: equal to round-off (1e-12 of the largest increment).
    For a fabric turned off the axes the mixed moments it leaves out matter: the
    difference is then non-zero (the test would see a formula that ignored the fabric)."""
    rng = np.random.default_rng(3)
    n = rng.normal(size=(40, 3)) * [1.0, 0.7, 1.6]  # anisotropic
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    flips = np.array([[a, b, c] for a in (1, -1) for b in (1, -1) for c in (1, -1)])
    n = (n[:, None, :] * flips).reshape(-1, 3)
    weight = np.repeat(rng.uniform(0.5, 2.0, 40), 8) * 1e6
    c = affine_moduli(n, weight, ratio)
    stored = np.einsum("aabb->ab", c)[None]  # C_aabb, what the kernel keeps
    for _ in range(12):
        eps = rng.normal(size=(3, 3)) * 1e-6
        eps = 0.5 * (eps + eps.T)
        want = np.einsum("abcd,cd->ab", c, eps)
        got = affine_tangent(stored, ratio, eps[None])[0]
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    turned = n @ rotation([1.0, 2.0, 3.0], 0.6).T
    c = affine_moduli(turned, weight, ratio)
    want = np.einsum("abcd,cd->ab", c, eps)
    got = affine_tangent(np.einsum("aabb->ab", c)[None], ratio, eps[None])[0]
    assert np.abs(got - want).max() > 1e-3 * np.abs(want).max()


def work_ratio(stretch: float, angle: float) -> tuple[float, float]:
    """Range over 500 random symmetric strains of the predictor's work eps:C_pred:eps
    (affine_tangent, from the six C_aabb) over the full affine work eps:C:eps of 4,000
    contacts whose normals are drawn elongated `stretch` : 1 along z, turned by `angle`
    about y (kt/kn 0.8)."""
    rng = np.random.default_rng(4)
    n = rng.normal(size=(4000, 3)) * [1.0, 1.0, stretch]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = n @ rotation([0.0, 1.0, 0.0], angle).T
    c = affine_moduli(n, np.full(len(n), 1e3), 0.8)
    eps = rng.normal(size=(500, 3, 3))
    eps = 0.5 * (eps + np.swapaxes(eps, 1, 2))
    full = np.einsum("abcd,kab,kcd->k", c, eps, eps)
    stored = np.repeat(np.einsum("aabb->ab", c)[None], 500, axis=0)
    pred = np.einsum("kab,kab->k", affine_tangent(stored, 0.8, eps), eps)
    return float((pred / full).min()), float((pred / full).max())


def test_the_predictor_bounds_the_stiffness_only_near_the_fabrics_axes():
    """What docs/coupling.md's error argument may claim: for a near-isotropic fabric, or
    an anisotropic one with the cell's axes as its principal axes, the predictor's work
    is the affine work within 2 % (measured 0.987-1.018), so it is as stiff as the affine
    field, which bounds the RVE (Voigt); for a fabric elongated 2.5 : 1 and turned 45 deg
    it is 0.68-1.91 of it: softer than the affine field along some strains, so it bounds
    neither the RVE's stiffness nor, by max_k M_k tol, the stress error there (up to
    ~2 times that)."""
    for stretch, angle in ((1.0, 0.0), (1.0, math.pi / 4), (2.5, 0.0)):
        lo, hi = work_ratio(stretch, angle)
        assert 0.98 < lo and hi < 1.02, (stretch, angle, lo, hi)
    lo, hi = work_ratio(2.5, math.pi / 4)
    assert lo < 0.75 and hi > 1.8, (lo, hi)


@pytest.mark.parametrize("size", [1e-6, 1e-3, 0.3])
def test_predicted_stress_is_the_polar_decomposition_formula(size):
    """predicted_stress (Newton's polar iteration, compiled) against the same formula
    evaluated independently with numpy's SVD, R = W V^T and U = V S V^T of
    I + H = W S V^T, for 20 random increments of each size (a waiting RVE's are below
    the tolerance; 0.3 shows the iteration converges far from the identity): equal to
    1e-10 of the largest stress component (round-off of U - I, ~1e-16, times moduli
    ~1e6 times the stress scale)."""
    rng = np.random.default_rng(5)
    h = rng.uniform(-size, size, (20, 3, 3))
    stress = rng.normal(size=(20, 3, 3)) * 1e3
    moduli = rng.uniform(1e5, 1e6, (20, 3, 3))
    moduli = 0.5 * (moduli + np.swapaxes(moduli, 1, 2))
    w, sv, vt = np.linalg.svd(np.eye(3) + h)
    rot = w @ vt
    stretch = np.einsum("pka,pk,pkb->pab", vt, sv - 1.0, vt)
    sym = 0.5 * (stress + np.swapaxes(stress, 1, 2))
    want = rot @ (sym + affine_tangent(moduli, 0.4, stretch)) @ np.swapaxes(rot, 1, 2)
    got = predicted_stress(stress, moduli, h, 0.4)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-10 * np.abs(want).max())
    r = np.empty((3, 3))
    polar_rotation(np.eye(3) + h[0], r)
    np.testing.assert_allclose(r, rot[0], rtol=0, atol=1e-14)


def test_a_tolerance_that_defers_nothing_is_bitwise_every_step(packing):
    """With a tolerance every increment exceeds, the adaptive path hands each RVE exactly
    its dH (the composed increment is kept as H, so dH + 0 + dH 0 = dH bit for bit) and
    gives the stress, DEM steps and point fields of update_tolerance = 0, to the bit."""
    ref, ada = material(packing), material(packing, update_tolerance=1e-300,
                                           max_deferred_steps=10_000)
    s_ref, s_ada = ref.initial_stress(), ada.initial_stress()
    for dH in increments(12):
        ref.update(dH, 1e-3, s_ref)
        ada.update(dH, 1e-3, s_ada)
        assert np.array_equal(s_ref, s_ada)
    assert ref.rve_steps == ada.rve_steps and ada.rve_updates == 12 * 3
    for k, v in ref.point_fields().items():
        assert np.array_equal(v, ada.point_fields()[k]), k


def test_deferred_increments_reach_the_dem_whole_and_the_stress_stays_within_the_bound(
        packing):
    """Increments of 3e-6 per component against a tolerance of 1e-5 (= the strain per
    DEM step here, its largest value): each RVE waits until its composed increment
    reaches it, then takes it in one update whose cell ends exactly at prod(I + dH) h0
    (1e-13, round-off of the products). While it waits its stress (the last update's; no
    spin beyond the random one's few 1e-6 rad) stays within the documented bound of the
    stress of the same RVE stepped every MPM step: of the order of the affine max_k M_k
    times the tolerance (the strict bound, sum_kl |C_ijkl| tol, is ~1.1 of it for a
    coherent compression; these random increments reach 0.91 of max_k M_k tol).
    Far fewer DEM updates, and no more DEM steps than stepping every MPM step."""
    tol = 1e-5
    ref = material(packing, strain_per_substep=tol)
    ada = material(packing, strain_per_substep=tol, update_tolerance=tol,
                   max_deferred_steps=1000)
    s_ref, s_ada = ref.initial_stress(), ada.initial_stress()
    h0 = ada.batch.h.copy()
    total = np.tile(np.eye(3), (3, 1, 1))
    worst = 0.0
    steps = increments(30, size=3e-6)
    for dH in steps:
        total = np.einsum("pab,pbc->pac", np.eye(3) + dH, total)
        ref.update(dH, 1e-3, s_ref)
        ada.update(dH, 1e-3, s_ada)
        waiting = ada.deferred > 0
        bound = np.diagonal(ref.batch.stiffness, axis1=1, axis2=2).max(axis=1) * tol
        worst = max(worst, float((np.abs(s_ada - s_ref).max(axis=(1, 2)) / bound)[
            waiting].max(initial=0.0)))
        fresh = ada.deferred == 0
        for r in np.flatnonzero(fresh):  # just updated: the cell took every increment
            np.testing.assert_allclose(ada.batch.h[r], total[r] @ h0[r], rtol=0, atol=1e-13
                                       * np.abs(h0[r]).max())
    print(f"worst deviation / bound {worst:.3f}; DEM steps {ada.rve_steps} against "
          f"{ref.rve_steps}; updates {ada.rve_updates} against {ref.rve_updates}")
    assert 0.0 < worst <= 1.0
    assert ada.rve_updates < 0.5 * ref.rve_updates
    n = ada.batch.n_particles  # cost.json's particle-steps: DEM steps x spheres
    assert (ada.particle_steps, ref.particle_steps) == (n * ada.rve_steps, n * ref.rve_steps)
    # a composed increment needs no more steps than its parts (up to each update's
    # rounding up), fewer where they partly cancel
    assert ada.rve_steps <= ref.rve_steps + ada.rve_updates


def test_a_waiting_rve_turns_its_stress_with_the_accumulated_spin(packing):
    """A point spun by 4e-6 rad per MPM step about a skew axis (tolerance 1e-4 = the
    strain per DEM step here, so it waits), after an axial preload that makes its stress
    anisotropic: while waiting its stress is R sigma R^T exactly (1e-12 of p); when the
    bound on deferred steps (20) makes it update, its DEM takes the composed rotation in
    one increment and gives what the same RVE gives when handed the whole rotation
    R(20 x 4e-6) - I at once (1e-9 of p: the composed and the direct rotation differ at
    round-off only)."""
    kw = {"n": 1, "strain_per_substep": 1e-4}
    ada = material(packing, update_tolerance=1e-4, max_deferred_steps=20, **kw)
    ref = material(packing, **kw)
    s_ada, s_ref = ada.initial_stress(), ref.initial_stress()
    preload = np.zeros((1, 3, 3))
    preload[0, 2, 2] = -1e-3  # > tolerance: updated every step
    for _ in range(5):
        ada.update(preload, 1e-3, s_ada)
        ref.update(preload, 1e-3, s_ref)
    assert ada.deferred[0] == 0 and np.array_equal(s_ada, s_ref)
    before = s_ada[0].copy()
    p = homogenise.mean_stress(before)
    assert homogenise.deviatoric_stress(before) > 0.1 * p
    dH = (rotation([1.0, 2.0, 3.0], 4e-6) - np.eye(3))[None]
    for k in range(1, 20):
        ada.update(dH, 1e-3, s_ada)
        assert ada.deferred[0] == k
        r = rotation([1.0, 2.0, 3.0], 4e-6 * k)
        np.testing.assert_allclose(s_ada[0], r @ before @ r.T, rtol=0, atol=1e-12 * p)
    steps_before = ada.rve_steps
    ada.update(dH, 1e-3, s_ada)  # the 20th: stepped, whatever its increment
    assert ada.deferred[0] == 0 and ada.rve_steps == steps_before + 1
    whole = (rotation([1.0, 2.0, 3.0], 4e-6 * 20) - np.eye(3))[None]
    ref.update(whole, 20e-3, s_ref)
    np.testing.assert_allclose(s_ada[0], s_ref[0], rtol=0, atol=1e-9 * p)


def mean_rotation(m: RVEMaterial) -> np.ndarray:
    """(P,) each RVE's mean accumulated rolling angle [rad], read from its grains."""
    return m.batch.rot.mean(axis=1)


def staggered(packing, **kw) -> RVEMaterial:
    """Three points whose RVEs wait out of step: a tolerance (1e-3) that small increments
    never reach, so an RVE updates only every max_deferred_steps (7) steps or when a large
    increment (`kick`) makes it due."""
    return material(packing, strain_per_substep=1e-3, update_tolerance=1e-3,
                    max_deferred_steps=7, **kw)


def kick(step: int) -> np.ndarray:
    """Increments of 1e-5 per component (spin included), with point p kicked past the
    tolerance at step p: the points' deferrals then run out of step."""
    dH = increments(1, size=1e-5, seed=step)[0]
    if step < 3:
        dH[step] *= 200.0
    return dH


def test_a_material_restored_mid_deferral_goes_on_bitwise(packing):
    """state() / load_state carry the composed increments, the deferred counts and times:
    a material restored with its three points 1, 2 and 3 steps into waiting (none due
    within the next 4 steps) goes on bitwise as the original through each point's next
    update (the bound on deferred steps, at 7), in the stress, the increments, counts,
    times and every point field (rotation_rate is the spin over the time since the
    update before: a lost t_acc shows there, a lost count in when the RVE updates)."""
    a = staggered(packing)
    s_a = a.initial_stress()
    dts = [1e-3 * (1.0 + 0.1 * k) for k in range(16)]
    for k in range(4):
        a.update(kick(k), dts[k], s_a)
    assert list(a.deferred) == [3, 2, 1] and (a.t_acc > 0).all()
    b = staggered(packing)
    b.load_state({k: np.copy(v) for k, v in a.state().items()})
    s_b = s_a.copy()
    updated = np.zeros(3, bool)
    for k in range(4, 12):
        a.update(kick(k), dts[k], s_a)
        b.update(kick(k), dts[k], s_b)
        updated |= a.deferred == 0
        assert np.array_equal(s_a, s_b), k
        for name in ("H_acc", "deferred", "t_acc", "spin_rate", "theta_prev"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), (k, name)
        for name, v in a.point_fields().items():
            assert np.array_equal(v, b.point_fields()[name]), (k, name)
    assert updated.all()  # every point updated after the restore


def test_a_waiting_rves_spin_rate_is_over_the_time_since_its_last_update(packing):
    """rotation_rate of an RVE that waited k MPM steps of different dt is its change of
    mean rolling angle over the sum of those dt (the time its grains' rotation took),
    not over the last step's dt alone."""
    m = staggered(packing)
    s = m.initial_stress()
    theta = mean_rotation(m)
    since = np.zeros(3)
    checked = 0
    for k in range(12):
        dt = 1e-3 * (1.0 + 0.3 * k)
        m.update(kick(k), dt, s)
        since += dt
        now = mean_rotation(m)
        for p in np.flatnonzero(m.deferred == 0):
            want = (now[p] - theta[p]) / since[p]
            assert m.spin_rate[p] == pytest.approx(want, rel=1e-12), (k, p)
            checked += since[p] > 1.5 * dt  # it had waited: t_acc and dt differ
            theta[p], since[p] = now[p], 0.0
    assert checked >= 3


def test_merged_states_are_the_state_of_all_points(packing):
    """merge_states of a material's state cut into pieces (as ranks write them) gives the
    whole state back, every key, to the bit: a key it dropped (the owed increments, say)
    would resume a run without them."""
    a = staggered(packing)
    s = a.initial_stress()
    for k in range(3):
        a.update(kick(k), 1e-3, s)
    whole = a.state()
    parts = [{k: v[lo:hi] if k.startswith("rve_") or v.shape[:1] == (3,) else v
              for k, v in whole.items()} for lo, hi in ((0, 1), (1, 3))]
    merged = RVEMaterial.merge_states(parts)
    assert sorted(merged) == sorted(whole)
    for k, v in whole.items():
        assert np.array_equal(merged[k], v), k


def test_increments_owed_when_the_tolerance_is_turned_off_are_applied(packing):
    """A run resumed with update_tolerance 0 from a checkpoint in which RVEs still owe
    composed increments (--allow-changed materials.NAME.update_tolerance): the next
    update hands each RVE its owed increment composed with the new one, so its cell ends
    exactly at prod(I + dH) h0 (1e-13, round-off of the products) as if no step had
    been deferred; after it nothing is owed and every RVE steps every step."""
    a = staggered(packing)
    s = a.initial_stress()
    h0 = a.batch.h.copy()
    total = np.tile(np.eye(3), (3, 1, 1))
    for k in range(3, 6):  # no kick: all three wait
        dH = kick(k)
        total = np.einsum("pab,pbc->pac", np.eye(3) + dH, total)
        a.update(dH, 1e-3, s)
    assert (a.deferred == 3).all()
    b = material(packing, strain_per_substep=1e-3)  # update_tolerance 0
    b.load_state({k: np.copy(v) for k, v in a.state().items()})
    dH = kick(6)
    total = np.einsum("pab,pbc->pac", np.eye(3) + dH, total)
    b.update(dH, 1e-3, s)
    for r in range(3):
        np.testing.assert_allclose(b.batch.h[r], total[r] @ h0[r], rtol=0,
                                   atol=1e-13 * np.abs(h0[r]).max())
    assert not b.H_acc.any() and not b.t_acc.any() and not b.deferred.any()


def test_the_tolerance_is_bounded_for_each_time_integration(packing, tmp_path):
    params, pack = packing
    with pytest.raises(ValueError, match=r"update_tolerance = 0.0001 with mode 'dynamic': "
                                         r"valid 0 to 3e-05"):
        RVEMaterial("sand", params, [pack], n_points=1, update_tolerance=1e-4)
    assert RVEMaterial("sand", params, [pack], n_points=1,
                       update_tolerance=3e-5).update_tolerance == 3e-5
    from grainscale.config.base import ConfigError
    from grainscale.config.case import load_case

    case = (tmp_path / "c.toml")
    text = open(__file__.replace("tests/coupling/test_adaptive_updates.py",
                                 "examples/unit_element/case.toml")).read()
    case.write_text(text.replace('time_integration = "dynamic"',
                                 'time_integration = "dynamic"\nupdate_tolerance = 4e-5'))
    with pytest.raises(ConfigError, match=r"materials\.sand\.update_tolerance = 4e-05: "
                                          r"above 3e-05 for dynamic RVEs; valid: 0 to 3e-05"):
        load_case(case)
    case.write_text(text.replace('time_integration = "dynamic"',
                                 'time_integration = "dynamic"\nupdate_tolerance = 1e-6'))
    assert load_case(case).materials["sand"].update_tolerance == 1e-6
    # above one DEM step's strain: refused (it would save nothing and add error)
    case.write_text(text.replace('time_integration = "dynamic"',
                                 'time_integration = "quasi_static"\n'
                                 'strain_per_substep = 2e-6\nupdate_tolerance = 1e-5'))
    with pytest.raises(ConfigError, match=r"update_tolerance = 1e-05: above "
                                          r"strain_per_substep = 2e-06; valid: 0 to"):
        load_case(case)
    with pytest.raises(ValueError, match="valid 0 to strain_per_substep"):
        RVEMaterial("sand", params, [pack], n_points=1, mode="quasi_static",
                    strain_per_substep=2e-6, update_tolerance=1e-5)
    # the default: one DEM step's strain for quasi-static RVEs (written so in
    # case.resolved.toml), 0 for dynamic ones, and no local damping in either
    case.write_text(text.replace('time_integration = "dynamic"',
                                 'time_integration = "quasi_static"\n'
                                 'strain_per_substep = 3e-6'))
    c = load_case(case)
    assert c.materials["sand"].update_tolerance == 3e-6 and c.rve.damping == 0.2  # as set
    case.write_text(case.read_text().replace("\ndamping = 0.2", "\n"))
    assert load_case(case).rve.damping == 0.0
    case.write_text(text)
    assert load_case(case).materials["sand"].update_tolerance == 0.0
    assert RVEMaterial("sand", params, [pack], n_points=1).update_tolerance == 0.0
    assert RVEMaterial("sand", params, [pack], n_points=1, mode="quasi_static",
                       strain_per_substep=4e-6).update_tolerance == 4e-6

"""Sleeping RVEs (dynamic RVEs with update_tolerance > 0, coupling/rve_material.py): an RVE
at rest (its grains near equilibrium and slow) whose composed increment is below the
tolerance is not stepped; its stress is predicted as a waiting quasi-static RVE's; it
wakes at the tolerance, at max_deferred_steps or when its grains are not at rest, and
takes what it owes over a time that keeps its grains in the rate-independent regime or
at the macroscopic rate."""

import math
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from grainscale.analysis import read_columns
from grainscale.cli import main
from grainscale.config.rve import RVEParams
from grainscale.coupling import rve_material
from grainscale.coupling.predictor import predicted_stress
from grainscale.coupling.rve_material import RVEMaterial
from grainscale.dem.generate import generate

sys.path.insert(0, str(Path(__file__).parent))
from test_mpi import small_column  # noqa: E402
from test_multiscale_run import run_folder_with_packings_of  # noqa: E402

DT = 2e-4  # s, the MPM step: a few DEM steps of the packing's dt_crit


@pytest.fixture(scope="module")
def packing():
    """A 150-sphere packing at 100 kPa, left near equilibrium by its preparation
    (unbalanced-force ratio ~2e-3, fluctuation inertial number ~2e-3: at rest)."""
    params = RVEParams(particles=150, damping=0.0,
                       preparation={"pressure": 100e3, "porosity": 0.38,
                                    "porosity_tolerance": 0.005})
    return params, generate(params)


def material(packing, n=3, **kw) -> RVEMaterial:
    params, pack = packing
    return RVEMaterial("sand", params, [pack], n_points=n, mode="dynamic", retile_width=0.0,
                       **kw)


def pressure(m: RVEMaterial) -> np.ndarray:
    """(P,) each RVE's mean stress [Pa], compression positive."""
    return -np.trace(m.batch.stress, axis1=1, axis2=2) / 3.0


def moduli(m: RVEMaterial) -> np.ndarray:
    """(P,) each RVE's largest affine modulus max_k M_k [Pa]."""
    return np.diagonal(m.batch.stiffness, axis1=1, axis2=2).max(axis=1)


def inertial_of_fluctuation(m: RVEMaterial) -> np.ndarray:
    """(P,) sqrt(2 E_k rho_s / (M p)) of each RVE, from its grains."""
    b = m.batch
    return np.sqrt(2.0 * b.kinetic * m.params.density / (b.mass.sum(axis=1) * pressure(m)))


def test_rves_at_rest_sleep_and_wake_owing_their_whole_increment(packing):
    """Increments of up to 2.5e-6 per component and step (spin included) against a
    tolerance of 1e-5: each RVE sleeps while its composed increment is below the tolerance, its
    stress meanwhile the predictor's (coupling/predictor.py) to the bit. On waking its
    cell ends exactly at prod(I + dH) h0 (1e-13: round-off of the products), and it took
    its increment over max(n, ceil(min(T_I, t_acc) / dt_DEM)) DEM steps, T_I =
    max|H_acc| d sqrt(rho_s / p) / 1e-3 computed here from its grains (n: one MPM
    step's): the rate its grains saw kept the inertial number at or below 1e-3, or was
    the macroscopic rate."""
    m = material(packing, update_tolerance=1e-5, max_deferred_steps=50)
    assert (inertial_of_fluctuation(m) < rve_material.QUIET_INERTIAL).all()
    assert (m.batch.unbalanced < rve_material.QUIET_UNBALANCED).all()
    assert (m.batch.unbalanced * pressure(m) < moduli(m) * 1e-5).all()
    s = m.initial_stress()
    h0 = m.batch.h.copy()
    n = max(1, math.ceil(DT / m.dt_crit - 1e-9))
    dt_dem = DT / n
    rng = np.random.default_rng(1)
    total = np.tile(np.eye(3), (3, 1, 1))
    last_stress = m.batch.stress.copy()
    last_moduli = m.batch.stiffness.copy()
    woke = 0
    for k in range(30):
        dH = rng.uniform(-1e-6, 1e-6, (3, 3, 3))
        dH[:, 2, 2] = -2.5e-6  # compressed along z: a path, not jiggle
        dH[1] *= 0.3  # point 1 strains slower: the points fall out of step
        total = np.einsum("pab,pbc->pac", np.eye(3) + dH, total)
        owed = m.H_acc + dH + np.einsum("pab,pbc->pac", dH, m.H_acc)
        t_owed = m.t_acc + DT
        p = -np.trace(m.batch.stress, axis1=1, axis2=2) / 3.0
        d = 2.0 * m.batch.radius.mean(axis=1)
        before = m.dem_steps.copy()
        slept = m.deferred > 0
        m.update(dH, DT, s)
        for r in range(3):
            if m.deferred[r] > 0:  # asleep: the predictor's stress, no DEM step
                assert m.dem_steps[r] == before[r]
                want = predicted_stress(last_stress[r:r + 1], last_moduli[r:r + 1],
                                        m.H_acc[r:r + 1], m.cp.stiffness_ratio)[0]
                assert np.array_equal(s[r], want)
                continue
            assert np.abs(owed[r]).max() >= 1e-5 or not slept[r]
            np.testing.assert_allclose(m.batch.h[r], total[r] @ h0[r], rtol=0,
                                       atol=1e-13 * np.abs(h0[r]).max())
            want = n
            if slept[r]:
                t_rate = np.abs(owed[r]).max() * d[r] * math.sqrt(
                    m.params.density / p[r]) / rve_material.WAKE_INERTIAL
                want = max(n, math.ceil(min(t_rate, t_owed[r]) / dt_dem - 1e-9))
                woke += 1
                rate = np.abs(owed[r]).max() / (want * dt_dem)
                inertial = rate * d[r] * math.sqrt(m.params.density / p[r])
                assert inertial <= 1e-3 * (1 + 1e-9) or want * dt_dem >= t_owed[r] * (
                    1 - 1e-9) or want == n
            assert m.dem_steps[r] - before[r] == want, (k, r)
            last_stress[r] = m.batch.stress[r]
            last_moduli[r] = m.batch.stiffness[r]
    assert woke >= 6
    assert m.rve_updates < 0.5 * 30 * 3  # they slept most of the time


def test_an_rve_whose_grains_are_not_at_rest_never_sleeps(packing):
    """Point 1's grains are given a fluctuating velocity that puts the inertial number of
    their motion above QUIET_INERTIAL: that RVE is stepped every MPM step while the two
    at rest sleep. An unbalanced-force ratio above QUIET_UNBALANCED (a rearranging
    RVE's), or one below it whose share of p exceeds max_k M_k tol (the stress its
    imbalance can release beyond what the tolerance resolves), wakes an RVE too."""
    m = material(packing, update_tolerance=1e-5, max_deferred_steps=50)
    b = m.batch
    p = -np.trace(b.stress[1]) / 3.0
    v = np.sqrt(p / m.params.density) * 0.05  # a fluctuation speed of I_v ~ 0.05
    b.v[1] = np.random.default_rng(0).normal(scale=v / math.sqrt(3.0), size=b.v[1].shape)
    b.kinetic[1] = 0.5 * (b.mass[1] * (b.v[1] ** 2).sum(axis=1)).sum()
    assert inertial_of_fluctuation(m)[1] > rve_material.QUIET_INERTIAL
    s = m.initial_stress()
    dH = np.full((3, 3, 3), 1e-8)
    for _ in range(5):
        m.update(dH, DT, s)
        assert list(m.deferred[[0, 2]] > 0) == [True, True] and m.deferred[1] == 0
    b.unbalanced[2] = 2 * rve_material.QUIET_UNBALANCED
    m.update(dH, DT, s)
    assert m.deferred[2] == 0 and m.deferred[0] > 0
    m.update(dH, DT, s)
    assert m.deferred[2] > 0  # its update left it at rest again
    noisy = 2e-5 * moduli(m)[0] / pressure(m)[0]  # twice what the tolerance resolves
    assert noisy < rve_material.QUIET_UNBALANCED
    b.unbalanced[0] = noisy
    m.update(dH, DT, s)
    assert m.deferred[0] == 0 and m.deferred[2] > 0


def test_a_loose_rve_sleeps_and_wakes_at_the_rate_its_collisions_allow(packing):
    """Point 1's cell is stretched 1 % in every direction in one step: its contacts open
    and its stress falls below LOOSE p_prep (its grains keep their fluctuating motion,
    so by the loaded criteria it would not be at rest). It sleeps all the same, and
    wakes at max_deferred_steps owing its increments, over the time that keeps its
    collisional stress rho_s d^2 (max|H| / T)^2 below LOOSE p_prep: here one MPM step's
    DEM steps; the cell ends at prod(I + dH) h0."""
    m = material(packing, update_tolerance=1e-5, max_deferred_steps=4)
    s = m.initial_stress()
    dH = np.zeros((3, 3, 3))
    dH[1] = 0.01 * np.eye(3)
    m.update(dH, DT, s)
    b = m.batch
    assert np.abs(b.stress[1]).max() <= rve_material.LOOSE * m.params.preparation.pressure
    assert m._loose(b)[1] and not m._loose(b)[0]
    h0 = b.h[1].copy()
    n = max(1, math.ceil(DT / m.dt_crit - 1e-9))
    small = np.full((3, 3, 3), 2e-6)  # below the tolerance in 4 steps: 8e-6
    total = np.eye(3)
    for k in range(4):
        before = m.dem_steps[1]
        total = (np.eye(3) + small[1]) @ total
        m.update(small, DT, s)
        if k < 3:
            assert m.deferred[1] == k + 1 and m.dem_steps[1] == before
    assert m.deferred[1] == 0 and m.dem_steps[1] - before == n  # woke: one step's worth
    np.testing.assert_allclose(m.batch.h[1], total @ h0, rtol=0, atol=1e-13 * np.abs(h0).max())


def test_a_tolerance_no_increment_falls_below_is_bitwise_every_step(packing):
    """Dynamic RVEs with a tolerance of 1e-300 step every RVE every MPM step with the
    stress, DEM steps and point fields of update_tolerance = 0, to the bit."""
    ref, sl = material(packing, update_tolerance=0.0), material(packing,
                                                                update_tolerance=1e-300)
    s_ref, s_sl = ref.initial_stress(), sl.initial_stress()
    for dH in np.random.default_rng(2).uniform(-1e-6, 1e-6, (6, 3, 3, 3)):
        ref.update(dH, DT, s_ref)
        sl.update(dH, DT, s_sl)
        assert np.array_equal(s_ref, s_sl)
    assert ref.rve_steps == sl.rve_steps
    for k, v in ref.point_fields().items():
        assert np.array_equal(v, sl.point_fields()[k]), k


def sleeping_column(tmp: Path) -> Path:
    """test_mpi.small_column with sleeping RVEs (tolerance 1e-5, at most 5 steps) and the
    cost columns in its history."""
    path = small_column(tmp)
    case = tomllib.loads(path.read_text())
    case["materials"]["sand"].update(update_tolerance=1e-5, max_deferred_steps=5)
    case["output"]["history"] += ["dem_steps_per_rve", "updates_per_rve"]
    path.write_text(tomli_w.dumps(case))
    return path


def test_a_run_with_sleeping_rves_resumes_bitwise(tmp_path):
    """The reduced column with sleeping RVEs, stopped at step 47 (checkpoints every 10:
    RVEs asleep in the one at step 40) and resumed: history.csv is the uninterrupted
    run's to the byte, its DEM steps per RVE included; some RVEs slept."""
    case = sleeping_column(tmp_path)
    ref = tmp_path / "full"
    assert main(["run", str(case), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    history = (ref / "history.csv").read_text()
    part = run_folder_with_packings_of(ref, tmp_path / "part")
    common = ["run", str(case), "--out", str(part), "--quiet", "--threads", "1",
              "--checkpoint-every", "10"]
    assert main([*common, "--max-steps", "47"]) == 0
    assert main([*common, "--resume"]) == 0
    assert (part / "history.csv").read_text() == history
    h = read_columns(ref / "history.csv")
    steps, updates = h["step"][-1], h["updates_per_rve"][-1]
    assert updates < 0.97 * steps, (updates, steps)  # some RVEs slept
    assert h["dem_steps_per_rve"][-1] >= updates

"""Drained triaxial compression of a generated packing: the stress path of a
medium-dense frictional sphere assembly.

Expected physics (seed Fig. 4-5; Thornton 2000, Geotechnique 50(1)): lateral stresses
held at the confining pressure; q/p rises steeply, peaks at a few % axial strain and
softens toward a lower residual value; the volume first contracts slightly, then
dilates, and dilation slows as the residual state is approached.

Reference data (tests/data/triaxial_150/, README there): the same test of the same stored
150-sphere packing run in YADE 2023.02a (same contact law, damping, time step and servo),
in several realisations.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from dem_helpers import SMALL_PARAMS

from grainscale.config.case import load_rve_case
from grainscale.config.rve import RVEParams, TriaxialTest
from grainscale.dem import element_tests
from grainscale.dem.state import from_packing
from grainscale.io.packing import load_packing, read_packing

DATA = Path(__file__).resolve().parents[1] / "data" / "triaxial_150"


def smooth(y, k):
    """Running mean over k rows (noise of a small RVE: stick-slip events)."""
    return np.convolve(y, np.ones(k) / k, mode="valid")


def check_path(rows, confining, window, peak_range=None, soften=None):
    """Assert the drained-compression stress path; returns (axial, q/p, eps_v).

    peak_range: bounds of the peak of q/p (smoothed over `window` rows), or None when the
    caller checks the peak itself.

    soften=None: only require no hardening after the peak (small RVEs: whether and how
    much they soften is a matter of the realisation); else the mean q/p over the last
    5 % of strain must be below soften x its mean over the peak region (2-6 %).
    """
    a = np.array([r["axial_strain"] for r in rows])
    qp = np.array([r["q_over_p"] for r in rows])
    ev = np.array([r["volumetric_strain"] for r in rows])
    lateral = np.array([[r["sigma_xx"], r["sigma_yy"]] for r in rows])
    # 1. lateral stresses at the confining pressure within 2 %, on the running mean over
    #    `window` rows: the proportional servo lags by an error proportional to the
    #    lateral strain rate (< 1 % here) and cannot anticipate the stress drops of
    #    individual slip events, which in a 150-sphere RVE reach ~2 % for a few rows
    #    (measured up to 2.2 % at 0.1 /s); single rows within 4 %
    dev = lateral / confining - 1.0
    assert np.all(np.abs(dev) < 0.04)
    assert np.all(np.abs(np.stack([smooth(dev[:, 0], window), smooth(dev[:, 1], window)]))
                  < 0.02)
    # 2. q/p rises steeply (elastic stiffness: well above 0.5 within 1 % strain) ...
    assert qp[np.searchsorted(a, 0.01)] > 0.5
    # ... to a peak, on the smoothed curve (running mean over `window` rows: stick-slip
    # noise of a small RVE)
    sm = smooth(qp, window)
    k = int(np.argmax(sm))
    if peak_range is not None:
        assert peak_range[0] < sm[k] < peak_range[1]
    # 3. after the peak region (2-6 % strain) q/p does not harden further: the mean over
    #    the last 5 % of strain stays below 1.05 x the mean over 2-6 % (measured ratios
    #    0.75-1.00 over 5 seeds of 150 spheres; 0.83 for 800 spheres)
    peak_region = qp[(a > 0.02) & (a < 0.06)].mean()
    residual = qp[a > a[-1] - 0.05].mean()
    assert residual < 1.05 * peak_region
    if soften is not None:
        assert smooth(a, window)[k] < 0.10  # the peak is at a few % strain
        assert residual < soften * peak_region
    # 4. volume: contraction first (eps_v < 0 within the first 2 %), then dilation
    early = a < 0.02
    assert ev[early].min() < -5e-4
    assert ev[-1] > 0.01 and ev[-1] > 5 * abs(ev[early].min())
    assert a[np.argmin(ev)] < 0.02 < a[np.argmax(ev)]
    return a, qp, ev


def _yade_runs():
    """The YADE realisations: (axial strain, q/p, eps_v) rows every 0.002 from 0.002."""
    return [np.loadtxt(f, delimiter=",", skiprows=1)[:, :3]
            for f in sorted(DATA.glob("yade_*.csv"))]


def test_triaxial_small_against_yade():
    """150 spheres (the stored packing of tests/data/triaxial_150) to 15 % axial strain
    at 0.1 /s (inertial number I = rate d sqrt(rho/p) ~ 2e-4: quasi-static); window of
    5 rows = 1 % strain. Against the same test in YADE 2023.02a:

    1. Up to 1 % axial strain, before slip events make each run a different realisation,
       the paths are the same: q/p within 6e-3 and eps_v within 1.5e-4 of every YADE
       run, row by row. Measured: 1.3e-3 and 8e-6 apart (7 YADE runs); realisations of
       our own (grain velocities perturbed by 1e-9 m/s, 16 runs) spread by up to 3.9e-3
       and 7.9e-5 at 1 %. A contact law off by a little is outside: friction 0.48
       instead of 0.5 moves q/p by 1.2e-2, kt/kn 0.7 instead of 0.8 by 1.4e-2, kt 10 %
       low by 1.1e-2, E 10 % low by 6e-2 (and eps_v by 1.3e-3).
    2. The peak of q/p (smoothed) within 0.08 of YADE's mean peak. Realisations peak at
       1.133 +- 0.019 here (16 runs, 1.113-1.194) and at 1.124 +- 0.006 in YADE (the
       7 stored runs); 0.08 is 4 standard deviations of one realisation, so that any
       machine's realisation passes: +-7 % where the old band 0.8-1.5 allowed +-30 %.
       One realisation cannot pin the law tighter (0.9 mu peaks at 1.059, inside),
       which is what check 1 does (0.9 mu moves the early path by 3.2e-2).
    3. The final dilation, eps_v at 15 %, within 0.02 of YADE's mean: realisations end
       at 0.038 +- 0.007 here (0.026-0.052), YADE's at 0.039 +- 0.007.
    """
    h, centres, radii = read_packing(DATA / "packing.txt")
    b = from_packing(h, centres, radii, SMALL_PARAMS.density)
    test = TriaxialTest(confining_pressure=100e3, axial_strain=0.15, strain_rate=0.1,
                        output_interval=0.002)
    rows = element_tests.triaxial(b, SMALL_PARAMS, test)
    assert rows[-1]["axial_strain"] == pytest.approx(0.15, abs=0.003)
    a, qp, ev = check_path(rows, 100e3, window=5)
    refs = _yade_runs()
    assert len(refs) >= 4
    for ref in refs:
        n = len(ref)
        # the same rows: same time step, rows every 0.002 of axial strain
        np.testing.assert_allclose(a[1:n + 1], ref[:, 0], rtol=0, atol=1e-5)
        early = ref[:, 0] < 0.0101
        assert early.sum() == 5
        np.testing.assert_allclose(qp[1:n + 1][early], ref[early, 1], rtol=0, atol=6e-3)
        np.testing.assert_allclose(ev[1:n + 1][early], ref[early, 2], rtol=0, atol=1.5e-4)
    peak = smooth(qp, 5).max()
    ref_peak = np.mean([smooth(ref[:, 1], 5).max() for ref in refs])
    assert abs(peak - ref_peak) < 0.08, (peak, ref_peak)
    ref_dilation = np.mean([ref[-1, 2] for ref in refs])
    assert abs(ev[-1] - ref_dilation) < 0.02, (ev[-1], ref_dilation)


@pytest.mark.validation
def test_triaxial_unit_element_800():
    """Seed section 4.1 RVE (800 spheres, the stored packing of tests/data/triaxial_800)
    to 30 % axial strain at 0.25 /s (I ~ 4e-4), against the same test in YADE 2023.02a
    (one run, tests/data/triaxial_800; made as in tests/data/triaxial_150/README.md with
    AXIAL 0.3 and RATE 0.25). The larger RVE is less noisy: it must soften, the residual
    (last 5 %) q/p at least 10 % below the peak region (measured 17 %); up to 1 % strain
    the paths agree as for 150 spheres (measured 1.8e-3 in q/p, 8e-6 in eps_v, over 8
    realisations); its smoothed peak, 0.998 +- 0.005 over 8 realisations here and 1.002
    in YADE, within 0.03 (4 standard deviations of the difference of two
    realisations); eps_v at 30 %, 0.049 +- 0.003 here and 0.046 in YADE, within 0.015."""
    params = RVEParams(preparation={"pressure": 100e3, "porosity": 0.373})
    h, centres, radii = read_packing(DATA.parent / "triaxial_800" / "packing.txt")
    b = from_packing(h, centres, radii, params.density)
    test = TriaxialTest(confining_pressure=100e3, axial_strain=0.3, strain_rate=0.25,
                        output_interval=0.002)
    rows = element_tests.triaxial(b, params, test)
    a, qp, ev = check_path(rows, 100e3, window=5, soften=0.9)
    assert rows[-1]["axial_strain"] == pytest.approx(0.3, abs=0.003)
    ref = np.loadtxt(DATA.parent / "triaxial_800" / "yade_0.csv", delimiter=",",
                     skiprows=1)
    n = len(ref)
    np.testing.assert_allclose(a[1:n + 1], ref[:, 0], rtol=0, atol=1e-5)
    early = ref[:, 0] < 0.0101
    np.testing.assert_allclose(qp[1:n + 1][early], ref[early, 1], rtol=0, atol=6e-3)
    np.testing.assert_allclose(ev[1:n + 1][early], ref[early, 2], rtol=0, atol=1.5e-4)
    assert abs(smooth(qp, 5).max() - smooth(ref[:, 1], 5).max()) < 0.03
    assert abs(ev[-1] - ref[-1, 2]) < 0.015


def curves(rows):
    """(axial strain, q/p, eps_v) of a triaxial's rows after the first (the state
    before any step, which YADE's files start with too)."""
    return tuple(np.array([r[k] for r in rows])[1:]
                 for k in ("axial_strain", "q_over_p", "volumetric_strain"))


def check_bands(a, qp, ev, ref):
    """The YADE comparisons' bands (issue 58): the smoothed peak of q/p within 5 %, the
    residual (mean over the last 5 % of strain) within 10 %, eps_v within 0.01 at 10
    and 20 % axial strain; ref the YADE rows matching a (axial, q/p, eps_v first)."""
    peak, ref_peak = smooth(qp, 5).max(), smooth(ref[:, 1], 5).max()
    assert abs(peak / ref_peak - 1.0) < 0.05, (peak, ref_peak)
    last = a > a[-1] - 0.05
    residual, ref_residual = qp[last].mean(), ref[last, 1].mean()
    assert abs(residual / ref_residual - 1.0) < 0.10, (residual, ref_residual)
    for strain in (0.1, 0.2):
        k = int(np.argmin(np.abs(a - strain)))
        assert abs(ev[k] - ref[k, 2]) < 0.01, (strain, ev[k], ref[k, 2])


@pytest.mark.validation
@pytest.mark.parametrize("eta", [0.1, 0.3])
def test_triaxial_800_with_rolling_resistance_against_yade(eta):
    """The 800-sphere packing of test_triaxial_unit_element_800 with rolling resistance
    (alpha_r = 1, eta_r = 0.1 and 0.3), to 30 % axial strain at 0.25 /s, against the
    same test in YADE 2023.02a with CohFrictMat and Law2_ScGeom6D_CohFrictPhys_
    CohesionMoment (incremental form; tests/data/triaxial_800/README.md): the smoothed
    peak of q/p within 5 %, the residual (mean over the last 5 % of strain) within 10 %
    and eps_v within 0.01 at 10 and 20 % axial strain. One realisation each, both from
    rest; up to 1 % strain the paths must still agree row by row as without rolling
    (q/p within 6e-3, eps_v within 1.5e-4: the same contact law, before slip events
    make each run its own realisation)."""
    params = RVEParams(preparation={"pressure": 100e3, "porosity": 0.373},
                       rolling_stiffness=1.0, rolling_friction=eta)
    h, centres, radii = read_packing(DATA.parent / "triaxial_800" / "packing.txt")
    b = from_packing(h, centres, radii, params.density)
    test = TriaxialTest(confining_pressure=100e3, axial_strain=0.3, strain_rate=0.25,
                        output_interval=0.002)
    a, qp, ev = curves(element_tests.triaxial(b, params, test))
    ref = np.loadtxt(DATA.parent / "triaxial_800" / f"yade_rolling_1_{eta}.csv",
                     delimiter=",", skiprows=1)
    n = len(ref)
    assert n == len(a)
    np.testing.assert_allclose(a, ref[:, 0], rtol=0, atol=1e-5)  # the same time step
    early = ref[:, 0] < 0.0101
    np.testing.assert_allclose(qp[early], ref[early, 1], rtol=0, atol=6e-3)
    np.testing.assert_allclose(ev[early], ref[early, 2], rtol=0, atol=1.5e-4)
    check_bands(a, qp, ev, ref)


@pytest.mark.validation
def test_triaxial_800_hertz_mindlin_against_yade():
    """The seed's 800-sphere RVE with Hertz-Mindlin contacts (examples/rve/hertz_mindlin.toml:
    E = 70 GPa, nu = 0.25; its packing in tests/data/triaxial_800_hertz, generated with that
    law at 100 kPa) to 30 % axial strain at 0.25 /s, against the same test of the same
    packing in YADE 2023.02a (Ip2_FrictMat_FrictMat_MindlinPhys, Law2_ScGeom_MindlinPhys_
    Mindlin, same time step, damping and servo; README there): the smoothed peak of q/p
    within 5 %, the residual (mean over the last 5 % of strain) within 10 % and eps_v
    within 0.01 at 10 and 20 % (the issue's bands; measured 2.5 %, 1.1 %, 0.0005 and
    0.0075). One realisation each, from rest. Stiff grains (stiffness number ~5000) reach
    q/p 0.94 within 0.2 % strain and slip events part the two runs soon after: from 0.6 %
    on on one machine, from 0.4 % on another (its CPU's round-off: q/p 7e-3 from YADE's
    there), so the row-by-row agreement is checked on the first row only (0.2 %; measured
    3e-3 in q/p on both machines, 1e-5 in eps_v): a law off by its 2/3 or E for E* moves
    it by > 0.02 and 1e-4."""
    path = Path(__file__).resolve().parents[2] / "examples" / "rve" / "hertz_mindlin.toml"
    case = load_rve_case(path)
    h, centres, radii = read_packing(DATA.parent / "triaxial_800_hertz" / "packing.txt")
    b = from_packing(h, centres, radii, case.rve.density)
    a, qp, ev = curves(element_tests.triaxial(b, case.rve, case.triaxial))
    ref = np.loadtxt(DATA.parent / "triaxial_800_hertz" / "yade_0.csv", delimiter=",",
                     skiprows=1)[1:]
    assert len(ref) == len(a)
    np.testing.assert_allclose(a, ref[:, 0], rtol=0, atol=1e-5)  # the same time step
    np.testing.assert_allclose(qp[:1], ref[:1, 1], rtol=0, atol=5e-3)
    np.testing.assert_allclose(ev[:1], ref[:1, 2], rtol=0, atol=3e-5)
    check_bands(a, qp, ev, ref)


def band_figures(a, qp, ev):
    """check_bands' measures of one run: smoothed peak of q/p, residual (mean over the
    last 5 % of strain), eps_v at 10 and 20 % axial strain."""
    last = a > a[-1] - 0.05
    at = [ev[int(np.argmin(np.abs(a - s)))] for s in (0.1, 0.2)]
    return np.array([smooth(qp, 5).max(), qp[last].mean(), *at])


@pytest.mark.validation
@pytest.mark.parametrize("name", ["elongated", "tetrahedral"])
def test_triaxial_of_clumps_against_yade(name):
    """Clumps (docs/dem.md) against YADE 2023.02a: the packings of
    examples/rve/clumps.toml (400 two-sphere clumps, aspect 1.5) and
    clumps_tetrahedral.toml (200 four-sphere tetrahedral clumps), both with the linear
    law of the unit element, in the drained triaxial at 100 kPa, 0.25 /s to 30 %, against
    YADE's runs of the same packing with appendClumped (tests/data/triaxial_clumps).

    1. The first row (0.2 % axial strain, before slip events part the runs), from rest:
       q/p within 3e-3 and eps_v within 2e-4 of YADE's (measured 4e-4 and 2e-5 for the
       rods, 7e-4 and 8e-5 for the tetrahedra; YADE integrates each clump's mass and
       inertia on its own grid, 0.2 % and 1 % from grainscale's).
    2. Issue 58's bands on the means over realisations: peak q/p within 5 %, residual
       within 10 %, eps_v within 0.01 at 10 and 20 %, grainscale's mean over five (from
       rest and four with velocities perturbed by 1e-9 m/s: studies/grains/
       against_yade.py's) against YADE's over its five stored runs. These loose packings
       (porosity 0.419 and 0.466) contract by 5-7 % and one realisation's peak strays by
       5 % (one standard deviation) from another's, so one run against one run is no
       test of the law (docs/validation.md §4.2). Measured: rods 0.1 %, 0.03 %, 0.0018,
       0.0017; tetrahedra 3.4 %, 3.6 %, 0.0006, 0.0064."""
    example = {"elongated": "clumps.toml", "tetrahedral": "clumps_tetrahedral.toml"}[name]
    case = load_rve_case(Path(__file__).resolve().parents[2] / "examples" / "rve" / example)
    data = DATA.parent / "triaxial_clumps"
    refs = [np.loadtxt(f, delimiter=",", skiprows=1)[1:]
            for f in sorted(data.glob(f"yade_{name}*.csv"))]
    ours = []
    for k in range(5):
        b = load_packing(data / f"{name}.txt", case.rve)
        assert b.clumped
        if k > 0:
            b.bv += np.random.default_rng(k - 1).normal(0.0, 1e-9, b.bv.shape)
        a, qp, ev = curves(element_tests.triaxial(b, case.rve, case.triaxial))
        if k == 0:
            ref = refs[0]  # yade_NAME.csv: from rest
            assert abs(ref[0, 0] - a[0]) < 1e-5
            assert abs(qp[0] - ref[0, 1]) < 3e-3 and abs(ev[0] - ref[0, 2]) < 2e-4
        assert abs(a[-1] - 0.3) < 0.005
        ours.append(band_figures(a, qp, ev))
    mine = np.mean(ours, axis=0)
    theirs = np.mean([band_figures(r[:, 0], r[:, 1], r[:, 2]) for r in refs], axis=0)
    assert abs(mine[0] / theirs[0] - 1.0) < 0.05, (mine, theirs)
    assert abs(mine[1] / theirs[1] - 1.0) < 0.10, (mine, theirs)
    assert np.all(np.abs(mine[2:] - theirs[2:]) < 0.01), (mine, theirs)

"""Drained triaxial compression of a generated packing: the stress path of a
medium-dense frictional sphere assembly.

Expected physics (seed Fig. 4-5; Thornton 2000, Geotechnique 50(1)): lateral stresses
held at the confining pressure; q/p rises steeply, peaks at a few % axial strain and
softens toward a lower residual value; the volume first contracts slightly, then
dilates, and dilation slows as the residual state is approached.
"""

from __future__ import annotations

import numpy as np
import pytest
from dem_helpers import SMALL_PARAMS

from grainscale.config.rve import RVEParams, TriaxialTest
from grainscale.dem import element_tests
from grainscale.dem.generate import generate


def smooth(y, k):
    """Running mean over k rows (noise of a small RVE: stick-slip events)."""
    return np.convolve(y, np.ones(k) / k, mode="valid")


def check_path(rows, confining, window, peak_range, soften=None):
    """Assert the drained-compression stress path; returns (axial, q/p, eps_v).

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
    # ... to a peak in the range of frictional spheres with mu = 0.5 (peak friction
    # angle ~21-37 deg: M = 6 sin phi/(3 - sin phi) = 0.8-1.5), on the smoothed curve
    # (running mean over `window` rows: stick-slip noise of a small RVE)
    sm = smooth(qp, window)
    k = int(np.argmax(sm))
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


def test_triaxial_small(small_packing):
    """150 spheres to 15 % axial strain at 0.1 /s (inertial number
    I = rate d sqrt(rho/p) ~ 2e-4: quasi-static). Window of 5 rows = 1 % strain."""
    b = small_packing.copy()
    test = TriaxialTest(confining_pressure=100e3, axial_strain=0.15, strain_rate=0.1,
                        output_interval=0.002)
    rows = element_tests.triaxial(b, SMALL_PARAMS, test)
    assert rows[-1]["axial_strain"] == pytest.approx(0.15, abs=0.003)
    check_path(rows, 100e3, window=5, peak_range=(0.8, 1.5))


@pytest.mark.slow
def test_triaxial_unit_element_800():
    """Seed section 4.1 RVE (800 spheres) to 30 % axial strain at 0.25 /s (I ~ 4e-4).
    The larger RVE is less noisy: it must soften, the residual (last 5 %) q/p at least
    10 % below the peak region (measured 17 %)."""
    params = RVEParams(preparation={"pressure": 100e3, "porosity": 0.373})
    b = generate(params)
    test = TriaxialTest(confining_pressure=100e3, axial_strain=0.3, strain_rate=0.25,
                        output_interval=0.002)
    rows = element_tests.triaxial(b, params, test)
    check_path(rows, 100e3, window=5, peak_range=(0.8, 1.5), soften=0.9)
    assert rows[-1]["axial_strain"] == pytest.approx(0.3, abs=0.003)

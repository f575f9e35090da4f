"""The unit element's comparison metrics (analysis.unit_element_metrics) on paths whose
deviations are known exactly."""

import math

import numpy as np
import pytest

from grainscale.analysis import unit_element_metrics


def _paths(offset, sem):
    eps = np.linspace(0.0, 0.3, 301)
    dem = {"axial_strain": eps, "q_over_p": 1.0 - np.exp(-eps / 0.02),
           "volumetric_strain": 0.1 * eps}
    dem["q_over_p_sem"] = np.full_like(eps, sem)
    dem["volumetric_strain_sem"] = np.full_like(eps, 0.03 * sem)
    ms = {"axial_strain": eps, "q_over_p": dem["q_over_p"] + offset,
          "volumetric_strain": dem["volumetric_strain"] + 0.03 * offset}
    return dem, ms


@pytest.mark.parametrize(("offset", "within"), [(0.02, True), (0.03, False)])
def test_realisation_noise_of_two_ensemble_means(offset, within):
    """A constant offset d is the mean deviation exactly; with a constant standard error
    s of both means, chaos alone gives a mean |difference| of 2 s / sqrt(pi) (the mean
    modulus of a normal of std sqrt(2) s), here 0.0113 for s = 0.01 on q/p (range
    ~1.0) and 0.03 x that on eps_v (range 0.03): an offset of 0.02 lies within twice
    that, 0.03 does not."""
    dem, ms = _paths(offset, 0.01)
    m = unit_element_metrics(dem, ms)
    q_range = np.ptp(dem["q_over_p"])
    assert m["mad_q_over_p"] == pytest.approx(offset, rel=1e-9)
    assert m["noise_q_over_p_over_dem_range"] == pytest.approx(
        2 * 0.01 / math.sqrt(math.pi) / q_range, rel=1e-9)
    assert m["noise_volumetric_strain_over_dem_range"] == pytest.approx(
        2 * 0.0003 / math.sqrt(math.pi) / 0.03, rel=1e-6)
    assert m["within_twice_noise"] is within


def test_no_noise_figures_without_an_ensemble():
    dem, ms = _paths(0.01, 0.01)
    del dem["q_over_p_sem"], dem["volumetric_strain_sem"]
    m = unit_element_metrics(dem, ms)
    assert "within_twice_noise" not in m and "noise_q_over_p_over_dem_range" not in m


@pytest.mark.parametrize(("v_offset", "verdict"), [(0.02, "pass"),
                                                   (0.04, "within realisation noise"),
                                                   (0.05, "fail")])
def test_verdict_weighs_the_realisation_noise(v_offset, verdict):
    """q/p off by 0.02 of its range (peak 2 % apart), eps_v by v_offset of its range,
    with standard errors 0.02 of each range: chaos alone leaves 2 x 0.02 / sqrt(pi) =
    2.26 % of each range between two means. 2 % passes the 3 % acceptance; 4 % fails it
    but lies within twice the noise (4.5 %); 5 % lies outside both."""
    dem, ms = _paths(0.02, 0.02)
    dem["volumetric_strain_sem"] = np.full_like(dem["axial_strain"], 0.02 * 0.03)
    ms["volumetric_strain"] = dem["volumetric_strain"] + v_offset * 0.03
    m = unit_element_metrics(dem, ms)
    assert m["mad_volumetric_strain_over_dem_range"] == pytest.approx(v_offset, rel=1e-9)
    assert m["verdict"] == verdict

"""Unit element test (seed §4.1), reduced for CI: the multiscale curves lie on the pure
DEM curves of the same RVE.

Reduced: RVEs of 300 instead of 800 spheres, loaded to 6 % axial strain (through the
peak) at 0.5 /s. Up to the peak the two runs follow the same packing through nearly the
same deformation; past it, each RVE is one chaotic realisation of strain softening and
the curves separate within the RVE's noise (docs/validation.md shows the full run).
"""

import pytest

from grainscale.analysis import read_columns, unit_element_metrics
from grainscale.cli import main
from grainscale.demo import demo_case


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("ue")
    case = out / "case.toml"
    case.write_text(demo_case(particles=300, strain=0.06, rate=0.5))
    assert main(["run", str(case), "--out", str(out / "ms"), "--quiet"]) == 0
    assert main(["rve", "triaxial", str(case), "--out", str(out / "dem.csv"), "--quiet"]) == 0
    return read_columns(out / "dem.csv"), read_columns(out / "ms" / "history.csv")


def test_multiscale_curves_lie_on_the_pure_dem_curves(runs):
    dem, ms = runs
    m = unit_element_metrics(dem, ms)
    assert m["axial_strain_compared"] == pytest.approx(0.06, abs=1e-3)
    # the acceptance: peak q/p within 3 %, mean deviations within 3 % of range
    assert m["peak_relative_difference"] < 0.03, m
    for key in ("q_over_p", "volumetric_strain"):
        assert m[f"mad_{key}_over_dem_range"] < 0.03, m
        assert m[f"mad_{key}_over_multiscale_range"] < 0.03, m


def test_multiscale_confinement_and_path(runs):
    _, ms = runs
    # drained path under a constant lateral Cauchy stress of 100 kPa: p = 100 kPa + q/3.
    # The traction equals the points' lateral stress only in equilibrium; at this CI rate
    # (0.5 /s, five times the example's) the cube's lateral motion lags the RVEs'
    # stress jumps by a few %: measured 3.5 % at most, 5 % allowed; the mean within 1 %
    # (a nominal traction would sit ~6 % high by the end, with the face area change).
    lateral = ms["p"] - ms["q"] / 3.0
    assert abs(lateral - 100e3).max() < 0.05 * 100e3
    assert abs(lateral.mean() - 100e3) < 0.01 * 100e3
    # medium-dense response: contraction, then dilation; q/p rises to a peak near 1
    assert ms["volumetric_strain"].min() < -5e-4
    assert ms["volumetric_strain"][-1] > 0.0
    assert 0.8 < ms["q_over_p"].max() < 1.3

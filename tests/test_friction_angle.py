"""examples/intrusion/friction_angle.py: the mobilised angle of a known stress state along
each axis, its Student-t band, and a run over generated packings of a tiny RVE."""

import json
import math

import numpy as np
import pytest

from example_scripts import load_example

fa = load_example("intrusion/friction_angle.py")

CASE = """
[rve]
particles = 120
radius_min = 4e-3
radius_max = 5e-3
density = 2650.0
young_modulus = 100e6
stiffness_ratio = 0.8
friction = 0.5
damping = 0.2
seed = 3

[rve.preparation]
pressure = 10e3
porosity = 0.40
porosity_tolerance = 0.03

[triaxial]
confining_pressure = 10e3
axial_strain = 0.15
strain_rate = 0.5
output_interval = 0.005
"""


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_mobilised_angle_of_a_mohr_coulomb_state(axis):
    """sigma_1 / sigma_3 = (1 + sin phi) / (1 - sin phi) on the axis tested, equal lateral
    stresses: the angle is phi exactly, and 0 in an isotropic state."""
    phi = math.radians(27.0)
    ratio = (1 + math.sin(phi)) / (1 - math.sin(phi))
    names = ("sigma_xx", "sigma_yy", "sigma_zz")
    a = fa.AXES[axis]
    rows = [{n: (ratio if k == a else 1.0) * 1e4 for k, n in enumerate(names)},
            {n: 1e4 for n in names}]
    assert fa.mobilised_angle(rows, axis) == pytest.approx([27.0, 0.0], abs=1e-12)


def test_student_t_band():
    """Tabulated quantiles, and the large-dof formula within 0.1 % of t(40) = 2.021 and
    t(120) = 1.980."""
    assert fa.t95(1) == 12.706 and fa.t95(30) == 2.042
    assert fa.t95(40) == pytest.approx(2.021, rel=1e-3)
    assert fa.t95(120) == pytest.approx(1.980, rel=1e-3)
    mean, band = fa.summary(np.array([20.0, 22.0]))
    assert mean == 21.0 and band == pytest.approx(12.706 * math.sqrt(2.0) / math.sqrt(2.0))
    assert math.isnan(fa.summary(np.array([20.0]))[1])


@pytest.mark.validation
def test_realisations_end_to_end(tmp_path):
    """Two generated 120-sphere packings, two axes: a steady angle that a frictional sphere
    packing can have (mu = 0.5 spheres without rolling resistance settle near 20-25 deg;
    a 120-sphere cell is noisy, so the bounds are wide), per axis and packing, and the
    cache reused on a second call."""
    case = tmp_path / "case.toml"
    case.write_text(CASE)
    out = tmp_path / "phi.json"
    assert fa.main([str(case), "--realisations", "2", "--axes", "x", "z", "--from", "0.08",
                    "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert 10.0 < r["phi_deg"] < 35.0
    assert r["peak_phi_deg"] >= r["phi_deg"]
    assert set(r["phi_per_axis_deg"]) == {"x", "z"} and len(r["phi_per_packing_deg"]) == 2
    assert r["packings"] == ["packing_0.h5", "packing_1.h5"]
    stamp = [p.stat().st_mtime_ns for p in sorted((tmp_path / "phi_packings").glob("*.h5"))]
    assert fa.main([str(case), "--realisations", "2", "--axes", "x", "z", "--from", "0.08",
                    "--out", str(out)]) == 0
    assert [p.stat().st_mtime_ns for p in sorted((tmp_path / "phi_packings").glob("*.h5"))] \
        == stamp
    assert json.loads(out.read_text()) == r  # same packings, same batch: same angles

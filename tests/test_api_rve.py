"""grainscale.rve (docs/api.md): each element test and generation from Python give what
`grainscale rve ...` writes, value for value (the CLI calls these functions and writes
their curves with repr, so the CSV holds the same doubles)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import grainscale as gs
from grainscale.analysis import read_columns
from grainscale.cli import main
from grainscale.io.packing import read_packing

PACKING = Path(__file__).parent / "data" / "triaxial_150" / "packing.txt"
PARAMS = """
[rve]
particles = 150
[rve.preparation]
pressure = 100e3
porosity = 0.373
[triaxial]
confining_pressure = 100e3
axial_strain = 0.01
strain_rate = 0.5
output_interval = 0.002
[undrained]
axial_strain = 0.01
strain_rate = 0.5
output_interval = 0.002
[isotropic]
pressure_final = 120e3
strain_rate = 0.05
output_interval = 2e-4
[shear]
normal_stress = 100e3
shear_strain = 0.02
strain_rate = 0.5
output_interval = 0.005
"""


@pytest.fixture(scope="module")
def params(tmp_path_factory):
    path = tmp_path_factory.mktemp("rve") / "params.toml"
    path.write_text(PARAMS)
    return path


@pytest.mark.parametrize("command", ["triaxial", "undrained", "isotropic", "shear"])
def test_each_test_gives_the_cli_curve(params, tmp_path, command):
    out = tmp_path / f"{command}.csv"
    assert main(["rve", command, str(params), "--packing", str(PACKING), "--out", str(out),
                 "--quiet"]) == 0
    cli = read_columns(out)
    case = gs.rve.load(params)
    start = gs.rve.packing(case, PACKING)
    curve = getattr(gs.rve, command)(case, start)
    assert list(curve) == list(cli)
    for key, values in curve.items():
        np.testing.assert_array_equal(values, cli[key], err_msg=key)
    assert len(curve["p"]) > 3
    # the starting packing is left as it was: a second test starts from the same state
    again = getattr(gs.rve, command)(case, start)
    np.testing.assert_array_equal(again["p"], curve["p"])


def test_generate_gives_the_cli_packing(tmp_path):
    """The same recipe generated from Python and by `rve generate`: the same spheres."""
    path = tmp_path / "small.toml"
    path.write_text("[rve]\nparticles = 60\nradius_min = 2e-3\nradius_max = 3e-3\n"
                    "[rve.preparation]\npressure = 50e3\n")
    assert main(["rve", "generate", str(path), "--out", str(tmp_path / "p.txt"),
                 "--quiet"]) == 0
    h, x, r = read_packing(tmp_path / "p.txt")
    lines = []
    b = gs.rve.generate(path, progress=lines.append)
    assert lines and "porosity" in lines[-1]
    np.testing.assert_allclose(b.h[0], h, rtol=1e-15)
    np.testing.assert_allclose(b.radius[0], r, rtol=1e-15)
    np.testing.assert_allclose(b.s[0] @ b.h[0].T, x, rtol=0, atol=1e-15)
    with pytest.raises(TypeError, match="RVECase"):
        gs.rve.triaxial({"rve": {}})

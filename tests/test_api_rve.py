"""grainscale.rve (docs/api.md): each element test and generation from Python give what
`grainscale rve ...` writes, value for value (the CLI calls these functions and writes
their curves with repr, so the CSV holds the same doubles)."""

from __future__ import annotations

import tomllib
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
    import tomllib  # the same tables given as a dict: the same packing

    d = gs.rve.generate(tomllib.loads(path.read_text()), progress=False)
    np.testing.assert_array_equal(d.s, b.s)
    with pytest.raises(gs.ConfigError, match="particles"):
        gs.rve.generate({"rve": {"particles": -3}})
    with pytest.raises(TypeError, match="RVECase"):
        gs.rve.triaxial(42)


FLOW = """
[rve]
particles = 100
radius_min = 3e-3
radius_max = 7e-3
friction = 0.5
restitution = 0.9
damping = 0.0
[rve.preparation]
pressure = 100e3
"""


def test_flow_gives_the_cli_table_and_names_bad_arguments(tmp_path, capsys):
    """rve.flow and `grainscale rve flow` on the same packing and rates: the same steady
    rows to the last digit (the CLI writes the API's table with repr), and the fitted
    table is the one the CLI writes. Three rates, the friction rising with I at a
    falling slope (0.34, 0.43, 0.51 at I = 0.033, 0.098, 0.30): the three-parameter law
    passes through all three points, inside its bounds, so the fit exists; two rates
    cannot fit it, and neither the API nor the CLI gives a table then. Bad arguments
    are named with the API's keywords."""
    path = tmp_path / "flow.toml"
    path.write_text(FLOW)
    packing = tmp_path / "p.h5"
    assert main(["rve", "generate", str(path), "--out", str(packing), "--quiet"]) == 0
    args = ["--rates", "20", "60", "200", "--strain", "0.6", "--steady-from", "0.2"]
    out = tmp_path / "flow.csv"
    assert main(["rve", "flow", str(path), "--packing", str(packing), *args, "--out",
                 str(out), "--quiet"]) == 0
    cli = read_columns(out)
    case = gs.rve.load(path)
    res = gs.rve.flow(case, gs.rve.packing(case, packing), rates=[20, 60, 200], strain=0.6,
                      steady_from=0.2, progress=False, source=str(path))
    assert list(res["table"]) == list(cli)
    for key, values in res["table"].items():
        np.testing.assert_array_equal(values, cli[key], err_msg=key)
    assert res["fit_error"] is None and res["fits"]["mu"]["warning"] == ""
    assert out.with_suffix(".mu_i.toml").read_text() == res["material"]
    fit = res["fits"]["mu"]
    law = fit["mu_s"] + (fit["mu_2"] - fit["mu_s"]) / (fit["I_0"] / res["table"]["I"] + 1.0)
    np.testing.assert_allclose(law, res["table"]["mu"], rtol=1e-9)  # through the points
    assert 0.0 < fit["mu_s"] < res["table"]["mu"].min() < res["table"]["mu"].max() < fit["mu_2"]
    table = tomllib.loads(res["material"])["materials"]["rve_fit"]
    assert table["type"] == "mu_i"
    assert (table["mu_s"], table["mu_2"]) == (round(fit["mu_s"], 4), round(fit["mu_2"], 4))
    assert table["I_0"] == pytest.approx(fit["I_0"], rel=1e-3)  # written to 4 digits
    slowest = int(np.argmin(res["table"]["I"]))  # bulk density at the slowest rate
    assert table["density"] == pytest.approx(
        (1.0 - res["table"]["porosity"][slowest]) * case.rve.density, rel=1e-5)
    two = tmp_path / "two.csv"
    capsys.readouterr()
    assert main(["rve", "flow", str(path), "--packing", str(packing), "--rates", "20", "60",
                 "--strain", "0.6", "--steady-from", "0.2", "--out", str(two), "--quiet"]) == 0
    assert "no mu(I) fit: 2 distinct inertial numbers" in capsys.readouterr().out
    assert two.is_file() and not two.with_suffix(".mu_i.toml").exists()
    res = gs.rve.flow(case, gs.rve.packing(case, packing), rates=[20, 60], strain=0.6,
                      steady_from=0.2, progress=False)
    assert res["material"] is None and res["fits"] == {}
    assert res["fit_error"].startswith("2 distinct inertial numbers")
    for bad, shown in ((dict(strain=30.0), "strain = 30.0"),
                       (dict(tiles=0), "tiles = 0"),
                       (dict(steady_from=0.5, strain=0.6), "steady_from = 0.5"),
                       (dict(pressures=[-5.0]), "pressures = -5.0")):
        kw = {"rates": [20.0], **bad}
        with pytest.raises(gs.ConfigError, match=shown):
            gs.rve.flow(case, progress=False, **kw)
    with pytest.raises(gs.ConfigError, match="inertial"):
        gs.rve.flow(case, progress=False)


@pytest.mark.validation  # 7 s of element tests
def test_several_packings_tested_together_give_each_its_own_curve(params, tmp_path):
    """packing() of several files and triaxial(per_rve=True): one curve per RVE. Two
    copies of one packing give, each, the curve of that packing tested alone (a batch
    shares one time step, the smallest RVE's, so only copies are comparable value for
    value with a test alone); a different packing gives a different curve; save() writes
    a packing that packing() reads back."""
    case = gs.rve.load(params)
    alone = gs.rve.triaxial(case, gs.rve.packing(case, PACKING), progress=False)
    twice = gs.rve.triaxial(case, gs.rve.packing(case, [PACKING, PACKING]), per_rve=True,
                            progress=False)
    assert len(twice) == 2
    for got in twice:
        np.testing.assert_allclose(got["q_over_p"], alone["q_over_p"], rtol=1e-12)
    other = tmp_path / "other.h5"
    gs.rve.save(case, gs.rve.generate(case, seed=7, progress=False), other)
    mixed = gs.rve.triaxial(case, gs.rve.packing(case, [PACKING, other]), per_rve=True,
                            progress=False)
    assert abs(mixed[0]["q_over_p"][-1] - mixed[1]["q_over_p"][-1]) > 1e-3
    with pytest.raises(gs.ConfigError, match="does not exist"):
        gs.rve.packing(case, [PACKING, tmp_path / "missing.h5"])


def test_generate_caches_a_packing_by_recipe_and_seed(tmp_path):
    """generate(path=...): the first call writes the packing, a second reads it back
    (the same spheres, without generating: no status lines); another seed is another
    packing and replaces it."""
    path = tmp_path / "small.toml"
    path.write_text("[rve]\nparticles = 60\nradius_min = 2e-3\nradius_max = 3e-3\n"
                    "[rve.preparation]\npressure = 50e3\n")
    cache = tmp_path / "cache.h5"
    a = gs.rve.generate(path, path=cache, progress=False)
    assert cache.is_file()
    b = gs.rve.generate(path, path=cache, progress=False)
    np.testing.assert_array_equal(a.s, b.s)
    c = gs.rve.generate(path, seed=2, path=cache, progress=False)
    assert not np.array_equal(a.radius, c.radius)
    with pytest.raises(gs.ConfigError, match="path"):
        gs.rve.generate(path, path=tmp_path / "cache.txt")


def test_progress_in_a_log_is_a_few_plain_lines(params, capfd, monkeypatch):
    """With stderr a file (a batch log), an element test's progress is plain lines (one
    at the end while the interval between lines has not passed), never a bar redrawn at
    each row; progress=False is silent."""
    from grainscale.io import progress

    # the interval made endless, so that a slow (loaded, cold-cache) test still gets the
    # final line only; the lines' timing is test_progress.py's, on a fake clock
    monkeypatch.setattr(progress, "PLAIN_INTERVAL_S", float("inf"))
    case = gs.rve.load(params)
    start = gs.rve.packing(case, PACKING)
    gs.rve.triaxial(case, start)
    err = capfd.readouterr().err
    lines = [ln for ln in err.splitlines() if ln]
    assert len(lines) == 1 and lines[0].startswith("rve triaxial: axial strain = "), err
    assert "\r" not in err
    gs.rve.triaxial(case, start, progress=False)
    assert capfd.readouterr().err == ""


def test_timestep_is_the_stiffest_contact_of_the_lightest_grain(params):
    """rve.timestep of the 150-sphere test packing: safety sqrt(m_min / (E r_max)), the
    lightest grain's mass from the smallest radius in the packing file and the [rve]
    density, computed here independently of the batch's masses."""
    from math import pi, sqrt

    from grainscale import rve

    case = rve.load(params)
    batch = rve.packing(case, PACKING)
    radius = read_packing(PACKING)[2]
    m_min = case.rve.density * 4.0 / 3.0 * pi * radius.min() ** 3
    expected = case.rve.numerics.timestep_safety * sqrt(
        m_min / (case.rve.young_modulus * radius.max()))
    assert rve.timestep(case, batch) == pytest.approx(expected, rel=1e-12)
    assert rve.timestep(params, batch) == rve.timestep(case, batch)

"""`grainscale rve ...` refuses bad input before any computation: exit code 2 and a
message on stderr that names the key and the bad value."""

from __future__ import annotations

from pathlib import Path

import pytest

from grainscale.cli import main

GOOD = """
[rve]
particles = 100
radius_min = 3e-3
radius_max = 7e-3
friction = 0.5
[rve.preparation]
pressure = 100e3
"""


def run(tmp_path, capsys, text, command="generate", extra=()):
    case = tmp_path / "case.toml"
    case.write_text(text)
    out = tmp_path / ("out.txt" if command == "generate" else "out.csv")
    code = main(["rve", command, str(case), "--out", str(out), "--quiet", *extra])
    err = capsys.readouterr().err
    assert not out.exists()  # nothing computed, nothing written
    return code, err


@pytest.mark.parametrize("key, line, shown", [
    ("rve.radius_min", "radius_min = -3e-3", "-0.003"),
    ("rve.friction", "friction = -0.2", "-0.2"),
    ("rve.preparation.porosity", "porosity = 0.55", "0.55"),
    ("rve.preparation.porosity", "porosity = 0.2", "0.2"),
    ("rve.partikles", "partikles = 100", "100"),
])
def test_bad_value_names_key_and_value(tmp_path, capsys, key, line, shown):
    name = line.split("=")[0].strip()
    if name == "porosity":
        text = GOOD + line + "\n"
    else:
        text = GOOD.replace("[rve]\n", f"[rve]\n{line}\n", 1)
        if name in ("radius_min", "friction"):  # replace, not duplicate, the key
            text = GOOD.replace(
                next(ln for ln in GOOD.splitlines() if ln.startswith(name)), line)
    code, err = run(tmp_path, capsys, text)
    assert code == 2
    assert key in err and shown in err, err


def test_radius_max_below_radius_min(tmp_path, capsys):
    text = GOOD.replace("radius_max = 7e-3", "radius_max = 2e-3")
    code, err = run(tmp_path, capsys, text)
    assert code == 2
    assert "radius_max" in err and "0.002" in err and "radius_min" in err, err


def test_missing_case_file(tmp_path, capsys):
    missing = tmp_path / "nope.toml"
    code = main(["rve", "generate", str(missing), "--out", str(tmp_path / "o.txt"),
                 "--quiet"])
    assert code == 2
    assert "nope.toml" in capsys.readouterr().err


def test_missing_packing_file(tmp_path, capsys):
    code, err = run(tmp_path, capsys, GOOD, command="triaxial",
                    extra=["--packing", str(tmp_path / "absent.txt")])
    assert code == 2
    assert "--packing" in err and "absent.txt" in err, err


def test_not_toml(tmp_path, capsys):
    code, err = run(tmp_path, capsys, "[rve\nparticles = 1")
    assert code == 2
    assert "case.toml" in err and "TOML" in err, err


def test_misspelled_table_is_named(tmp_path, capsys):
    code, err = run(tmp_path, capsys, GOOD + "[triaxal]\nstrain_rate = 0.1\n")
    assert code == 2
    assert "triaxal" in err and "unknown key" in err, err


def test_an_element_test_without_its_table_names_its_defaults(tmp_path, capsys, monkeypatch):
    """`grainscale rve isotropic` on a file without [isotropic] says which defaults it
    runs (before preparing anything: the preparation is stubbed out here); with the
    table it says nothing."""

    class Prepared(Exception):
        pass

    def stop(*args, **kw):
        raise Prepared

    monkeypatch.setattr("grainscale.cli.rve.prepared", stop)
    params = tmp_path / "p.toml"
    params.write_text("[rve]\nparticles = 150\n")
    with pytest.raises(Prepared):
        main(["rve", "isotropic", str(params), "--out", str(tmp_path / "o.csv"), "--quiet"])
    err = capsys.readouterr().err
    assert "has no [isotropic] table: the defaults pressure_final = 1000000.0" in err
    params.write_text("[rve]\nparticles = 150\n[isotropic]\npressure_final = 2e5\n")
    with pytest.raises(Prepared):
        main(["rve", "isotropic", str(params), "--out", str(tmp_path / "o.csv"), "--quiet"])
    assert "defaults" not in capsys.readouterr().err


def test_too_few_particles_for_the_radii_are_refused_before_any_generation(tmp_path,
                                                                          capsys):
    """60 spheres of 3-7 mm cannot fill a cell 8 radius_max wide at the insertion
    porosity (0.7) even with radii 3 standard deviations above their mean: refused with
    the smallest valid count, by `rve generate` and by `run` of a multiscale case, before
    a packing is generated or a folder made."""
    from grainscale.config.rve import RVEParams, min_particles

    assert min_particles(3e-3, 7e-3, 0.7) == 87  # the mean radius^3 fills it
    least = min_particles(3e-3, 7e-3, 0.7, spread=3.0)
    assert 60 < least < 87
    # the count that fills the cell on average: n (4/3) pi <r^3> = 0.3 (8 r_max)^3
    a, b = 3e-3, 7e-3
    mean_r3 = (b**4 - a**4) / (4 * (b - a))
    assert 86 < 0.3 * (8 * b) ** 3 / (4 / 3 * 3.141592653589793 * mean_r3) <= 87
    params = tmp_path / "p.toml"
    params.write_text("[rve]\nparticles = 60\n")
    assert RVEParams(particles=60).radius_max == 7e-3  # the defaults used above
    assert main(["rve", "generate", str(params), "--out", str(tmp_path / "p.h5"),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "rve.particles = 60 is too few" in err and f">= {least}" in err
    assert not (tmp_path / "p.h5").exists()
    case = Path(__file__).parents[1] / "examples" / "unit_element" / "case.toml"
    text = case.read_text()
    assert "\nparticles = " in text
    small = tmp_path / "case.toml"
    small.write_text("\n".join("particles = 60" if ln.startswith("particles =") else ln
                               for ln in text.splitlines()))
    assert main(["run", str(small), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert f">= {least}" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()

"""`grainscale check` (coupling/dry_run.py): a case's counts and cost without running it,
against a run of the same case."""

import dataclasses
import json
import sys
from pathlib import Path

import pytest

from grainscale.cli import main

sys.path.insert(0, str(Path(__file__).parent / "coupling"))
from test_mpi import small_column  # noqa: E402


def test_check_predicts_the_runs_steps_and_dem_work(tmp_path, capsys):
    """The reduced column (dynamic RVEs): the check's points and RVEs are the run's, its
    MPM steps within 25 % of the run's (the wave speed grows as the RVEs are compressed;
    the estimate reads the packing's) and its DEM steps per RVE and MPM step within 25 %
    of cost.json's (the same ceil(dt / dt_crit) at the estimated dt); it makes no output
    folder."""
    case = small_column(tmp_path)
    resolved = tmp_path / "resolved.toml"
    assert main(["check", str(case), "--resolved", str(resolved)]) == 0
    out = capsys.readouterr().out
    r = json.loads(out.strip().splitlines()[-1])
    assert "MPM steps to the end" in out and "estimated DEM wall time" in out
    ref = tmp_path / "run"
    assert main(["run", str(case), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    cost = json.loads((ref / "cost.json").read_text())
    sand = r["materials"]["sand"]
    assert r["points"] == cost["points"] and sand["rves"] == cost["rves"]
    assert r["mpm_steps"] == pytest.approx(cost["steps"], rel=0.25)
    assert sand["dem_steps_per_step"] == pytest.approx(cost["dem_steps_per_rve_per_step"],
                                                       rel=0.25)
    assert not sand["dem_steps_assumed"] and r["dem_wall_seconds"] > 0
    import grainscale as gs

    again = gs.check(case)  # the Python API: the same figures but the timed ones
    assert again["mpm_steps"] == r["mpm_steps"] and again["points"] == r["points"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["column.toml", "resolved.toml", "run"]
    # the resolved case is the run's but for the bulk density its packings set
    import tomllib

    ran = tomllib.loads((ref / "case.resolved.toml").read_text())
    assert ran["materials"]["sand"].pop("density") > 0
    assert tomllib.loads(resolved.read_text()) == ran


def test_check_refuses_bad_input_as_a_run_does(tmp_path, capsys):
    case = tmp_path / "c.toml"
    case.write_text((Path(__file__).parents[1] / "examples" / "column_collapse" /
                     "quick.toml").read_text().replace("cfl = 0.5", "cfl = 5.0"))
    assert main(["check", str(case)]) == 2
    assert "solver.cfl" in capsys.readouterr().err


def test_check_warns_of_a_valid_case_its_author_likely_does_not_want(tmp_path):
    """The reduced column warns: its body spans 3 of the grid's 4 cells in z (GIMP leaves
    it no interior), one point per cell in a flow (dynamic RVEs), and retile_width 20
    against a packing ~5 diameters wide (it retiles at once); with quasi-static RVEs one
    point a cell is not warned. The same column 4 cells tall, with retile_width 0, warns
    of nothing: each warning is tied to its own key."""
    import tomllib

    import grainscale as gs

    case = small_column(tmp_path)
    data = tomllib.loads(case.read_text())
    data["bodies"][0]["points_per_cell"] = 1
    warn = gs.check(_write(case, data))["warnings"]
    assert len(warn) == 3, warn
    assert any(w.startswith("bodies[0].points_per_cell = 1 in a flow") for w in warn)
    assert any("spans 3 cells along z" in w for w in warn)
    assert any(w.startswith("materials.sand.retile_width = 20") for w in warn)
    data["materials"]["sand"]["time_integration"] = "quasi_static"  # static: 1 is fine
    static = gs.check(_write(case, data))["warnings"]
    assert len(static) == 2 and not any("points_per_cell" in w for w in static)
    data["bodies"][0].update(hi=[0.04, 0.01, 0.04])
    data["materials"]["sand"]["retile_width"] = 0.0
    r = gs.check(_write(case, data))
    assert r["warnings"] == []
    least = r["smallest_valid_particles"]  # the number the check refuses below
    assert least <= 80
    data["rve"]["particles"] = least - 1
    _write(case, data)
    with pytest.raises(gs.ConfigError, match=f"rve.particles >= {least}"):
        gs.check(case)


def test_check_warns_of_hertzian_overlaps_near_the_bound(tmp_path):
    """Hertz-Mindlin grains too soft for max_overlap at the preparation pressure are
    warned, naming the key; glass-like grains (E = 70 GPa) are not. The estimate
    (hertz.largest_overlap) is the largest overlap of examples/rve/hertz_mindlin.toml's
    stored packing at 100 kPa (tests/data/triaxial_800_hertz), measured here, to 5 %."""
    import tomllib

    import grainscale as gs
    from grainscale.dem import hertz

    case = small_column(tmp_path)
    data = tomllib.loads(case.read_text())
    data["materials"]["sand"]["retile_width"] = 0.0
    data["bodies"][0].update(hi=[0.04, 0.01, 0.04])
    data["rve"].pop("stiffness_ratio", None)
    data["rve"].update(contact_law="hertz_mindlin", poisson_ratio=0.25, young_modulus=70e9)
    assert gs.check(_write(case, data))["warnings"] == []
    data["rve"]["young_modulus"] = 1e8
    warn = gs.check(_write(case, data))["warnings"]
    assert len(warn) == 1 and warn[0].startswith("rve.numerics.max_overlap = 0.01"), warn
    assert "at rve.preparation.pressure" in warn[0]
    from grainscale.config.case import load_rve_case
    from grainscale.dem import engine
    from grainscale.dem.generate import contact_params
    from grainscale.dem.state import from_packing
    from grainscale.io.packing import read_packing

    root = Path(__file__).parents[1]
    params = load_rve_case(root / "examples" / "rve" / "hertz_mindlin.toml").rve
    h, x, r = read_packing(root / "tests" / "data" / "triaxial_800_hertz" / "packing.txt")
    b = from_packing(h, x, r, params.density)
    cp = contact_params(params)
    out = engine.refresh(b, cp)
    with pytest.raises(engine.RVEError, match=r"delta/R\* = 0.00382"):
        engine.refresh(out, dataclasses.replace(cp, max_overlap=1e-3))
    assert hertz.largest_overlap(100e3, 70e9, 0.25) == pytest.approx(3.82e-3, rel=0.05)


def _write(path: Path, data: dict) -> Path:
    import tomli_w

    path.write_text(tomli_w.dumps(data))
    return path

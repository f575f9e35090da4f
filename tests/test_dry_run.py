"""`grainscale check` (coupling/dry_run.py): a case's counts and cost without running it,
against a run of the same case."""

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
    assert main(["check", str(case)]) == 0
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
    assert sorted(p.name for p in tmp_path.iterdir()) == ["column.toml", "run"]


def test_check_refuses_bad_input_as_a_run_does(tmp_path, capsys):
    case = tmp_path / "c.toml"
    case.write_text((Path(__file__).parents[1] / "examples" / "column_collapse" /
                     "quick.toml").read_text().replace("cfl = 0.5", "cfl = 5.0"))
    assert main(["check", str(case)]) == 2
    assert "solver.cfl" in capsys.readouterr().err

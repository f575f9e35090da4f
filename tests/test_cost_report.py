"""cost.json (coupling/cost.py): sane on any run, and cumulative over resumes with the last
invocation's figures beside them."""

import json
import sys
import tomllib
from pathlib import Path

import pytest
import tomli_w

from grainscale.cli import main

sys.path.insert(0, str(Path(__file__).parent / "coupling"))
from test_mpi import small_column  # noqa: E402
from test_multiscale_run import run_folder_with_packings_of  # noqa: E402

PARTS = ("mpm", "dem", "comm", "wait", "other", "total")


@pytest.fixture(scope="module")
def column(tmp_path_factory):
    """The reduced column with sleeping RVEs (so that not every RVE is stepped) and its
    uninterrupted run's cost.json."""
    tmp = tmp_path_factory.mktemp("cost")
    path = small_column(tmp)
    case = tomllib.loads(path.read_text())
    case["materials"]["sand"].update(update_tolerance=1e-5, max_deferred_steps=5)
    path.write_text(tomli_w.dumps(case))
    ref = tmp / "full"
    assert main(["run", str(path), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    return path, ref, json.loads((ref / "cost.json").read_text())


def sane(r: dict) -> None:
    """Every part of the time per step non-negative, every share within [0, 1]."""
    for part in PARTS:
        assert r["seconds_per_step"][part] >= 0.0, (part, r["seconds_per_step"])
    assert 0.0 <= r["fraction_of_rves_stepped"] <= 1.0
    assert r["dem_steps_per_rve_per_step"] >= 0.0 and r["core_hours"] >= 0.0


def test_a_run_stopped_by_an_error_at_its_third_step_reports_sanely(column, tmp_path,
                                                                    capsys):
    """The column thrown upward at 100 m/s leaves the grid within a few steps (exit 1):
    its cost.json counts the failed step's time and work (no negative MPM time, no share
    of RVEs stepped above 1, as when the failed step's DEM update was counted against the
    completed steps only) and says that a step failed."""
    path, ref, _ = column
    case = tomllib.loads(path.read_text())
    case["bodies"][0]["velocity"] = [0.0, 0.0, 100.0]
    case["time"]["start"] = 0.0  # no geostatic stage: thrown from the first step
    thrown = tmp_path / "thrown.toml"
    thrown.write_text(tomli_w.dumps(case))
    out = run_folder_with_packings_of(ref, tmp_path / "out")
    assert main(["run", str(thrown), "--out", str(out), "--quiet", "--threads", "1"]) == 1
    assert "left the grid" in capsys.readouterr().err
    r = json.loads((out / "cost.json").read_text())
    assert r["this_invocation"]["failed_step"] is True and r["steps"] <= 10
    sane(r)
    sane(r["this_invocation"])


def test_cost_is_cumulative_over_a_resume(column, tmp_path):
    """Stopped at step 40 and resumed: the top-level figures are the whole run's (its
    steps, DEM steps per RVE and step, share of RVEs stepped: those of the uninterrupted
    run exactly, as the run is), `this_invocation` the resumed part's."""
    path, ref, full = column
    out = run_folder_with_packings_of(ref, tmp_path / "out")
    common = ["run", str(path), "--out", str(out), "--quiet", "--threads", "1",
              "--checkpoint-every", "10"]
    assert main([*common, "--max-steps", "40"]) == 0
    first = json.loads((out / "cost.json").read_text())
    assert first["steps"] == 40 and first["whole_run"]
    assert main([*common, "--resume"]) == 0
    r = json.loads((out / "cost.json").read_text())
    assert r["whole_run"] and r["steps"] == full["steps"]
    assert r["this_invocation"]["steps"] == full["steps"] - 40
    for key in ("dem_steps_per_rve_per_step", "fraction_of_rves_stepped", "particle_steps"):
        assert r[key] == pytest.approx(full[key], rel=1e-12), key
    assert 0.0 < full["fraction_of_rves_stepped"] < 1.0  # some slept
    assert r["wall_seconds"] > r["this_invocation"]["wall_seconds"] > 0.0
    sane(r)
    sane(r["this_invocation"])

"""studies/column_collapse/sleeping.py `why` on the reduced column: what it says keeps RVEs
awake must add up, and its share of RVEs stepped must be the run's own count (the
history's cumulative updates_per_rve over the same steps, written by the solver)."""

import json
import sys
import tomllib
from pathlib import Path

import pytest
import tomli_w

from example_scripts import load_example
from grainscale.analysis import read_columns

sys.path.insert(0, str(Path(__file__).parent / "coupling"))
from test_mpi import small_column  # noqa: E402

pytestmark = pytest.mark.validation  # ~1 min: a reduced column and 20 more steps

sleeping = load_example("column_collapse/sleeping.py")


def test_why_accounts_for_every_rve_stepped(tmp_path, monkeypatch, capsys):
    run, copy = tmp_path / "run", tmp_path / "copy"
    case = small_column(tmp_path)
    tables = tomllib.loads(case.read_text())
    tables["output"]["interval"] = 1e-9  # a history row every step
    case.write_text(tomli_w.dumps(tables))
    for argv in (["run", "--case", str(case), "--tolerance", "3e-5",
                  "--out", str(run)],
                 ["why", str(run), "--out", str(copy), "--steps", "21"]):
        monkeypatch.setattr(sys, "argv", ["sleeping.py", *argv])
        sleeping.main()
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["steps"] == 20  # the first call only records the state the steps start from
    parts = out["stepped_by_increment"] + out["stepped_by_cap"] + out["stepped_not_at_rest"]
    assert parts == pytest.approx(out["stepped"], abs=1e-12)
    assert 0.0 < out["stepped"] < 1.0  # a tolerance some RVEs sleep under
    h = read_columns(copy / "history.csv")
    step, updates = list(h["step"]), h["updates_per_rve"]
    first, last = step.index(out["from_step"] + 1), step.index(out["from_step"] + 21)
    # the solver's count over the same 20 steps (cumulative per RVE: a mean over points)
    assert (updates[last] - updates[first]) / 20 == pytest.approx(out["stepped"], rel=1e-9)

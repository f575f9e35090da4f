"""studies/column_collapse/cross_scale.py, as the README tells users to run it, reduced:
the flow measurement at one pressure and five inertial numbers on an 80-sphere RVE, and
a finished small multiscale column given with --multiscale. What it must guarantee: the
continuum carries the fit the RVE's measurement gave and nothing else of the case
changes ("the very same case"), and what it reports is what the runs did."""

import json
import sys
import tomllib
from pathlib import Path

import pytest

from example_scripts import load_example
from grainscale.cli import main
from grainscale.io.history import read_history

sys.path.insert(0, str(Path(__file__).parent / "coupling"))
from test_mpi import small_column  # noqa: E402

pytestmark = pytest.mark.validation  # ~1 min: a flow measurement and three small runs

cross = load_example("column_collapse/cross_scale.py")
conv = load_example("column_collapse/convergence.py")


def test_the_continuum_is_the_case_with_the_fitted_law(tmp_path, monkeypatch):
    case = small_column(tmp_path)
    ms = tmp_path / "ms"
    assert main(["run", str(case), "--out", str(ms), "--quiet"]) == 0
    out = tmp_path / "xs"
    monkeypatch.setattr(sys, "argv", [
        "cross_scale.py", "--out", str(out), "--case", str(case), "--multiscale", str(ms),
        "--pressures", "200", "--inertial", "0.01", "0.03", "0.1", "0.2", "0.4"])
    cross.main()
    fit = tomllib.loads((out / "flow.mu_i.toml").read_text())["materials"]["sand"]
    result = json.loads((out / "results.json").read_text())
    assert (result["mu_s"], result["mu_2"], result["I_0"]) == (
        fit["mu_s"], fit["mu_2"], fit["I_0"])
    # a rate-strengthening law: the friction at I = 0.3 above that at 0.03 (dense flow)
    mu = [fit["mu_s"] + (fit["mu_2"] - fit["mu_s"]) / (1 + fit["I_0"] / i) for i in (0.03, 0.3)]
    assert 0.1 < mu[0] < mu[1] < 1.5
    original = tomllib.loads(case.read_text())
    continuum = tomllib.loads((out / "continuum" / "case.toml").read_text())
    assert continuum["materials"] == {"sand": fit}
    for key in ("grid", "solver", "bodies", "boundaries", "time", "damping"):
        assert continuum[key] == original[key], key
    # the reported runouts are the runs' own, read back independently
    for name, run in (("multiscale", ms), ("continuum", out / "continuum" / "run"),
                      ("baseline", out / "baseline" / "run")):
        m = conv.measures(read_history(run / "history.csv"))
        assert result[f"{name}_runout"] == pytest.approx(m["runout"], abs=1e-4), name
    assert (out / "cross_scale.png").stat().st_size > 0

"""A continuum column collapse should not depend on the time step (the flow-numerics
issue: with a FLIP/PIC blend it did, by a factor 2-3, through its per-step PIC share).
APIC does depend on it (1.4 % at 5 mm cells, 11 % at 10 mm: it loses energy once per
step, docs/validation.md §2.1); that is a property of the transfer, not a guarantee, so
only the shipped transfer is held to dt independence here."""

import tomllib
from pathlib import Path

import pytest

import grainscale as gs
from example_scripts import load_example
from grainscale.cli import main

pytestmark = pytest.mark.validation  # minutes: the validation tier

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "column_collapse"


def _convergence():
    return load_example("column_collapse/convergence.py")


def _runout(tmp_path, cfl, update, relaxation_time):
    conv = _convergence()
    # mu_i.toml at 5 mm cells: 20-40 s a run
    case = conv.case_at(0.005, "mu_i", 22.0, cfl=cfl, update=update,
                        relaxation_time=relaxation_time)
    path = tmp_path / f"case_{update}_{cfl}.toml"
    case.save(path)
    out = tmp_path / f"out_{update}_{cfl}"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    return conv.measures(gs.open_result(out).history)


def _aflip_runs(tmp_path, relaxation_time):
    """The 5 mm column with AFLIP at cfl 0.5 and 0.25: (coarse, fine) measures with the
    thick-deposit runouts; both must have come to rest (front stopped before 5 tau_c)
    in the flow regime (runout > 0.8)."""
    conv = _convergence()
    case = conv.case_at(0.005, "mu_i", 22.0)
    runs = []
    for cfl in (0.5, 0.25):
        r = _runout(tmp_path, cfl, "aflip", relaxation_time=relaxation_time)
        r.update(conv.thick_runouts(*conv.deposit(tmp_path / f"out_aflip_{cfl}", case)))
        assert r["runout"] > 0.8 and r["front_stop_t_over_tc"] < 5.0
        runs.append(r)
    return runs


def test_halving_dt_leaves_the_relaxed_aflip_runout(tmp_path):
    """The transfer the column cases ship (mu_i.toml, quick.toml): AFLIP with the PIC
    share set per unit time (velocity_relaxation_time = 0.01 s, about tau_c / 8), so the
    sub-grid velocity relaxes at a rate that does not depend on dt. The reference is the
    dt -> 0 limit: with an error first order in dt, r(dt) - r(dt/2) estimates
    r(dt/2) - r(0), so a 1 % change on halving bounds the distance from the converged
    runout by ~1 %. Measured: runout 1.129 and 1.131 (0.2 %), the deposit at least 3
    beads thick 1.050 at both steps. Both come to rest (front stopped before 5 tau_c;
    kinetic energy below 1e-5 of its peak at 7 tau_c). Mutation tried: the PIC share
    per step instead of per unit time (flip = exp(-1e-4 s / relaxation_time) in
    mpm/step.py, the FLIP-blend behaviour the flow-numerics issue removed) gives 1.122
    and 1.109 (1.1 %) and fails."""
    coarse, fine = _aflip_runs(tmp_path, relaxation_time=0.01)
    for r in (coarse, fine):
        assert r["kinetic_energy_end_over_peak"] < 1e-5
    assert fine["runout"] == pytest.approx(coarse["runout"], rel=0.01)
    assert fine["runout_3d"] == pytest.approx(coarse["runout_3d"], rel=0.01)
    with open(EXAMPLE / "mu_i.toml", "rb") as f:  # the baseline's own setting
        solver = tomllib.load(f)["solver"]
    assert (solver["velocity_update"], solver["velocity_relaxation_time"]) == ("aflip", 0.01)

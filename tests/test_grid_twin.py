"""studies/column_collapse/grid_twin.py's cases: the column on finer cells must be the
hand-written fine.toml where that exists (an independent statement of the same
refinement), change nothing else, and carry the fitted law with the transfer asked for."""

from pathlib import Path

import pytest

import grainscale as gs
from example_scripts import load_example

twin = load_example("column_collapse/grid_twin.py")
CASES = Path(__file__).resolve().parents[1] / "examples" / "column_collapse"
LAW = {"type": "mu_i", "density": 1500.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3,
       "mu_s": 0.36, "mu_2": 0.79, "I_0": 0.42, "grain_diameter": 0.006,
       "grain_density": 2500.0}


def tables(case: gs.Case) -> dict:
    return case.model_dump(mode="json", exclude_unset=True, exclude_none=True)


def test_quick_on_5_mm_cells_is_fine_toml():
    refined = tables(twin.on_cells(gs.load_case(CASES / "quick.toml"), 0.005))
    fine = tables(gs.load_case(CASES / "fine.toml"))
    for key in ("grid", "bodies", "boundaries", "solver", "time", "materials", "rve"):
        assert refined[key] == fine[key], key


def test_the_twin_carries_the_law_and_the_transfer():
    quick = tables(gs.load_case(CASES / "quick.toml"))
    for transfer in ("aflip", "apic"):
        t = tables(twin.twin(CASES / "quick.toml", LAW, 0.01, transfer))
        assert list(t["materials"]) == ["sand"]
        assert {k: t["materials"]["sand"][k] for k in LAW} == LAW
        assert "rve" not in t
        assert (t["grid"], t["bodies"], t["boundaries"]) == (
            quick["grid"], quick["bodies"], quick["boundaries"])
        assert t["solver"]["velocity_update"] == transfer
        assert ("velocity_relaxation_time" in t["solver"]) == (transfer == "aflip")


def test_a_cell_that_does_not_divide_the_grid_is_refused():
    with pytest.raises(SystemExit, match="--cells 3"):
        twin.on_cells(gs.load_case(CASES / "quick.toml"), 0.003)

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


def test_one_layer_of_points_is_the_same_planar_flow(tmp_path, monkeypatch):
    """sleeping.py --one-layer halves the column's RVEs by leaving one point layer between
    the side walls. In a continuum (no RVE to sample) that is the same planar flow: with
    v_y held at both node planes, each node plane gets mass and force in the same
    proportion (its weight S_y) and so the same acceleration. Exactly so only without the
    node-mass cut-offs (mpm/step.py MASS_TOL, LIGHT_MASS_TOL: fractions of the heaviest
    point's mass), which a one-layer column's far node plane, a third of the near one's
    mass, crosses at other moments at the free surface: with them the fronts differ by
    2.6e-6 L_i after one tau_c (1e-4 of a point spacing), without them by 5e-12, the
    fixed-point nodal sums' resolution (a cfl changed by 1e-12 moves them 1e-13). So the
    cut-offs are set to 0 here and the tolerance is round-off: 1e-9 fails on any
    difference in the kinematics."""
    sleeping = load_example("column_collapse/sleeping.py")
    import grainscale.mpm.step as step
    monkeypatch.setattr(step, "MASS_TOL", 0.0)
    monkeypatch.setattr(step, "LIGHT_MASS_TOL", 0.0)

    def short(t: dict) -> None:
        t["time"]["start"] = -0.01  # s, a third of the geostatic stage: settling enough
        t["time"]["end"] = 0.04  # s, 0.5 tau_c after release
        t["output"]["interval"] = 0.01

    two = twin.twin(CASES / "quick.toml", LAW, 0.01, "aflip").edited(short)
    one = sleeping.with_one_layer(two)
    assert one.bodies[0].hi[1] == pytest.approx(0.005)
    h2, h1 = (gs.run(c, tmp_path / name, progress=False).history
              for c, name in ((two, "two"), (one, "one")))
    assert h1["runout_ratio"][-1] > 0.03  # the front has moved 3 mm
    for key in ("runout_ratio", "height_ratio"):
        assert abs(h1[key] - h2[key]).max() < 1e-9, key
    # the one-layer column carries half the mass, so half the kinetic energy
    assert h1["kinetic_energy"] == pytest.approx(h2["kinetic_energy"] / 2, rel=1e-9, abs=1e-15)


def test_one_layer_refuses_a_slice_thicker_than_a_cell():
    sleeping = load_example("column_collapse/sleeping.py")
    with pytest.raises(SystemExit, match="--one-layer: a body must be a box one cell"):
        sleeping.with_one_layer(twin.on_cells(gs.load_case(CASES / "quick.toml"), 0.005)
                                .edited(lambda t: t["bodies"][0]["hi"].__setitem__(1, 0.01)))


def test_points_per_cell_gives_one_point_a_cell():
    """sleeping.py run --points-per-cell 1 and grid_twin.py --points-per-cell 1:
    quick.toml's 0.1 x 0.06 m column on 10 mm cells, one cell thick, is 10 x 6 = 60
    points (8 times fewer than its 2 x 2 x 2, the twin's default), and `check` warns
    that one point a cell in a flow is unusual."""
    sleeping = load_example("column_collapse/sleeping.py")
    report = gs.check(sleeping.sleeping_case(CASES / "quick.toml", 3e-6, 20, 0.0,
                                             points_per_cell=1))
    assert report["points"] == 60
    assert any("points_per_cell = 1" in w for w in report["warnings"])
    for n, points in ((None, 480), (1, 60)):
        assert gs.check(twin.twin(CASES / "quick.toml", LAW, 0.01, "aflip", n))["points"] == points

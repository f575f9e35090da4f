"""The column in half of a channel (convergence.py --channel): with frictionless walls it
is the slice's planar flow; with Coulomb walls the layer along the wall runs out less."""

import pytest

import grainscale as gs
from example_scripts import load_example
from grainscale.cli import main

conv = load_example("column_collapse/convergence.py")


def _run(tmp_path, name, **channel):
    # mu_i.toml at 10 mm cells: 5-10 s a run
    case = conv.case_at(0.010, "mu_i", 22.0, **channel)
    path = tmp_path / f"{name}.toml"
    case.save(path)
    out = tmp_path / name
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    row = conv.measures(gs.open_result(out).history)
    if channel:
        row.update(conv.wall_runouts(out, case))
    return row


@pytest.mark.validation
def test_channel_walls(tmp_path):
    """A channel 40 mm wide (two cells on each side of the symmetry plane):
    - frictionless walls: the flow is planar, so the front is the slice's; measured
      0.88032 against 0.88032 (5e-6 apart: the nodal sums differ in order), 1e-4 guards it;
    - walls of Coulomb friction 0.466 (the floor's): the wall's traction mu_w sigma_yy
      holds the layer along it back, measured front 0.557 there against 0.880 (the
      channel's whole front 0.775); the wall layer must lose more than 20 % and no
      measure may grow."""
    slice_ = _run(tmp_path, "slice")
    smooth = _run(tmp_path, "smooth", channel=0.040, wall_friction=0.0)
    rough = _run(tmp_path, "rough", channel=0.040, wall_friction=0.466)
    assert slice_["runout"] > 0.8 and slice_["front_stop_t_over_tc"] < 5.0
    assert smooth["runout"] == pytest.approx(slice_["runout"], rel=1e-4)
    assert smooth["wall_runout"] == pytest.approx(smooth["runout"], rel=1e-4)
    assert rough["wall_runout"] < 0.8 * smooth["wall_runout"]
    assert rough["runout"] <= smooth["runout"]
    assert rough["wall_runout_mass99"] < smooth["wall_runout_mass99"]


def test_channel_must_be_whole_cells():
    with pytest.raises(ValueError, match="--channel 45 mm: half of it must be a whole"):
        conv.case_at(0.010, "mu_i", 22.0, channel=0.045)

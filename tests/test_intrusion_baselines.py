"""examples/intrusion/baselines.py: the continuum twin of a multiscale intrusion case, and
the same case on another grid or bed (`reshape`)."""


import pytest

from example_scripts import EXAMPLES, load_example
from grainscale.config.base import validate
from grainscale.config.case import Case, check_case

HERE = EXAMPLES / "intrusion"


baselines = load_example("intrusion/baselines.py")


@pytest.mark.parametrize("name", ["quick.toml", "quick_cuboid.toml", "mohr_coulomb.toml"])
def test_reshape_keeps_the_intruder_on_the_surface(name):
    """A 5 x 5 m quarter of a 4 m bed on 0.125 m cells, one point a cell: the grid spans
    the bed and ABOVE more, the intruder's base sits on the new surface at the same x, y,
    and the case passes the loader's checks."""
    path = HERE / name
    case = (baselines.baseline_case(path, "mohr_coulomb", 20.0) if name.startswith("quick")
            else baselines.tomllib.loads(path.read_text()))
    rigid0 = {k: list(v) for k, v in case["rigid"].items() if k in ("center", "lo", "hi")}
    out = baselines.reshape(case, 0.125, 1, 5.0, 4.0)
    assert out["grid"]["cells"] == [40, 40, round((4.0 + baselines.ABOVE) / 0.125)]
    assert out["bodies"][0]["hi"] == [5.0, 5.0, 4.0]
    assert out["bodies"][0]["points_per_cell"] == 1
    rigid = out["rigid"]
    base = rigid["center"][2] if "center" in rigid else rigid["lo"][2]
    assert base == pytest.approx(4.0, abs=1e-12)
    for key, v0 in rigid0.items():
        assert rigid[key][:2] == v0[:2]
    check_case(validate(Case, out, source=name))


def test_reshape_defaults_leave_the_case_as_it_was():
    case = baselines.baseline_case(HERE / "quick.toml", "mohr_coulomb", 20.0)
    before = baselines.tomllib.loads(baselines.tomli_w.dumps(case))
    assert baselines.reshape(case) == before

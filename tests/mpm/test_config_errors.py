"""Bad input is refused before the run, with a message naming key, value and valid range."""

import textwrap

import pytest

from grainscale.config.base import ConfigError
from grainscale.config.case import load_case
from grainscale.mpm.setup import build_state

GOOD = """
[grid]
cell_size = 0.05
cells = [4, 4, 4]

[solver]
gravity = [0.0, 0.0, -9.81]

[time]
end = 0.01

[materials.soil]
type = "linear_elastic"
density = 1000.0
youngs_modulus = 1e6
poisson_ratio = 0.3

[[bodies]]
shape = "box"
material = "soil"
lo = [0.0, 0.0, 0.0]
hi = [0.1, 0.1, 0.1]

[output]
interval = 0.005
"""


def _load(tmp_path, text):
    p = tmp_path / "case.toml"
    p.write_text(textwrap.dedent(text))
    case = load_case(p)
    return build_state(case, tmp_path)


def test_good_case_builds(tmp_path):
    s = _load(tmp_path, GOOD)
    assert s.points.n == 64


@pytest.mark.parametrize("old,new,words", [
    ("cell_size = 0.05", "cell_size = 0.0", ["grid.cell_size", "0.0", "greater than 0"]),
    ("cell_size = 0.05", "cell_size = -1.0", ["grid.cell_size", "-1.0"]),
    ('hi = [0.1, 0.1, 0.1]', 'hi = [0.1, 0.1, 0.3]', ["bodies[0]", "outside the grid",
                                                        "valid range"]),
    ("[solver]", "[solver]\ndt = 0.01", ["solver.dt", "0.01", "CFL limit"]),
    ("poisson_ratio = 0.3", "poisson_ratio = 0.3\npossion_ratio = 0.3",
     ["materials.soil.possion_ratio", "unknown key", "did you mean 'poisson_ratio'"]),
    ('type = "linear_elastic"', 'type = "hyperelastic"', ["materials.soil", "hyperelastic",
                                                          "linear_elastic"]),
    ('material = "soil"', 'material = "sand"', ["bodies[0].material", "'sand'", "soil"]),
    ('shape = "box"\nmaterial = "soil"\nlo = [0.0, 0.0, 0.0]\nhi = [0.1, 0.1, 0.1]',
     'shape = "file"\nmaterial = "soil"\npath = "nope.txt"',
     ["bodies[0].path", "nope.txt", "not found"]),
    ("poisson_ratio = 0.3", "poisson_ratio = 0.5", ["poisson_ratio", "0.5", "less than 0.5"]),
    ("end = 0.01", "end = -1.0", ["time.end", "-1.0"]),
    ('interval = 0.005', 'interval = 0.005\nhistory = ["time", "runout_ratio"]',
     ["output.history[1]", "runout_ratio", "[output.column]"]),
    ('interval = 0.005', 'interval = 0.005\nhistory = ["runout_ratio_thick"]\n'
     '[output.column]\nlength = 0.05\nheight = 0.1',
     ["runout_ratio_thick", "output.column.min_thickness", "> 0"]),
    ("[grid]", "[grid]\nsize = 3", ["grid.size", "unknown key"]),
])
def test_bad_input_is_named(tmp_path, old, new, words):
    assert old in GOOD
    with pytest.raises(ConfigError) as err:
        _load(tmp_path, GOOD.replace(old, new))
    msg = str(err.value)
    for w in words:
        assert w in msg, (w, msg)


def test_missing_case_file(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        load_case(tmp_path / "none.toml")


def test_boundary_needs_face_or_box(tmp_path):
    text = GOOD + '\n[[boundaries]]\ntype = "fixed"\n'
    with pytest.raises(ConfigError, match="boundaries\\[0\\].*exactly one of"):
        _load(tmp_path, text)


def test_clip_to_grid_keeps_the_quarter(tmp_path):
    """A cylinder centred on the grid corner: an error unless clipped, then a quarter."""
    cyl = ('shape = "cylinder"\nmaterial = "soil"\ncenter = [0.0, 0.0, 0.0]\nradius = 0.1\n'
           'height = 0.1')
    text = GOOD.replace('shape = "box"\nmaterial = "soil"\nlo = [0.0, 0.0, 0.0]\n'
                        'hi = [0.1, 0.1, 0.1]', cyl)
    with pytest.raises(ConfigError, match="clip_to_grid"):
        _load(tmp_path, text)
    s = _load(tmp_path, text.replace("height = 0.1", "height = 0.1\nclip_to_grid = true"))
    import numpy as np

    np.testing.assert_allclose(s.points.vol0.sum(), np.pi * 0.1**2 * 0.1 / 4, rtol=0.1)

"""Geostatic packing libraries (materials.NAME.geostatic_pressures, coupling/materials.py):
each point starts from a packing prepared near its lithostatic mean stress."""

import numpy as np
import pytest

from grainscale.config.base import ConfigError
from grainscale.config.case import load_case
from grainscale.coupling.materials import geostatic_assignment, prepare
from grainscale.dem import homogenise
from grainscale.mpm.setup import build_state


def test_assignment_follows_depth_along_gravity():
    """Level boundary where p = rho |g| depth (1 + 2 k0) / 3 meets the geometric mean of
    two levels, computed here by hand: 2 kPa between 1 and 4 kPa, so with rho = 1500,
    g = 9.81 and k0 = 0.5 at depth 2000 / (1500 x 9.81 x 2/3) = 0.2039 m. The same bed
    turned so that gravity points along +x gets the same levels."""
    depth = np.linspace(0.0, 0.5, 51)
    boundary = 2000.0 / (1500.0 * 9.81 * (1 + 2 * 0.5) / 3)
    expect = (depth > boundary).astype(int)
    upright = np.column_stack([np.zeros(51), np.zeros(51), 1.0 - depth])
    turned = np.column_stack([depth - 3.0, np.full(51, 0.2), np.zeros(51)])
    for x, g in ((upright, (0, 0, -9.81)), (turned, (9.81, 0, 0))):
        k = geostatic_assignment(x, g, 1500.0, 0.5, [1e3, 4e3], per_level=3, seed=7)
        assert np.array_equal(k // 3, expect)
    # within a level the packing is drawn from all of that level's
    x = np.zeros((300, 3))
    k = geostatic_assignment(x, (0, 0, -9.81), 1500.0, 0.5, [1e3, 4e3], per_level=3, seed=0)
    assert set(k) == {0, 1, 2}  # depth 0: the lowest level


CASE = """
[grid]
cell_size = 0.05
cells = [2, 2, 5]
[solver]
gravity = [0.0, 0.0, -981.0]   # 100 g: lithostatic stresses of 0-160 kPa in 0.2 m
[time]
end = 0.01
[materials.sand]
type = "dem"
{material}
[[bodies]]
shape = "box"
material = "sand"
lo = [0.0, 0.0, 0.0]
hi = [0.05, 0.05, 0.2]
points_per_cell = 1
[output]
interval = 0.005
[rve]
particles = 100
[rve.preparation]
pressure = 10e3
"""


def _case(tmp_path, material):
    p = tmp_path / "case.toml"
    p.write_text(CASE.format(material=material))
    return load_case(p)


def test_each_point_starts_at_its_levels_stress(tmp_path):
    """Four points 0.05 m apart under 100 g: depths 0, 0.05, 0.1, 0.15 m below the top
    point give p = rho 981 depth 2/3 = 0, ~50, ~100, ~150 kPa, so levels 10 and 100 kPa
    (boundary 31.6 kPa) give the top point 10 kPa and the three below 100 kPa. Each RVE's
    initial mean stress is its level's within 1 %: generate.consolidate stops only with
    every stress component within tol = 1 % of its target, and the material's initial
    stress is that state's own (engine.refresh, the end-of-increment evaluation). A
    point given the other level's packing is off by a factor of 10. Mutation tried:
    depth measured up from the lowest point (materials.geostatic_assignment) gives the
    top point the 100 kPa packing and fails."""
    case = _case(tmp_path, "geostatic_pressures = [10e3, 100e3]")
    out = tmp_path / "out"
    factory = prepare(case, tmp_path, out, progress=False)
    assert sorted(f.name for f in (out / "packings").iterdir()) == [
        "sand_p0_0.h5", "sand_p1_0.h5"]
    s = build_state(case, tmp_path, material_factory=factory)
    mat = s.materials[0]
    z = s.points.x[:, 2]
    p = homogenise.mean_stress(mat.initial_stress())
    top = z == z.max()
    assert top.sum() == 1
    np.testing.assert_allclose(p[top], 10e3, rtol=0.01)
    np.testing.assert_allclose(p[~top], 100e3, rtol=0.01)
    assert np.array_equal(mat.assignment, (~top).astype(int))


@pytest.mark.parametrize("material,match", [
    ("geostatic_pressures = [4e3, 1e3]", r"geostatic_pressures.*strictly ascending"),
    ("geostatic_pressures = [1e3, -4e3]", r"geostatic_pressures"),
    ('geostatic_pressures = [1e3]\npackings = ["a.txt"]',
     r"materials.sand.geostatic_pressures = \[1000.0\].*packings = \[\] only"),
    ("geostatic_pressures = [1e3]\ngeostatic_k0 = 0.0", r"geostatic_k0"),
])
def test_bad_geostatic_keys_are_named(tmp_path, material, match):
    with pytest.raises(ConfigError, match=match):
        _case(tmp_path, material)


def test_a_geostatic_library_needs_gravity(tmp_path):
    p = tmp_path / "case.toml"
    p.write_text(CASE.format(material="geostatic_pressures = [1e3]").replace(
        "-981.0", "0.0"))
    with pytest.raises(ConfigError, match=r"needs gravity.*solver.gravity = \[0.0, 0.0, 0.0\]"):
        load_case(p)

"""studies/intrusion/dem_work.py: the points it fills and its projection of a run's
per-point DEM work onto a larger case."""

import numpy as np
import pytest

import grainscale as gs
from example_scripts import EXAMPLES, load_example

dw = load_example("intrusion/dem_work.py")
HERE = EXAMPLES / "intrusion"


@pytest.mark.parametrize("name, count", [("seed_quick.toml", 5_491), ("seed.toml", 296_208),
                                         ("quick.toml", 3_072)])
def test_fill_makes_the_loaders_points(name, count):
    """The RVE counts the case files state (tests/mpm/test_graded_case.py checks them
    against the loader's fill_box), each point inside the bed."""
    case = gs.load_case(HERE / name)
    x = dw.fill(case)
    assert len(x) == count
    body = case.bodies[0]
    assert np.all((x > np.array(body.lo)) & (x < np.array(body.hi)))


def test_projection_onto_the_run_itself_returns_its_work():
    """A case projected onto itself gives every point its own value (a random field,
    so a misplaced cell would show)."""
    case = gs.load_case(HERE / "seed_quick.toml")
    x0 = dw.fill(case)
    work = np.random.default_rng(1).random(len(x0))
    got, inside = dw.project(case, x0, work, case)
    assert inside.all()
    np.testing.assert_array_equal(got, work)


def test_projection_onto_the_seed_mesh_by_place():
    """seed_quick's work mapped onto seed.toml (surface 4 m, not 1.5 m; 8 points a
    cell): the 8 points of the seed's fine cell just under the intruder's base on its
    axis take the run's point of that cell; points deeper than the run's 1.5 m bed take
    the run's median."""
    run, seed = gs.load_case(HERE / "seed_quick.toml"), gs.load_case(HERE / "seed.toml")
    x0 = dw.fill(run)
    work = np.arange(len(x0), dtype=float)
    got, inside = dw.project(run, x0, work, seed)
    y = dw.fill(seed)
    under = np.all(np.abs(y - [0.03125, 0.03125, 4.0 - 0.03125]) < 0.0313, axis=1)
    assert under.sum() == 8
    k = int(np.argmin(np.linalg.norm(x0 - [0.03125, 0.03125, 1.5 - 0.03125], axis=1)))
    assert np.all(got[under] == work[k])
    deep = y[:, 2] < 4.0 - 1.5
    assert not inside[deep].any() and np.all(got[deep] == np.median(work))

"""The deposit profile of a column collapse (grainscale.analysis.deposit_profile and
front_at_thickness) against a lattice of points filling a known wedge."""

import numpy as np
import pytest

from grainscale.analysis import deposit_profile, front_at_thickness
from grainscale.io.vtk import read_points_vtu, write_points_vtu


def _wedge(H=0.06, slope=0.3, d=1e-3):
    """Point centres of a square lattice (spacing d, point domains of half-width d/2)
    under the surface z = H - slope x, x >= 0."""
    xs = (np.arange(int(H / slope / d) + 2) + 0.5) * d
    zs = (np.arange(int(H / d) + 1) + 0.5) * d
    x, z = np.meshgrid(xs, zs, indexing="ij")
    inside = z + d / 2 <= H - slope * x
    return x[inside], z[inside]


def test_profile_of_a_wedge_follows_its_surface():
    """Each bin's thickness is the top of the last whole point layer under the surface:
    within one spacing d below H - slope x at the bin's far end (the staircase), never
    above the surface at its near end."""
    H, slope, d = 0.06, 0.3, 1e-3
    x, z = _wedge(H, slope, d)
    edges, thick = deposit_profile(x, z, d / 2, d)
    assert edges[0] == pytest.approx(0.0, abs=1e-15)
    assert len(edges) == len(thick) + 1
    np.testing.assert_allclose(np.diff(edges), d, rtol=1e-12)
    assert np.all(thick <= H - slope * edges[:-1] + 1e-12)
    assert np.all(thick >= H - slope * edges[1:] - d - 1e-12)


@pytest.mark.parametrize("minimum", [1e-3, 5e-3, 20e-3])
def test_front_at_a_thickness(minimum):
    """The wedge is `minimum` thick at x = (H - minimum)/slope; the staircase of point
    layers (steps d high, d/slope long) puts the measured front within d/slope + d."""
    H, slope, d = 0.06, 0.3, 1e-3
    x, z = _wedge(H, slope, d)
    edges, thick = deposit_profile(x, z, d / 2, d)
    front = front_at_thickness(edges, thick, minimum)
    assert front == pytest.approx((H - minimum) / slope, abs=d / slope + d)


def test_any_thickness_gives_the_outermost_edge_and_none_gives_nan():
    """A minimum below every point's height reproduces the history's `front` (outermost
    point-domain edge); one above the deposit has no front."""
    x, z = _wedge()
    edges, thick = deposit_profile(x, z, 0.5e-3, 1e-3)
    assert front_at_thickness(edges, thick, 1e-9) == pytest.approx(x.max() + 0.5e-3,
                                                                   rel=1e-12)
    assert np.isnan(front_at_thickness(edges, thick, 1.0))


def test_frames_read_back(tmp_path):
    """read_points_vtu returns what write_points_vtu wrote (tensors flattened)."""
    rng = np.random.default_rng(0)
    pts = rng.random((5, 3))
    stress = rng.random((5, 3, 3))
    write_points_vtu(tmp_path / "f.vtu", pts, {"stress": stress, "p": pts[:, 0]})
    back, data = read_points_vtu(tmp_path / "f.vtu")
    np.testing.assert_array_equal(back, pts)
    np.testing.assert_array_equal(data["stress"].reshape(5, 3, 3), stress)
    np.testing.assert_array_equal(data["p"], pts[:, 0])


"""studies/column_collapse/measurement.py's failure surface and runout on synthetic
columns (the script itself reads runs: docs/validation.md §2.3)."""

import math

import numpy as np
import pytest

from example_scripts import load_example


@pytest.mark.parametrize("angle", [50.0, 60.0, 70.0])
def test_failure_surface_angle_of_a_sliding_wedge(angle):
    """A 100 x 60 mm column of points 2.5 mm apart whose wedge above the plane from the
    toe (x = L, z = 0) rising back at `angle` moves at 0.2 m/s and the rest is still:
    the fitted boundary's angle is the plane's within the point spacing's resolution
    (the boundary is found to one spacing per 5 mm layer: atan of a 2.5 mm error over
    the 60 mm height is ~2 deg); a point moving below the threshold does not count."""
    m = load_example("column_collapse/measurement.py")
    xs, zs = np.meshgrid(np.arange(1.25e-3, 0.1, 2.5e-3), np.arange(1.25e-3, 0.06, 2.5e-3))
    x0 = np.column_stack([xs.ravel(), np.full(xs.size, 0.005), zs.ravel()])
    above = x0[:, 0] > 0.1 - x0[:, 2] / math.tan(math.radians(angle))
    v = np.zeros_like(x0)
    v[above, 0] = 0.2
    v[~above, 0] = 0.05  # below the 0.1 sqrt(g H) threshold (0.077 m/s)
    s = m.failure_surface(x0, v, 0.1 * math.sqrt(9.81 * 0.06), 0.1, 0.06, 2.5e-3)
    assert s["angle_deg"] == pytest.approx(angle, abs=2.0)
    assert s["layers"] == 12  # every 5 mm layer has moving points
    assert m.failure_surface(x0, np.zeros_like(x0), 0.077, 0.1, 0.06, 2.5e-3) is None


def _boundary_column(x_edge: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points `spacing` apart in x, one row per 5 mm layer (z at its centre), moving at
    0.2 m/s from x_edge[k] on in layer k."""
    x = np.arange(0.0, 0.1 + 1e-12, spacing)
    x0 = np.vstack([np.column_stack([x, np.full(x.size, 0.005), np.full(x.size, 5e-3 * k + 2.5e-3)])
                    for k in range(len(x_edge))])
    v = np.zeros_like(x0)
    v[:, 0] = np.where(x0[:, 0] >= np.repeat(x_edge, x.size) - 1e-12, 0.2, 0.0)
    return x0, v


def test_failure_surface_error_of_a_boundary_on_the_lattice():
    """A boundary through 4 layers exactly on the points' 5 mm lattice at 45 deg (one
    spacing back per layer) has no residual: its error is that of a boundary known to
    one spacing, a uniform error of spacing / sqrt(12) in x: for x = a + b z with b = 1,
    se_b = (5 mm / sqrt 12) / sqrt(sum (z - mean z)^2) = 1.443 / sqrt(125) = 0.129, and
    the angle's se_b / (1 + b^2) = 0.0645 rad = 3.70 deg."""
    m = load_example("column_collapse/measurement.py")
    x0, v = _boundary_column(np.array([0.1, 0.095, 0.09, 0.085]), 5e-3)
    s = m.failure_surface(x0, v, 0.077, 0.1, 0.02, 5e-3)
    assert s["layers"] == 4 and s["angle_deg"] == 45.0
    want = math.degrees(5e-3 / math.sqrt(12) / math.sqrt(125e-6) / 2.0)
    assert s["angle_se_deg"] == pytest.approx(want, abs=0.05)  # rounded to 0.1 deg


def test_failure_surface_error_of_a_scattered_boundary():
    """A boundary scattered well beyond the lattice (1 mm spacing, edges off a 60 deg
    line by up to 4 mm): the angle's standard error is the least-squares one of x(z),
    computed here from the normal equations, (X^T X)^-1 s^2 with s^2 = RSS / (n - 2),
    mapped by d(atan(1/b))/db."""
    m = load_example("column_collapse/measurement.py")
    rng = np.random.default_rng(3)
    z = 5e-3 * np.arange(10) + 2.5e-3
    x_edge = np.round((0.1 - z / math.tan(math.radians(60.0)) + rng.uniform(-4e-3, 4e-3, 10))
                      / 1e-3) * 1e-3
    x0, v = _boundary_column(x_edge, 1e-3)
    s = m.failure_surface(x0, v, 0.077, 0.1, 0.05, 1e-3)
    X = np.column_stack([np.ones_like(z), z])
    coef, rss, *_ = np.linalg.lstsq(X, x_edge, rcond=None)
    se_b = math.sqrt(np.linalg.inv(X.T @ X)[1, 1] * rss[0] / (len(z) - 2))
    assert se_b > 1e-3 / math.sqrt(12) / math.sqrt(np.sum((z - z.mean()) ** 2))  # not the floor
    want = math.degrees(se_b / (1 + coef[1] ** 2))
    assert s["layers"] == 10
    assert s["angle_se_deg"] == pytest.approx(want, abs=0.05)  # rounded to 0.1 deg
    assert s["angle_deg"] == pytest.approx(60.0, abs=3 * s["angle_se_deg"])


def test_runout_at_reads_the_history_between_rows():
    m = load_example("column_collapse/measurement.py")
    h = {"t_over_tc": np.array([0.0, 1.0, 2.0, 6.995]),
         "runout_ratio": np.array([0.0, 0.2, 0.6, 1.0])}
    r = m.runout_at(h, (0.5, 2, 7, 8))
    assert r == {"0.5": 0.1, "2": 0.6, "7": 1.0, "8": None}

"""Shape functions on rectilinear (graded) grids, mpm/rectilinear.py: partition of
unity and linear completeness to round-off anywhere, including points whose domain
straddles a change of cell size, for the linear hats and for GIMP; the uniform grid's
functions recovered; graded axes and bad node lists checked."""

import numpy as np
import pytest

from grainscale.mpm import rectilinear, shape
from grainscale.mpm.grid import Grid

# an axis graded 2:1 by steps: 0.25 m cells, then 0.125, then 0.0625 m, then back
AXIS = np.concatenate([np.arange(0.0, 1.0, 0.25), np.arange(1.0, 1.5, 0.125),
                       np.arange(1.5, 2.0, 0.0625), np.arange(2.0, 2.5, 0.125),
                       np.arange(2.5, 3.01, 0.25)])


def sums(x, lp, gimp, axes):
    """sum S, sum S X_I, sum dS, sum dS X_I per point and axis (the 1D factors)."""
    base, w, dw = rectilinear.evaluate(x, lp, axes, gimp=gimp)
    ns = w.shape[2]
    out = np.empty((4, len(x), 3))
    for a in range(3):
        X = axes[a][base[:, a, None] + np.arange(ns)]
        out[:, :, a] = (w[:, a].sum(1), (w[:, a] * X).sum(1), dw[:, a].sum(1),
                        (dw[:, a] * X).sum(1))
    return out


@pytest.mark.parametrize("gimp", [False, True], ids=["linear", "GIMP"])
def test_partition_of_unity_and_linear_completeness_on_a_graded_grid(gimp):
    """Random points (and points placed astride every change of cell size) with the
    half-widths of points filled 2 a cell in the largest (0.0625 m) and the smallest
    cells: every identity holds to 1e-12 (round-off of O(10) terms of O(1); the
    antiderivative's differences lose ~h/l_p ~ 4-16 digits' worth of eps)."""
    rng = np.random.default_rng(3)
    axes = [AXIS, AXIS[::2].copy(), AXIS]
    lp_big = 0.25 / 4
    steps = np.array([1.0, 1.5, 2.0, 2.5])
    n = 400
    x = rng.uniform(lp_big, 3.0 - lp_big, (n, 3))
    x[:40, 0] = np.repeat(steps, 10) + rng.uniform(-lp_big, lp_big, 40)  # straddling
    lp = np.where(rng.random(n) < 0.5, lp_big, 0.0625 / 4)
    s = sums(x, lp, gimp, axes)
    np.testing.assert_allclose(s[0], 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s[1], x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s[2], 0.0, rtol=0, atol=1e-10)  # dS ~ 1/h ~ 16 /m
    np.testing.assert_allclose(s[3], 1.0, rtol=0, atol=1e-12)


def test_partition_of_unity_holds_outside_the_grid_too():
    """A point domain reaching past the last node: the folded boundary hat keeps the sum
    of weights 1 and of gradients 0 (the wall stands for the missing nodes)."""
    x = np.array([[0.01, 1.0, 2.99], [-0.02, 1.5, 3.02]])
    s = sums(x, np.full(2, 0.0625), True, [AXIS] * 3)
    np.testing.assert_allclose(s[0], 1.0, atol=1e-12)
    np.testing.assert_allclose(s[2], 0.0, atol=1e-10)


@pytest.mark.parametrize("kind", [shape.GIMP, shape.LINEAR])
def test_a_uniform_rectilinear_grid_gives_the_uniform_functions(kind):
    """Nodes 0.1 m apart given as coordinates: the weights and gradients of the uniform
    kernels (mpm/shape.py), node for node, to round-off."""
    grid = Grid.make((0.0, 0.0, 0.0), 0.1, (8, 8, 8))
    axes = [0.1 * np.arange(9)] * 3
    rng = np.random.default_rng(1)
    x = rng.uniform(0.0, 0.8, (300, 3))
    lp = np.full(300, 0.025)
    b0, w0, d0 = shape.evaluate(x, lp, grid, kind)
    ns = shape.stencil_width(kind)  # the uniform kernel's arrays hold 3 slots always
    w0, d0 = w0[:, :, :ns], d0[:, :, :ns]
    b1, w1, d1 = rectilinear.evaluate(x, lp, axes, gimp=kind == shape.GIMP)
    for a in range(3):
        full0 = np.zeros((300, 9))
        full1 = np.zeros((300, 9))
        rows = np.arange(300)[:, None]
        np.add.at(full0, (rows, b0[:, a, None] + np.arange(w0.shape[2])), w0[:, a])
        np.add.at(full1, (rows, b1[:, a, None] + np.arange(w1.shape[2])), w1[:, a])
        np.testing.assert_allclose(full1, full0, atol=1e-13)
        full0[:] = 0.0
        full1[:] = 0.0
        np.add.at(full0, (rows, b0[:, a, None] + np.arange(d0.shape[2])), d0[:, a])
        np.add.at(full1, (rows, b1[:, a, None] + np.arange(d1.shape[2])), d1[:, a])
        np.testing.assert_allclose(full1, full0, atol=1e-10)


def test_graded_axis_ends_on_its_bounds_with_the_fine_cells_exact():
    """The seed's intrusion axis (issue 33): 0.0625 m cells over [0, 1] m, growing by
    1.5 to at most 0.5 m out to 5 m: nodes at 0 and 5 exactly, 16 fine cells of 0.0625 m,
    every neighbouring ratio within the limit, accepted by check_nodes."""
    x = rectilinear.graded_axis(0.0, 5.0, 0.0, 1.0, 0.0625, 1.5, max_cell=0.5)
    assert x[0] == 0.0 and x[-1] == pytest.approx(5.0, abs=1e-12)
    h = np.diff(x)
    np.testing.assert_allclose(h[:16], 0.0625, rtol=1e-12)
    assert h[16:].min() >= 0.0625 and h.max() <= 0.5 * (1 + 1e-12)
    rectilinear.check_nodes(x, "nodes_x")
    both = rectilinear.graded_axis(-3.0, 3.0, -0.5, 0.5, 0.125, 1.3)
    assert both[0] == pytest.approx(-3.0) and both[-1] == pytest.approx(3.0)
    rectilinear.check_nodes(both, "nodes_y")
    np.testing.assert_allclose(np.diff(both)[np.abs(both[:-1] + 0.0625) < 0.5], 0.125)


@pytest.mark.parametrize("nodes, shown", [
    ([0.0], "at least 2"),
    ([0.0, 1.0, 1.0], "nodes_x[2] = 1.0"),
    ([0.0, 1.0, 1.1], "factor 10"),
    ([0.0, float("nan")], "finite"),
])
def test_bad_node_lists_are_refused_by_name(nodes, shown):
    with pytest.raises(ValueError, match=shown.replace("[", r"\[").replace("]", r"\]")):
        rectilinear.check_nodes(nodes, "nodes_x")


def test_bad_grading_arguments_are_refused_by_name():
    with pytest.raises(ValueError, match="ratio = 3"):
        rectilinear.graded_axis(0.0, 5.0, 0.0, 1.0, 0.0625, 3.0)
    with pytest.raises(ValueError, match="whole number of cells"):
        rectilinear.graded_axis(0.0, 5.0, 0.0, 1.0, 0.3, 1.5)

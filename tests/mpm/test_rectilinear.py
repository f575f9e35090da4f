"""Shape functions on rectilinear (graded) grids, mpm/rectilinear.py: partition of
unity and linear completeness to round-off anywhere, including points whose domain
straddles a change of cell size, for the linear hats and for GIMP; the uniform grid's
functions recovered; graded axes and bad node lists checked."""

import numpy as np
import pytest

from grainscale.mpm import grid as geometry
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
    for a in range(3):  # slots past an axis' own stencil hold zeros: any node will do
        X = axes[a][np.minimum(base[:, a, None] + np.arange(ns), len(axes[a]) - 1)]
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


def quadrature_weights(X, x, l):
    """Independent GIMP weights of every node of the axis X at a point x of half-width l:
    S_I = (1/2l) * integral of N_I over [x - l, x + l], by the midpoint rule on the
    pieces between the nodes (exact: N_I is linear on each; np.interp holds the end
    hats at 1 outside the grid, as the solver does), and dS_I/dx as the central
    difference of that integral in x (the integrand is piecewise linear in x, so a step
    of 1e-7 m differs from the derivative only at round-off)."""

    def S(xc):
        cuts = np.unique(np.concatenate([[xc - l, xc + l],
                                         X[(X > xc - l) & (X < xc + l)]]))
        mid, width = 0.5 * (cuts[1:] + cuts[:-1]), np.diff(cuts)
        hats = np.array([np.interp(mid, X, np.eye(len(X))[i]) for i in range(len(X))])
        return hats @ width / (2 * l)

    e = 1e-7
    return S(x), (S(x + e) - S(x - e)) / (2 * e)


def full_row(X, base, w, a):
    """The weights of one point on one axis spread over all the axis' nodes."""
    out = np.zeros(len(X))
    idx = base[a] + np.arange(w.shape[1])
    keep = idx < len(X)  # slots past the axis' own stencil are zeros
    np.add.at(out, idx[keep], w[a][keep])
    return out


# a point filled in a 1 m cell (l = 0.5 m) beside cells graded down to 0.25 m: its
# domain covers 2 to 4 small cells; points astride each step of an abrupt 2:1 change
STEPPED = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 5.5, 6.0, 6.25, 6.5, 6.75, 7.0, 7.5, 8.0])


@pytest.mark.parametrize("x, l", [
    (4.6, 0.5), (4.75, 0.5), (5.4, 0.25), (5.9, 0.25), (6.1, 0.125), (5.95, 0.5),
    (6.3, 0.125), (6.9, 0.25), (7.1, 0.25), (0.3, 0.5), (7.8, 0.25), (2.2, 0.5)])
def test_gimp_weights_on_unequal_cells_match_a_quadrature_of_the_hats(x, l):
    """The weight and gradient of every node, for points whose domain straddles a change
    of cell size (and, as a control, points inside one cell size and at the grid's
    ends), against the independent quadrature above: to 1e-9 (the central difference's
    round-off, ~eps / 1e-7 m). A stencil cut short of what a domain touches, or a
    half-width other than the point's own, moves weights by 1e-2 or more."""
    axes = [STEPPED, np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0])]  # y: 2 cells, z: 1
    xp = np.array([[x, 1.0, 0.5]])
    lp = np.array([[l, 0.5, 0.5]])
    base, w, dw = rectilinear.evaluate(xp, lp, axes, gimp=True)
    S, dS = quadrature_weights(STEPPED, x, l)
    np.testing.assert_allclose(full_row(STEPPED, base[0], w[0], 0), S, rtol=0, atol=1e-9)
    np.testing.assert_allclose(full_row(STEPPED, base[0], dw[0], 0), dS, rtol=0, atol=1e-7)


def test_a_narrow_axis_does_not_cut_a_wide_stencil_short():
    """The review's case: x graded from 1 m to 0.25 m cells, y and z with 2 cells, a
    point of a 1 m cell (l = 0.5 m) at x = 5.95 needs 5 nodes along x but only 3 along
    y and z: each axis gets its own count, the x weights sum to 1 and their gradients to
    0, and all 500 kg of a P2G reach the nodes (a stencil capped at the shortest axis'
    3 nodes lost a third of the mass)."""
    from grainscale.mpm.transfer import Transfer

    axes = [STEPPED, np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0])]
    xp = np.array([[5.95, 1.0, 1.0]])
    lp = np.array([[0.5, 0.5, 0.5]])
    ns = rectilinear.stencil(xp, lp, axes)
    assert ns.tolist() == [5, 3, 3]
    base, w, dw = rectilinear.evaluate(xp, lp, axes, gimp=True)
    assert w[0, 0].sum() == pytest.approx(1.0, abs=1e-12)
    assert dw[0, 0].sum() == pytest.approx(0.0, abs=1e-12)
    grid = Grid.rectilinear(axes)
    m = np.array([500.0])
    mass, _, ok = Transfer(grid.n_nodes, 1, 1).mass_momentum(
        m, np.zeros((1, 3)), np.zeros((1, 3, 3)), xp, grid, base, w, ns)
    assert ok and mass.sum() == pytest.approx(500.0, rel=1e-12)


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
    x = geometry.graded_axis(0.0, 5.0, 0.0, 1.0, 0.0625, 1.5, max_cell=0.5)
    assert x[0] == 0.0 and x[-1] == pytest.approx(5.0, abs=1e-12)
    h = np.diff(x)
    np.testing.assert_allclose(h[:16], 0.0625, rtol=1e-12)
    assert h[16:].min() >= 0.0625 and h.max() <= 0.5 * (1 + 1e-12)
    geometry.check_nodes(x, "nodes_x")
    both = geometry.graded_axis(-3.0, 3.0, -0.5, 0.5, 0.125, 1.3)
    assert both[0] == pytest.approx(-3.0) and both[-1] == pytest.approx(3.0)
    geometry.check_nodes(both, "nodes_y")
    np.testing.assert_allclose(np.diff(both)[np.abs(both[:-1] + 0.0625) < 0.5], 0.125)


@pytest.mark.parametrize("nodes, shown", [
    ([0.0], "at least 2"),
    ([0.0, 1.0, 1.0], "nodes_x[2] = 1.0"),
    ([0.0, 1.0, 1.1], "factor 10"),
    ([0.0, float("nan")], "finite"),
])
def test_bad_node_lists_are_refused_by_name(nodes, shown):
    with pytest.raises(ValueError, match=shown.replace("[", r"\[").replace("]", r"\]")):
        geometry.check_nodes(nodes, "nodes_x")


def test_bad_grading_arguments_are_refused_by_name():
    with pytest.raises(ValueError, match="ratio = 3"):
        geometry.graded_axis(0.0, 5.0, 0.0, 1.0, 0.0625, 3.0)
    with pytest.raises(ValueError, match="whole number of cells"):
        geometry.graded_axis(0.0, 5.0, 0.0, 1.0, 0.3, 1.5)


def test_a_periodic_graded_axis_is_padded_for_its_widest_point():
    """End cells of 0.125 m and 0.25 m on a periodic axis whose largest cells are 1 m: a
    point of a 1 m cell (l = 0.5 m) at x = 0.05 reaches 0.45 m past the period's start,
    beyond two image cells (0.375 m), which folded its weight onto the padding's end
    node (sum S X = 0.0528, sum dS X = 0.925). The padding spans the largest cell, so
    linear completeness holds in the padded coordinates at both ends, to round-off."""
    cells = [0.125, 0.25, 0.5, 1.0, 1.0, 0.5, 0.25, 0.125, 0.25]
    nodes = np.concatenate([[0.0], np.cumsum(cells)])
    g = Grid.rectilinear([nodes, [0.0, 1.0], [0.0, 1.0]], periodic=(True, False, False))
    assert g.reach()[0] >= 1.0 and np.isinf(g.reach()[1])
    x = np.array([[0.05, 0.5, 0.5], [nodes[-1] - 0.05, 0.5, 0.5], [1.2, 0.5, 0.5]])
    lp = np.array([[0.5, 0.25, 0.25]] * 3)
    s = sums(x, lp, True, g.axes)
    np.testing.assert_allclose(s[0, :, 0], 1.0, atol=1e-12)
    np.testing.assert_allclose(s[1, :, 0], x[:, 0], atol=1e-12)
    np.testing.assert_allclose(s[3, :, 0], 1.0, atol=1e-12)


def test_a_point_wider_than_the_periodic_padding_is_refused():
    """A half-width reaching past the padding is refused before the first step, naming
    lp, the axis and the largest accepted value."""
    from grainscale.mpm.materials import LinearElastic
    from grainscale.mpm.points import make_points
    from grainscale.mpm.step import MPMState

    g = Grid.rectilinear([[0.0, 0.5, 1.0], [0.0, 1.0], [0.0, 1.0]],
                         periodic=(True, False, False))
    pts = make_points(np.array([[0.25, 0.5, 0.5]]), 0.1, 1000.0, 0,
                      lp=np.array([[1.2, 0.25, 0.25]]))
    mat = LinearElastic("m", 1, density=1000.0, youngs_modulus=1e6, poisson_ratio=0.3)
    with pytest.raises(ValueError, match=r"lp: .* axis x \(1\.2 m\).*below 1 m"):
        MPMState(grid=g, points=pts, materials=[mat], mat_points=[None])


@pytest.mark.parametrize("hi, gap", [(2.5, "0.5"), (2.05, "0.05")])
def test_a_side_shorter_than_one_cell_is_refused_naming_fine_hi_and_cell(hi, gap):
    """graded_axis(0, hi, 0, 2, 1.0, 1.2) with hi 2.5 made a last cell of 0.5 m, below
    `cell` (halving the CFL step silently), and with 2.05 one of 0.05 m, refused later
    as a 'factor 20' between cells; now refused naming what to change."""
    with pytest.raises(ValueError, match=rf"fine = \[0.0, 2.0\] ends {gap} m from hi = "
                                         rf"{hi}, less than one cell = 1.0"):
        geometry.graded_axis(0.0, hi, 0.0, 2.0, 1.0, 1.2)
    with pytest.raises(ValueError, match="from lo = -0.5"):
        geometry.graded_axis(-0.5, 3.0, 0.0, 2.0, 1.0, 1.2)


def test_graded_cells_never_fall_below_the_fine_cell():
    """Over many bounds and ratios, every cell of a graded axis is at least `cell` (to
    round-off) and neighbours stay within the ratio limit."""
    for ratio in (1.0, 1.1, 1.5, 2.0):
        for length in np.linspace(1.0, 9.0, 33):
            x = geometry.graded_axis(-length, 2.0 + length, 0.0, 2.0, 1.0, ratio,
                                     max_cell=3.0)
            h = np.diff(x)
            assert h.min() >= 1.0 * (1 - 1e-12), (ratio, length, h)
            geometry.check_nodes(x, "nodes_x")

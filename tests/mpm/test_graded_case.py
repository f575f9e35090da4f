"""Graded grids from a case file: [grid] nodes_x / nodes_y / nodes_z as node lists or
graded axes, their input checks, and what a body gets on them (points per local cell,
sub-cell volumes, per-axis half-widths)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from grainscale.config.base import ConfigError
from grainscale.config.case import load_case
from grainscale.mpm.grid import graded_axis
from grainscale.mpm.setup import build_state

REST = """
[solver]
gravity = [0.0, 0.0, -9.81]
[time]
end = 0.01
[materials.m]
type = "linear_elastic"
density = 1000.0
youngs_modulus = 1e6
poisson_ratio = 0.3
[[bodies]]
material = "m"
shape = "box"
lo = [0.0, 0.0, 0.0]
hi = [0.4, 0.2, 1.0]
points_per_cell = 2
[output]
interval = 0.002
history = ["time", "kinetic_energy"]
"""

GRADED = """
[grid]
nodes_x = [0.0, 0.1, 0.2, 0.4, 0.6]
nodes_y = {lo = 0.0, hi = 0.2, cell = 0.1}
[grid.nodes_z]
lo = 0.0
hi = 1.0
cell = 0.05
fine = [0.0, 0.2]
ratio = 1.5
"""


def _case(tmp_path, grid: str, rest: str = REST):
    path = tmp_path / "case.toml"
    path.write_text(textwrap.dedent(grid) + rest)
    return load_case(path)


def test_node_lists_and_graded_axes_make_the_grid_and_its_bodies(tmp_path):
    """The three forms (a list, an inline graded table, a graded table) give the node
    coordinates they say; the box gets 8 points in every local cell it covers, each
    with its sub-cell's volume (summing to the box's) and its sub-cell's half-widths
    per axis."""
    case = _case(tmp_path, GRADED)
    s = build_state(case, tmp_path)
    ax = s.grid.axes
    np.testing.assert_array_equal(ax[0], [0.0, 0.1, 0.2, 0.4, 0.6])
    np.testing.assert_allclose(ax[1], [0.0, 0.1, 0.2], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(ax[2], graded_axis(0.0, 1.0, 0.0, 0.2, 0.05, 1.5))
    assert np.all(np.diff(ax[2])[:4] == pytest.approx(0.05))  # the fine interval
    assert np.diff(ax[2]).max() <= 2 * 0.05 * 1.5 ** 3  # grows outward
    pts = s.points
    assert pts.vol.sum() == pytest.approx(0.4 * 0.2 * 1.0, rel=1e-12)
    # per local cell covered by the box: 2 x 2 x 2 points
    cx = np.searchsorted(ax[0], pts.x[:, 0]) - 1
    cz = np.searchsorted(ax[2], pts.x[:, 2]) - 1
    cy = np.searchsorted(ax[1], pts.x[:, 1]) - 1
    _, counts = np.unique(np.stack([cx, cy, cz], axis=1), axis=0, return_counts=True)
    assert np.all(counts == 8)
    h = [np.diff(a) for a in ax]
    for a, c in enumerate((cx, cy, cz)):
        np.testing.assert_allclose(pts.lp[:, a], h[a][c] / 4, rtol=1e-12)
    np.testing.assert_allclose(pts.vol, 8 * pts.lp.prod(axis=1), rtol=1e-12)
    # the CFL step comes from the smallest cell
    assert s.grid.cell_size.min() == pytest.approx(0.05)


def test_node_axes_of_uniform_and_graded_grids(tmp_path):
    """GridCfg.node_axes is the solver's node coordinates, graded or uniform."""
    from grainscale.mpm.setup import build_grid

    graded = _case(tmp_path, GRADED)
    # the case's own node lists, as written in GRADED, against the solver's grid
    written = [[0.0, 0.1, 0.2, 0.4, 0.6], [0.0, 0.1, 0.2],
               graded_axis(0.0, 1.0, 0.0, 0.2, 0.05, 1.5)]
    for got, want, solver in zip(graded.grid.node_axes(), written,
                                 build_state(graded, tmp_path).grid.axes, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(got, solver)
    uniform = load_case(Path(__file__).resolve().parents[2] / "examples" / "intrusion"
                        / "quick.toml")
    assert uniform.grid.axes() is None
    solver = build_grid(uniform).node_axes()
    for a, nodes in enumerate(uniform.grid.node_axes()):
        assert len(nodes) == uniform.grid.cells[a] + 1
        np.testing.assert_array_equal(nodes, solver[a])


@pytest.mark.parametrize("grid, words", [
    ("[grid]\nnodes_x = [0.0, 0.1, 0.1, 0.2]\nnodes_y = [0.0, 0.1]\nnodes_z = [0.0, 0.1]\n",
     ["grid.nodes_x[2] = 0.1", "increase strictly"]),
    ("[grid]\nnodes_x = [0.0, 0.1, 0.4]\nnodes_y = [0.0, 0.1]\nnodes_z = [0.0, 0.1]\n",
     ["grid.nodes_x", "cells 0 and 1", "factor 3", "at most 2"]),
    ("[grid]\nnodes_x = [0.0, 0.1]\nnodes_y = [0.0, 0.1]\n",
     ["grid.nodes_x is given but not grid.nodes_z"]),
    ("[grid]\ncell_size = 0.1\nnodes_x = [0.0, 0.1]\nnodes_y = [0.0, 0.1]\n"
     "nodes_z = [0.0, 0.1]\n", ["grid.cell_size with grid.nodes_x/y/z"]),
    ("[grid]\nnodes_x = [0.0, 0.1, 0.15, 0.175]\nnodes_y = [0.0, 0.1]\nnodes_z = [0.0, 0.1]\n"
     "periodic = ['x']\n", ["grid.nodes_x", "meet across the periodic ends", "factor 4",
                            "at most 2"]),
    ("[grid]\nnodes_x = [0.0, 0.1]\nnodes_y = [0.0, 0.1]\nnodes_z = [0.0, 0.1]\n"
     "periodic = ['x']\n", ["grid.nodes_x", "at least 2 cells"]),
    ("[grid]\nnodes_x = {lo = 0.0, hi = 1.0, cell = 0.1, fine = [0.0, 0.2], ratio = 3.0}\n"
     "nodes_y = [0.0, 0.1]\nnodes_z = [0.0, 0.1]\n", ["grid.nodes_x", "ratio = 3.0",
                                                     "valid 1 to 2"]),
    ("[grid]\nnodes_x = {lo = 0.0, hi = 1.0, cell = 0.3, fine = [0.0, 0.5]}\n"
     "nodes_y = [0.0, 0.1]\nnodes_z = [0.0, 0.1]\n", ["grid.nodes_x", "whole number"]),
    ("[grid]\ncells = [2, 2, 2]\n", ["grid.cell_size is missing"]),
])
def test_bad_grids_are_refused_by_key_value_and_range(tmp_path, grid, words):
    with pytest.raises(ConfigError) as err:
        _case(tmp_path, grid)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_a_graded_case_runs_and_keeps_its_points_inside(tmp_path):
    """`grainscale run` of the graded case: 10 steps of a column settling under
    gravity on its fixed base (the grid's z- face); momentum enters only through the
    base, so the points stay inside and the history is written."""
    from grainscale.analysis import read_columns
    from grainscale.cli import main

    path = tmp_path / "case.toml"
    path.write_text(textwrap.dedent(GRADED) + REST.replace("[output]", textwrap.dedent("""
        [[boundaries]]
        face = "z-"
        type = "fixed"
        [output]""")))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet", "--max-steps", "10"]) == 0
    hist = read_columns(out / "history.csv")
    assert hist["step"][-1] == 10
    assert np.isfinite(hist["kinetic_energy"]).all()
    # where the points went: the base's reaction has not reached the top yet (a wave at
    # ~40 m/s covers 0.25 m of the 1 m column in the run's t), so the top layer falls
    # freely, g t^2 / 2 to g t^2 (n + 1) / 2n with the n steps' symplectic Euler;
    # sideways only the points by the fixed base move, squeezed out by its reaction
    # (3e-5 m measured; 1e-4 m is 1/500 of the smallest cell), and every point stays
    # inside the grid's box
    import xml.etree.ElementTree as ET

    import meshio

    pvd = ET.parse(out / "frames.pvd").getroot().findall("Collection/DataSet")
    x0, x1 = (meshio.read(out / d.get("file")).points for d in (pvd[0], pvd[-1]))
    t = float(pvd[-1].get("timestep")) - float(pvd[0].get("timestep"))
    assert t > 0.0
    top = x0[:, 2] > x0[:, 2].max() - 1e-9
    drop = x0[top, 2] - x1[top, 2]
    assert np.all(drop >= 0.5 * 9.81 * t**2 * (1 - 1e-9))
    n = int(hist["step"][np.argmin(np.abs(hist["time"] - hist["time"][0] - t))])
    assert np.all(drop <= 0.5 * 9.81 * t**2 * (n + 1) / n * (1 + 1e-6))  # the upper bound
    # is exact for a constant step, so only round-off is allowed
    assert np.abs(x1[:, :2] - x0[:, :2]).max() < 1e-4
    assert np.all((x1 >= [0.0, 0.0, 0.0]) & (x1 <= [0.6, 0.2, 1.0]))
    # grid.vtr, ParaView's RectilinearGrid of the node coordinates
    root = ET.parse(out / "grid.vtr").getroot()
    arrays = root.find("RectilinearGrid/Piece/Coordinates").findall("DataArray")
    axes = load_case(path).grid.axes()
    for a, arr in enumerate(arrays):
        np.testing.assert_array_equal(np.array(arr.text.split(), float), axes[a])
    assert root.find("RectilinearGrid").get("WholeExtent") == "0 4 0 2 0 9"
    # the run's case.resolved.toml reads back as the same grid (no uniform origin in it)
    import grainscale as gs

    for a, nodes in enumerate(gs.open_result(out).case.grid.axes()):
        np.testing.assert_array_equal(nodes, axes[a])


@pytest.mark.parametrize("name", ["seed", "seed_cuboid"])
def test_the_seed_mesh_cases_load_with_the_seeds_resolution(name):
    """examples/intrusion/seed.toml (and its cuboid): the seed's 5 x 5 m quarter with
    0.0625 m cells over the intruder's neighbourhood (x, y to 0.75 m; z from 3.0 to
    4.25 m), 33 x 33 x 34 cells in the 4 m bed, 8 points a cell: 296,208 RVEs, 3 %
    more than the seed's 287,496."""
    from grainscale.mpm.grid import Grid
    from grainscale.mpm.points import fill_box

    path = Path(__file__).resolve().parents[2] / "examples" / "intrusion" / f"{name}.toml"
    case = load_case(path)
    axes = case.grid.axes()
    grid = Grid.rectilinear(axes)
    h = [np.diff(a) for a in axes]
    for a in (0, 1):
        fine = axes[a][1:] <= 0.75 + 1e-9
        np.testing.assert_allclose(h[a][fine], 0.0625, rtol=1e-12)
        assert fine.sum() == 12 and len(h[a]) == 33
    fine = (axes[2][:-1] >= 3.0 - 1e-9) & (axes[2][1:] <= 4.25 + 1e-9)
    np.testing.assert_allclose(h[2][fine], 0.0625, rtol=1e-12)
    assert fine.sum() == 20
    body = case.bodies[0]
    x, vol = fill_box(grid, body.lo, body.hi, body.points_per_cell)
    assert len(x) == 296_208
    assert vol.sum() == pytest.approx(5.0 * 5.0 * 4.0, rel=1e-12)


def test_the_quick_seed_mesh_case_loads_with_the_seeds_near_field_cells():
    """examples/intrusion/seed_quick.toml: quick.toml's 2 x 2 m quarter of a 1.5 m bed
    with the seed's 0.0625 m cells over x, y <= 0.75 m and z in [0.5, 1.75] m, growing by
    1.5 per cell outward, one point a cell: 17 x 17 x 19 cells in the bed, 5,491 RVEs."""
    from grainscale.mpm.grid import Grid
    from grainscale.mpm.points import fill_box

    path = Path(__file__).resolve().parents[2] / "examples" / "intrusion" / "seed_quick.toml"
    case = load_case(path)
    axes = case.grid.axes()
    h = [np.diff(a) for a in axes]
    assert np.isclose(h[0], 0.0625, rtol=1e-12).sum() == 12
    fine_z = (axes[2][:-1] >= 0.5 - 1e-9) & (axes[2][1:] <= 1.75 + 1e-9)
    np.testing.assert_allclose(h[2][fine_z], 0.0625, rtol=1e-12)
    assert fine_z.sum() == 20
    body = case.bodies[0]
    x, _ = fill_box(Grid.rectilinear(axes), body.lo, body.hi, body.points_per_cell)
    assert len(x) == 5_491


@pytest.mark.parametrize("surface, lo, hi, traction, area", [
    ("z+", [0.0, 0.0, 0.9], [0.4, 0.2, 1.0], [0.0, 0.0, -1e4], 0.4 * 0.2),
    ("x+", [0.3, 0.0, 0.0], [0.4, 0.2, 1.0], [-1e4, 0.0, 0.0], 0.2 * 1.0),
    ("z-", [0.0, 0.0, 0.0], [0.4, 0.2, 0.02], [0.0, 0.0, 2e3], 0.4 * 0.2),
])
def test_a_traction_on_a_graded_face_applies_traction_times_its_area(tmp_path, surface, lo,
                                                                     hi, traction, area):
    """The loaded points' forces add up to the traction times the face's area on a graded
    grid, where each point's sub-cell is a box (0.05-0.12 m along z, 0.1-0.2 m along
    x): 1e-12 relative (a sum of O(100) areas). A point's area taken as V0^(2/3), as
    if its domain were a cube, gave 0.57x the top's load and 2.66x the side's on the
    intrusion's grid. Both nodal load totals (after the linear spread) agree too."""
    from grainscale.mpm import boundary

    extra = textwrap.dedent(f"""
        [[tractions]]
        lo = {lo}
        hi = {hi}
        surface = "{surface}"
        traction = {traction}
        area = "initial"
        """)
    s = build_state(_case(tmp_path, GRADED, REST + extra), tmp_path)
    (t,) = s.tractions
    layer = {"z+": s.points.x[:, 2] > 1.0 - s.points.lp[:, 2] * 1.01,
             "x+": s.points.x[:, 0] > 0.4 - s.points.lp[:, 0] * 1.01,
             "z-": s.points.x[:, 2] < s.points.lp[:, 2] * 1.01}[surface]
    assert np.array_equal(np.sort(t.points), np.flatnonzero(layer))  # one layer of points
    np.testing.assert_allclose(t.force.sum(axis=0), np.asarray(traction) * area, rtol=1e-12,
                               atol=1e-9)
    _, f = boundary.traction_loads([t], 1.0, s.points.x, s.points.lp, s.grid)
    np.testing.assert_allclose(f.sum(axis=0), np.asarray(traction) * area, rtol=1e-12,
                               atol=1e-9)


def test_points_read_from_a_file_get_half_widths_from_their_own_cell(tmp_path):
    """A point of a file body in a 0.2 m cell with the volume of a 0.1 m cube gets
    l = 0.05 m on every axis (half the cube's side), one in a 0.05 m cell along z gets
    0.025 m there (half its cell): the grid's smallest cell (0.05 m) no longer caps a
    coarse cell's point, which made GIMP the linear hats there."""
    (tmp_path / "pts.txt").write_text("0.5 0.1 0.9 0.001\n0.05 0.05 0.025 0.001\n")
    rest = REST.replace('shape = "box"\nlo = [0.0, 0.0, 0.0]\nhi = [0.4, 0.2, 1.0]\n'
                        'points_per_cell = 2\n', 'shape = "file"\npath = "pts.txt"\n')
    s = build_state(_case(tmp_path, GRADED, rest), tmp_path)
    np.testing.assert_allclose(s.points.lp, [[0.05, 0.05, 0.05], [0.05, 0.05, 0.025]],
                               rtol=1e-12)


def test_a_nodes_mass_threshold_is_a_point_of_its_own_cells():
    """The mass of "a point" beside a node (MPMState.m_point_ref, which the active-node,
    light-node and contact-zone thresholds are fractions of) is that of a point made in
    the largest cell beside the node, wherever the grid's largest cells are: a body 2
    points a cell in 0.1 m cells under empty cells growing to 0.4 m gives its nodes the
    mass of its own points (dividing by the grid's largest cell made it 1/4 of it) and a
    node beside a 0.2 m cell twice that (the cell is twice as tall)."""
    from grainscale.mpm.grid import Grid
    from grainscale.mpm.materials import LinearElastic
    from grainscale.mpm.points import fill_box, make_points, sub_cell_half_widths
    from grainscale.mpm.step import MPMState

    xy = [0.0, 0.1, 0.2]
    grid = Grid.rectilinear([xy, xy, [0.0, 0.1, 0.2, 0.4, 0.8]])
    x, vol = fill_box(grid, [0, 0, 0], [0.2, 0.2, 0.2], 2)
    pts = make_points(x, vol, 1000.0, 0, lp=sub_cell_half_widths(grid, x, 2))
    mat = LinearElastic("m", pts.n, density=1000.0, youngs_modulus=1e6, poisson_ratio=0.3)
    s = MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None])
    ref = s.m_point_ref.reshape(5, 3, 3)  # [k, j, i]
    m = 1000.0 * 0.05**3
    np.testing.assert_allclose(ref[1], m, rtol=1e-12)  # z = 0.1: cells of 0.1 m around
    np.testing.assert_allclose(ref[2], 2 * m, rtol=1e-12)  # z = 0.2: a 0.2 m cell above


def test_a_traction_on_file_points_whose_cell_cut_their_domain_uses_their_volume(tmp_path):
    """A file point whose cube (V0^(1/3) = 0.1 m) its 0.05 m cell cut along z carries
    V0^(2/3) on a z face, as it would on a uniform grid, not V0 / (2 l_z) (twice that):
    only a sub-cell box (V0 = 8 lx ly lz) is loaded on its face."""
    (tmp_path / "pts.txt").write_text("0.05 0.05 0.025 0.001\n")
    rest = REST.replace('shape = "box"\nlo = [0.0, 0.0, 0.0]\nhi = [0.4, 0.2, 1.0]\n'
                        'points_per_cell = 2\n', 'shape = "file"\npath = "pts.txt"\n')
    rest += textwrap.dedent("""
        [[tractions]]
        lo = [0.0, 0.0, 0.0]
        hi = [0.1, 0.1, 0.05]
        surface = "z-"
        traction = [0.0, 0.0, 1e3]
        area = "initial"
        """)
    s = build_state(_case(tmp_path, GRADED, rest), tmp_path)
    assert s.points.lp[0, 2] == pytest.approx(0.025)
    np.testing.assert_allclose(s.tractions[0].force[0], [0.0, 0.0, 1e3 * 0.01], rtol=1e-12)

"""examples/intrusion/force_chains.py (a probe RVE's contact network) and
studies/intrusion/stress_scatter.py (the point-to-point scatter of the pressure)."""

import meshio
import numpy as np
import pytest

from dem.dem_helpers import agitated_dense_state
from example_scripts import load_example
from grainscale import analysis
from grainscale.dem import engine
from grainscale.io.rve_vtk import write_rve_vtk
from grainscale.stress import p_q

chains = load_example("intrusion/force_chains.py")
scatter = load_example("intrusion/stress_scatter.py")


def test_network_of_a_written_rve_matches_the_engine(tmp_path):
    """On an RVE the engine compressed and wrote (io/rve_vtk.py), the pressure summed
    from the contacts file, (1/V) sum d (x) f with V from the cell file, is the engine's
    own Love-Weber pressure once the grains are at rest (the engine adds the kinetic
    stress of their fluctuating motion, which the contacts file does not hold): both
    are the same sum in double precision, so 1e-9 relative. Z counts each contact with a
    positive normal force twice over the spheres: with no dashpot every touching pair
    pushes, so Z is twice the engine's own contact count over the spheres."""
    b, p, _ = agitated_dense_state()
    b.v[0] = 0.0
    b.w[0] = 0.0
    engine.refresh(b, p)
    spheres, contacts, cell = (meshio.read(f) for f in write_rve_vtk(tmp_path / "r", b, p))
    assert chains.cell_volume(cell) == pytest.approx(abs(np.linalg.det(b.h[0])), rel=1e-12)
    m = chains.network(contacts, spheres, cell)
    p_engine = p_q(b.stress[0])[0]
    assert p_engine > 0
    assert m["p_contacts"] == pytest.approx(p_engine, rel=1e-9)
    assert m["p"] == pytest.approx(p_engine, rel=1e-9)
    assert p.gamma == 0.0
    assert m["Z"] == pytest.approx(2 * b.ncontact[0] / b.n_particles)
    assert 0.0 < m["strong_share"] < 1.0


def hand_network(fn_z, fn_x):
    """Four spheres: two contacts along z with normal forces fn_z, one along x with
    fn_x, one touching pair with no force; a unit cube cell with stress -p I."""
    pts = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 1], [0, 0, 2], [0, 0, 0], [1, 0, 0],
                    [1, 0, 0], [1, 1, 0]], float)
    lines = np.arange(8).reshape(4, 2)
    fn = np.array([fn_z[0], fn_z[1], fn_x, 0.0])
    d = pts[1::2] - pts[0::2]
    contacts = meshio.Mesh(pts, [("line", lines)], cell_data={
        "normal_force": [fn], "force_vector": [-fn[:, None] * d]})
    spheres = meshio.Mesh(np.zeros((4, 3)), [("vertex", np.arange(4).reshape(-1, 1))])
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                        [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    cell = meshio.Mesh(corners, [("hexahedron", np.arange(8).reshape(1, 8))], cell_data={
        "p": [np.array([7.0])], "q": [np.array([3.5])], "porosity": [np.array([0.4])]})
    return contacts, spheres, cell


def test_fabric_and_strong_network_by_hand():
    """Forces 2, 2 along z and 0.5 along x (mean 1.5): the strong network is the two
    vertical contacts, so a_z = 1 - 0 = 1 and its share 2/3; Z = 2 x 3 / 4; the
    contacts' pressure -tr(sum d (x) f)/3V = (2 + 2 + 0.5)/3 in a unit cell."""
    m = chains.network(*hand_network((2.0, 2.0), 0.5))
    assert m["Z"] == pytest.approx(1.5)
    assert m["mean_normal_force"] == pytest.approx(1.5)
    assert m["strong_share"] == pytest.approx(2 / 3)
    assert m["a_z_strong"] == pytest.approx(1.0)
    assert m["p_contacts"] == pytest.approx(4.5 / 3)
    assert (m["p"], m["q_over_p"], m["porosity"]) == pytest.approx((7.0, 0.5, 0.4))
    # chains along x instead: a_z = 0 - (1 + 0)/2
    m = chains.network(*hand_network((0.5, 0.5), 2.0))
    assert m["a_z_strong"] == pytest.approx(-0.5) and m["strong_share"] == pytest.approx(1 / 3)


def lattice(n=9, h=0.1):
    """Points at the cell centres of an n^3 grid of cells h in x, y in [0, n h] (two
    symmetry planes, as the quarter model's) and z in [-n h, 0]."""
    g = (np.arange(n) + 0.5) * h
    x = np.stack(np.meshgrid(g, g, g - n * h, indexing="ij"), axis=-1).reshape(-1, 3)
    return x, np.indices((n, n, n)).reshape(3, -1).T


def test_neighbours_are_the_face_neighbours_also_on_the_symmetry_planes():
    """On the lattice a point's neighbours are its face neighbours: 6 inside, 5 on one
    symmetry plane, 4 on the axis (x, y < h). Given the values 1..k on its k face
    neighbours and 100 on every other point, the median is (k + 1) / 2 exactly; one
    more point, such as a diagonal one at sqrt(2) h (which a fixed count of six nearest
    would take on a plane), would move it."""
    x, ijk = lattice()
    for cell, k in (((4, 4, 4), 6), ((0, 4, 4), 5), ((0, 0, 4), 4)):
        i = int(np.flatnonzero(np.all(ijk == cell, axis=1))[0])
        faces = np.flatnonzero(np.abs(ijk - cell).sum(axis=1) == 1)
        assert len(faces) == k
        values = np.full(len(x), 100.0)
        values[faces] = np.arange(1.0, k + 1)
        assert analysis.neighbour_median(x, values, [i])[0] == (k + 1) / 2


def test_scatter_of_smooth_and_checkerboard_fields():
    """A pressure growing linearly with depth: every point's face neighbours straddle it
    (+-z) or share its value (x, y), so the median is its own value: no scatter. One
    also growing as x^2 + y^2 (symmetric about the planes, as a quarter model's fields
    are): the median of the neighbours departs from the point by the curvature and the
    lateral gradient's step, 0.44 % of p in the median here (2 % at most), bound 1 %,
    far below the tens of percent measured in the runs. A checkerboard
    p = 1 +- 0.9: every neighbour has the other sign, so the low half (0.1 against 1.9)
    all lie below a fifth of their neighbours' pressure."""
    x, ijk = lattice()
    m = scatter.scatter(x, x, 1e4 * (1.0 - x[:, 2]), base=0.0, radius=0.5, depth=0.45,
                        width=1.0)
    assert m["points"] > 0
    assert m["median_rel_dev"] < 1e-12 and m["share_below_fifth"] == 0.0
    bowl = 1e4 * (1.0 - x[:, 2]) + 3e3 * (x[:, 0] ** 2 + x[:, 1] ** 2)
    m = scatter.scatter(x, x, bowl, base=0.0, radius=0.5, depth=0.45, width=1.0)
    assert m["median_rel_dev"] < 0.01 and m["share_below_fifth"] == 0.0
    board = 1.0 + 0.9 * (-1.0) ** ijk.sum(axis=1)
    m = scatter.scatter(x, x, board, base=0.0, radius=0.5, depth=0.45, width=1.0,
                        coordination=np.where(board < 1.0, 1.0, 4.0))
    low = np.mean(board[(np.hypot(x[:, 0], x[:, 1]) < 0.5) & (x[:, 2] > -0.45)] < 1.0)
    assert m["share_below_fifth"] == pytest.approx(low)
    assert m["median_rel_dev"] > 0.9
    # the low points are the ones given Z = 1
    assert m["share_z_below_2"] == pytest.approx(low)
    assert m["share_below_fifth_with_z_below_2"] == 1.0

"""examples/intrusion/force_chains.py (a probe RVE's contact network) and
studies/intrusion/stress_scatter.py (the point-to-point scatter of the pressure)."""

import meshio
import numpy as np
import pytest

from dem.dem_helpers import agitated_dense_state
from example_scripts import load_example
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
    positive normal force twice over the spheres."""
    b, p, _ = agitated_dense_state()
    b.v[0] = 0.0
    b.w[0] = 0.0
    engine.refresh(b, p)
    spheres, contacts, cell = (meshio.read(f) for f in write_rve_vtk(tmp_path / "r", b, p.young))
    assert chains.cell_volume(cell) == pytest.approx(abs(np.linalg.det(b.h[0])), rel=1e-12)
    m = chains.network(contacts, spheres, cell)
    p_engine = p_q(b.stress[0])[0]
    assert p_engine > 0
    assert m["p_contacts"] == pytest.approx(p_engine, rel=1e-9)
    assert m["p"] == pytest.approx(p_engine, rel=1e-9)
    fn = contacts.cell_data["normal_force"][0]
    assert m["Z"] == pytest.approx(2 * np.count_nonzero(fn > 0) / b.n_particles)
    assert 0.0 < m["strong_share"] < 1.0 and -0.5 <= m["a_z_strong"] <= 1.0


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
    g = (np.arange(n) + 0.5) * h
    x = np.stack(np.meshgrid(g, g, g - n * h, indexing="ij"), axis=-1).reshape(-1, 3)
    return x, np.indices((n, n, n)).reshape(3, -1).T


def test_scatter_of_smooth_and_checkerboard_fields():
    """A pressure linear in depth: each interior point's six face neighbours straddle it
    symmetrically, so their median is its own value: no scatter. A checkerboard
    p = 1 +- 0.9: every neighbour has the other sign, so the low half (0.1 against 1.9)
    all lie below a fifth of their neighbours."""
    x, ijk = lattice()
    smooth = 1e4 * (1.0 - x[:, 2])
    m = scatter.scatter(x, x, smooth, base=0.0, radius=0.5, depth=0.45, width=1.0)
    assert m["points"] > 0
    # edge points (neighbours not symmetric) are few; the median stays at round-off
    assert m["median_rel_dev"] < 1e-12 and m["share_below_fifth"] == 0.0
    board = 1.0 + 0.9 * (-1.0) ** ijk.sum(axis=1)
    m = scatter.scatter(x, x, board, base=0.0, radius=0.5, depth=0.45, width=1.0)
    low = np.mean(board[(np.hypot(x[:, 0], x[:, 1]) < 0.5) & (x[:, 2] > -0.45)] < 1.0)
    assert m["share_below_fifth"] == pytest.approx(low)
    assert m["median_rel_dev"] > 0.9

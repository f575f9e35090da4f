"""Full-state HDF5 round trip (restart continues bitwise) and VTK snapshots."""

from __future__ import annotations

import meshio
import numpy as np
import pytest
from dem_helpers import agitated_dense_state

from grainscale.config.base import ConfigError
from grainscale.dem import engine
from grainscale.dem.state import STATE_FIELDS, from_packing
from grainscale.io.rve_h5 import read_rve_state, write_rve_state
from grainscale.io.rve_vtk import write_rve_vtk

FIELDS = ("h", "s", "v", "w", "rot", "stress", "stiffness", "force", "torque", "L",
          "ncontact", "unbalanced", "kinetic")


def _control():
    # a servo (needs stress and stiffness of the last step: they must be in the file)
    # plus a prescribed shear
    lc = np.array([[0.0, 0.0, 0.0], [0.0, -10.0, 4.0], [0.0, 0.0, -10.0]])
    return engine.rate_control(1, l_ctrl=lc, servo={0: -2e3}, max_rate=50.0)


def test_restart_from_hdf5_continues_bitwise(tmp_path):
    """Run 200 + 200 steps uninterrupted vs 200 steps, write, read, 200 steps: equal
    bitwise (every state array, incl. tangential history and the servo's stress and
    stiffness, survives; nothing is recomputed differently after a reload)."""
    b, p, dt = agitated_dense_state()
    engine.advance(b, 200, dt, p, _control())
    path = tmp_path / "state.h5"
    write_rve_state(path, b, {"young_modulus": p.young})
    loaded, params = read_rve_state(path)
    assert params == {"young_modulus": p.young}
    for name in STATE_FIELDS:
        a, c = getattr(b, name), getattr(loaded, name)
        assert a.dtype == c.dtype and np.array_equal(a, c), name
    engine.advance(b, 200, dt, p, _control())
    engine.advance(loaded, 200, dt, p, _control())
    assert b.ncontact[0] > 0
    for name in FIELDS:
        assert np.array_equal(getattr(b, name), getattr(loaded, name)), name
    for i in range(b.n_particles):
        c = b.nbr_count[0, i]
        assert np.array_equal(b.ft[0, i, :c], loaded.ft[0, i, :c])


def test_hdf5_errors(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        read_rve_state(tmp_path / "none.h5")
    import h5py
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["format"] = "something else"
    with pytest.raises(ConfigError, match="not a grainscale RVE state"):
        read_rve_state(tmp_path / "other.h5")


def test_vtk_snapshot_counts_and_values(tmp_path):
    """Spheres file: one vertex per sphere, wrapped into the cell, with the radii.
    Contacts file: one line per touching pair (independent brute-force count over the
    27 images), normal force kn * overlap, line length = centre distance < ri + rj.
    Cell file: the 8 corners h @ {0,1}^3."""
    b, p, dt = agitated_dense_state()
    engine.refresh(b, p)
    paths = write_rve_vtk(tmp_path / "snap", b, p)
    assert [q.name for q in paths] == ["snap_spheres.vtu", "snap_contacts.vtu",
                                       "snap_cell.vtu"]
    sph = meshio.read(paths[0])
    n = b.n_particles
    assert len(sph.points) == n and sum(len(c.data) for c in sph.cells) == n
    np.testing.assert_array_equal(sph.point_data["radius"], b.radius[0])
    s = np.linalg.solve(b.h[0], sph.points.T).T
    assert np.all(s > -1e-12) and np.all(s < 1 + 1e-12)
    con = meshio.read(paths[1])
    # brute-force contacts
    r = b.radius[0]
    iu, ju = np.triu_indices(n, 1)
    ds = b.s[0, ju] - b.s[0, iu]
    ds -= np.round(ds)
    dist = np.linalg.norm(ds @ b.h[0].T, axis=1)
    touch = dist < r[iu] + r[ju]
    assert touch.sum() == b.ncontact[0] > 0
    lines = con.cells_dict["line"]
    assert len(lines) == touch.sum()
    length = np.linalg.norm(con.points[lines[:, 1]] - con.points[lines[:, 0]], axis=1)
    np.testing.assert_allclose(np.sort(length), np.sort(dist[touch]), rtol=1e-12)
    kn = p.young * 2 * r[iu] * r[ju] / (r[iu] + r[ju])
    fn_expected = (kn * (r[iu] + r[ju] - dist))[touch]
    np.testing.assert_allclose(np.sort(con.cell_data["normal_force"][0]),
                               np.sort(fn_expected), rtol=1e-9)
    cell = meshio.read(paths[2])
    corners = np.array([[a, c, d] for d in (0, 1) for c in (0, 1) for a in (0, 1)], float)
    expected = corners @ b.h[0].T
    got = {tuple(np.round(x / 1e-12)) for x in cell.points}
    assert got == {tuple(np.round(x / 1e-12)) for x in expected}


def test_vtk_contact_line_starts_at_drawn_sphere_across_boundary(tmp_path):
    """A sphere that has crossed the periodic face since the last list build (s not yet
    wrapped) is drawn wrapped; its contact line must start at the drawn centre and end
    at the touching image of its partner (branch length = centre distance)."""
    r = 1e-3
    x1 = np.array([0.005e-3, 5e-3, 5e-3])
    b = from_packing(np.eye(3) * 10e-3, np.array([x1, x1 + [2 * r - 1e-5, 0, 0]]),
                     np.array([r, r]), 2500.0)
    p = engine.ContactParams(young=1e7, stiffness_ratio=0.5, friction=0.5, damping=0.0,
                             skin=0.5e-3)
    b.v[0, :, 0] = -1.0  # both drift across the x face together
    engine.advance(b, 6, engine.critical_dt(b, p, 0.1), p, engine.rate_control(1))
    assert b.s[0, 0, 0] < 0 and b.need_rebuild[0] == 0 and b.ncontact[0] == 1
    engine.refresh(b, p)
    sph, con, _ = (meshio.read(q) for q in write_rve_vtk(tmp_path / "c", b, p))
    (i0, i1), = con.cells_dict["line"]
    start, end = con.points[i0], con.points[i1]
    np.testing.assert_allclose(start, sph.points[0], rtol=0, atol=1e-15)
    d = b.s[0, 1] - b.s[0, 0]
    np.testing.assert_allclose(end - start, b.h[0] @ d, rtol=0, atol=1e-15)

"""Doubling a thin periodic cell (dem/retile.py) leaves the physical system unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from dem_helpers import agitated_dense_state

from grainscale.dem import engine
from grainscale.dem.cell import perpendicular_widths
from grainscale.dem.retile import double_cell, widths


@pytest.mark.parametrize("k", [0, 1, 2])
def test_doubled_cell_is_the_same_periodic_system(k):
    """The cell doubled along edge k holds every grain twice, so per grain the forces
    (tangential history included) and the Love-Weber stress (twice the contacts in twice
    the volume) are those of the original, and the same deformation keeps them equal.

    Tolerances: at the instant of doubling both compute the same sums in another order
    (1e-12 of the largest entry). The two copies start identical and, under the same
    cell motion, stay so up to round-off growing chaotically over 150 steps; the
    measured gap is below 1e-10, so 1e-8 leaves margin. A lost tangential history
    changes the forces by O(1e-2) of their size, a wrong image shift by O(1).
    """
    b, p, dt = agitated_dense_state()
    shear = np.array([[0.0, 60.0, 0.0], [0.0, 0.0, 20.0], [-30.0, 0.0, 0.0]])
    engine.advance(b, 200, dt, p, engine.rate_control(1, l_ctrl=shear, max_rate=100.0))
    assert np.abs(b.ft).max() > 0  # contacts carry tangential history
    n = b.n_particles
    c = double_cell(b, 0, k)
    old_widths = perpendicular_widths(np.ascontiguousarray(b.h[0]))
    new_widths = perpendicular_widths(np.ascontiguousarray(c.h[0]))
    expect = old_widths.copy()
    expect[k] *= 2
    np.testing.assert_allclose(new_widths, expect, rtol=1e-12)
    assert np.isclose(c.volume()[0], 2 * b.volume()[0], rtol=1e-12)
    engine.refresh(b, p)
    engine.refresh(c, p)  # rebuilds c's lists from the transformed ones
    assert c.ncontact[0] == 2 * b.ncontact[0]
    smax = np.abs(b.stress).max()
    fmax = np.abs(b.force).max()
    np.testing.assert_allclose(c.stress[0], b.stress[0], rtol=0, atol=1e-12 * smax)
    for copy in (0, 1):
        np.testing.assert_allclose(c.force[0, copy * n:(copy + 1) * n], b.force[0], rtol=0,
                                   atol=1e-12 * fmax)
    for _ in range(3):
        engine.advance(b, 50, dt, p, engine.rate_control(1, l_ctrl=shear, max_rate=100.0))
        engine.advance(c, 50, dt, p, engine.rate_control(1, l_ctrl=shear, max_rate=100.0))
        np.testing.assert_allclose(c.stress[0], b.stress[0], rtol=0, atol=1e-8 * smax)
        assert c.ncontact[0] == 2 * b.ncontact[0]


def test_batch_widths_and_the_edge_to_double():
    """Doubling the edge across the narrowest face pair (the one `_retile` picks) widens
    the narrowest width; the batch widths equal the kernel's per-cell ones."""
    h = np.diag([3.0, 1.0, 2.0])
    h[0, 1] = 0.5  # a sheared cell: widths are not the edge lengths
    w = widths(h[None])[0]
    k = int(np.argmin(w))
    h2 = h.copy()
    h2[:, k] *= 2
    assert widths(h2[None])[0].min() > w.min()
    np.testing.assert_allclose(widths(np.stack([h, h2])),
                               [perpendicular_widths(h), perpendicular_widths(h2)], rtol=1e-12)


def _batch(n_rve: int, seed: int = 0):
    """A batch whose every array holds distinct values (so a misplaced row shows); its
    clump arrays too (2 bodies)."""
    from dataclasses import fields

    from grainscale.dem.state import RVEBatch, allocate

    b = allocate(n_rve, 5, 4, n_bodies=2)
    rng = np.random.default_rng(seed)
    for f in fields(RVEBatch):
        a = getattr(b, f.name)
        a[...] = rng.integers(0, 100, a.shape).astype(a.dtype)
    return b


def test_removing_rves_moves_only_the_tail_and_keeps_every_other_rve():
    """remove_rves: the batch without RVEs 1 and 4 of 8 equals take() of the RVEs it
    reports, array for array, and is a view of the original's rows (no copy); with more
    than half removed it is a compact copy."""
    from dataclasses import fields

    from grainscale.dem.state import RVEBatch, remove_rves

    b = _batch(8)
    ref = b.copy()
    rest, order = remove_rves(b, [4, 1])
    assert sorted(order.tolist()) == [0, 2, 3, 5, 6, 7] and rest.n_rve == 6
    want = ref.take(order)
    for f in fields(RVEBatch):
        np.testing.assert_array_equal(getattr(rest, f.name), getattr(want, f.name))
        assert np.shares_memory(getattr(rest, f.name), getattr(b, f.name))
    b = _batch(8)
    rest, order = remove_rves(b, [0, 1, 2, 3, 4])
    assert order.tolist() == [5, 6, 7] and not np.shares_memory(rest.s, b.s)


def test_extending_a_batch_reuses_its_spare_rows():
    """extend: RVEs appended one call at a time give concatenate()'s batch; the second
    append writes into the storage the first made (the same arrays, nothing copied)."""
    from dataclasses import fields

    from grainscale.dem.state import RVEBatch, concatenate, extend

    base, x1, x2 = _batch(10), _batch(1, 1), _batch(1, 2)
    out, store = extend(base.copy(), [x1])
    assert store.n_rve >= 12  # room for the next
    out2, store2 = extend(out, [x2], store)
    assert store2 is store and np.shares_memory(out2.s, store.s)
    want = concatenate([base, x1, x2])
    for f in fields(RVEBatch):
        np.testing.assert_array_equal(getattr(out2, f.name), getattr(want, f.name))

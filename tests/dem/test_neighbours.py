"""Verlet neighbour lists: completeness against brute force, capacity regrowth, history
carried over rebuilds."""

from __future__ import annotations

import numpy as np
import pytest
from dem_helpers import IMAGES, SMALL_PARAMS, agitated_dense_state, brute_pairs

from grainscale.dem import engine
from grainscale.dem.generate import contact_params
from grainscale.dem.neighbours import shift_code
from grainscale.dem.state import from_packing


def list_entries(b, r=0):
    out = []
    for i in range(b.n_particles):
        for k in range(b.nbr_count[r, i]):
            out.append((i, int(b.nbr_j[r, i, k]), int(b.nbr_shift[r, i, k])))
    return out


@pytest.mark.parametrize("shear", [0.0, 0.3])
def test_list_equals_brute_force_after_build(small_packing, shear):
    """Every pair closer than r_i + r_j + skin (over all 27 images) is listed exactly
    once, with its image, and nothing else; in the generated cube and in a sheared cell."""
    b = small_packing.copy()
    side = b.h[0, 0, 0]
    b.h[0] = b.h[0] + np.array([[0, 0.1, shear], [0, 0, -0.5 * shear], [0, 0, 0]]) * side
    b.need_rebuild[:] = 1
    p = contact_params_for(b)
    engine.refresh(b, p)
    assert b.need_rebuild[0] == 0
    rad = b.radius[0]
    entries = list_entries(b)
    assert len(entries) == len(set(entries))  # no duplicates
    expected = brute_pairs(b.h[0], b.s[0], rad, lambda i, j: rad[i] + rad[j] + p.skin)
    assert set(entries) == expected
    # the packing's radii spread enough for the pair cutoff to matter: the common cutoff
    # 2 r_max + skin would list at least a third more pairs
    common = brute_pairs(b.h[0], b.s[0], rad,
                         lambda i, j: np.full(len(i), 2 * rad.max() + p.skin))
    assert len(common) > 1.33 * len(expected)
    assert np.all((b.s >= 0) & (b.s < 1))  # positions wrapped at the build


def contact_params_for(b):
    return contact_params(SMALL_PARAMS)


# the wide radii take 0.43 x the time step (m_min / r_max): 1400 steps reach the strain
@pytest.mark.parametrize(("radii", "compress"), [((1.0e-3, 1.3e-3), 600),
                                                 ((0.6e-3, 1.5e-3), 1400)])
def test_every_touching_pair_is_listed_at_every_step(radii, compress):
    """Between rebuilds the list must contain every pair in contact (the skin criterion
    accounts for fluctuating motion and for the cell deformation, for each pair's own
    cutoff r_i + r_j + skin; kernel.py). Checked step by step against brute force in an
    agitated, compressed and sheared 48-sphere RVE, with narrow and wide radii (where the
    smallest pairs' cutoffs lie far below the common 2 r_max + skin)."""
    b, p, dt = agitated_dense_state(radii=radii, compress_steps=compress)
    lc = np.array([[-40.0, 15.0, 0.0], [0.0, 30.0, -10.0], [5.0, 0.0, -20.0]])
    ctrl = engine.rate_control(1, l_ctrl=lc, max_rate=100.0)
    builds = 0
    for _ in range(300):
        h_ref = b.h_ref[0].copy()
        engine.advance(b, 1, dt, p, ctrl)
        builds += not np.array_equal(h_ref, b.h_ref[0])  # a build records its cell
        listed = set(list_entries(b))
        touching = brute_pairs(b.h[0], b.s[0] - np.floor(b.s[0]), b.radius[0],
                               lambda i, j: b.radius[0, i] + b.radius[0, j])
        # the list stores shifts relative to the positions at the build (s unwrapped
        # since): translate the brute-force images of the wrapped positions back
        wrap = np.floor(b.s[0]).astype(int)
        fixed = set()
        for i, j, code in touching:
            k = IMAGES[code] - wrap[j] + wrap[i]
            fixed.add((i, j, shift_code(*k)))
        assert fixed <= listed
        assert b.ncontact[0] == len(fixed)  # evaluated where the step ended
    assert builds >= 3  # the run crossed several rebuilds


def _run_pair(b1, b2, p, dt, lc, nsteps):
    for b in (b1, b2):
        engine.advance(b, nsteps, dt, p, engine.rate_control(1, l_ctrl=lc, max_rate=100.0))


def _assert_same_state(a, b):
    for name in ("h", "s", "v", "w", "rot", "stress", "force", "torque", "nbr_count"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for i in range(a.n_particles):
        c = a.nbr_count[0, i]
        assert np.array_equal(a.nbr_j[0, i, :c], b.nbr_j[0, i, :c])
        assert np.array_equal(a.ft[0, i, :c], b.ft[0, i, :c])


def test_capacity_overflow_is_regrown_without_changing_the_run(small_packing):
    """A batch started with capacity 2 (overflow at the first build) and one with the
    exact initial need (overflow later, mid-run, while the packing is compressed) both
    follow a capacity-64 run bitwise: an overflowing build must leave the state untouched
    and the retry must redo the same step."""
    g = small_packing
    centres = g.s[0] @ g.h[0].T
    p = contact_params_for(g)
    dt = engine.critical_dt(g, p)
    rng = np.random.default_rng(0)
    vel = rng.normal(0, 0.05, (g.n_particles, 3))

    def fresh(capacity):
        b = from_packing(g.h[0], centres, g.radius[0], 2650.0, capacity=capacity)
        b.v[0] = vel
        return b

    probe = fresh(64)
    engine.refresh(probe, p)
    need = int(probe.nbr_count.max())
    big, tiny, exact = fresh(64), fresh(2), fresh(need)
    lc = -np.eye(3) * 10.0  # volumetric compression: rows grow as the packing densifies
    for b in (big, tiny, exact):
        engine.advance(b, 2000, dt, p, engine.rate_control(1, l_ctrl=lc, max_rate=100.0))
    assert tiny.capacity > 2 and exact.capacity > need  # both really regrew
    assert big.nbr_count.max() > need
    _assert_same_state(big, tiny)
    _assert_same_state(big, exact)


def test_rebuilds_carry_tangential_history():
    """A run that rebuilds its lists before every step equals one that rebuilds only when
    the skin requires. Rebuilds wrap positions (x changes by a lattice vector: round-off
    of |h| ~ 1e-2 m, ~1e-18 m) and may reorder list rows (force summation order), so the
    runs agree to round-off, amplified over 200 steps: 1e-9 relative is generous
    (measured ~1e-13); a history reset at a rebuild would change tangential forces by
    O(1)."""
    a, p, dt = agitated_dense_state(friction=0.5)
    b = a.copy()
    lc = np.array([[-20.0, 10.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, -10.0]])
    ctrl = engine.rate_control(1, l_ctrl=lc, max_rate=100.0)
    engine.advance(a, 200, dt, p, ctrl)
    hist = 0.0
    for _ in range(200):
        b.need_rebuild[:] = 1
        engine.advance(b, 1, dt, p, ctrl)
        hist = max(hist, np.abs(b.ft).max())
    assert hist > 0
    for name in ("v", "w", "force", "torque", "stress"):
        x, y = getattr(a, name), getattr(b, name)
        assert np.abs(x - y).max() <= 1e-9 * np.abs(x).max(), name
    ds = a.s - b.s
    ds -= np.round(ds)
    assert np.abs(ds).max() < 1e-12

"""Batching and threading never change an RVE's arithmetic (bitwise)."""

from __future__ import annotations

import numba
import numpy as np
from dem_helpers import agitated_dense_state, insert_spheres

from grainscale.dem import engine, kernel
from grainscale.dem.state import concatenate, from_packing

FIELDS = ("h", "s", "v", "w", "rot", "stress", "stiffness", "force", "torque", "L",
          "nbr_count", "ncontact", "unbalanced", "kinetic")


def _three():
    """Three different agitated RVEs (same N, different seeds) with one parameter set."""
    out = [agitated_dense_state(seed=s) for s in (3, 4, 5)]
    return [b for b, _, _ in out], out[0][1], out[0][2]


def _control(n):
    lc = np.array([[-20.0, 5.0, 0.0], [0.0, 10.0, 0.0], [2.0, 0.0, -5.0]])
    return engine.rate_control(n, l_ctrl=lc, max_rate=100.0)


def _assert_equal(a, b, ra=0, rb=0):
    for name in FIELDS:
        assert np.array_equal(getattr(a, name)[ra], getattr(b, name)[rb]), name
    for i in range(a.n_particles):
        c = a.nbr_count[ra, i]
        assert np.array_equal(a.ft[ra, i, :c], b.ft[rb, i, :c])


def test_rve_alone_equals_rve_in_batch():
    """The middle RVE of a batch of three different RVEs ends bitwise where it ends when
    advanced alone (also with a different number of steps per RVE in the batch)."""
    rves, p, dt = _three()
    batch = concatenate(rves)
    alone = rves[1].copy()
    engine.advance(batch, np.array([150, 300, 50]), dt, p, _control(3))
    engine.advance(alone, 300, dt, p, _control(1))
    assert alone.ncontact[0] > 0
    _assert_equal(alone, batch, 0, 1)


def test_one_thread_equals_two_threads():
    """Same batch advanced with 1 and with 2 numba threads: bitwise identical. Two
    threads exist on any machine (tests/conftest.py asks numba for at least two).
    Mutation tried: each lane's RVEs reporting into the lane's row (out[t] for out[r]
    in kernel._advance_split) fails here (and in the batch test above)."""
    assert numba.config.NUMBA_NUM_THREADS >= 2
    rves, p, dt = _three()
    a = concatenate(rves)
    b = a.copy()
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        engine.advance(a, 300, dt, p, _control(3))
        engine.refresh(a, p)
        numba.set_num_threads(2)
        engine.advance(b, 300, dt, p, _control(3))
        engine.refresh(b, p)
    finally:
        numba.set_num_threads(before)
    for r in range(3):
        _assert_equal(a, b, r, r)


def test_rve_with_zero_steps_keeps_its_reported_state():
    """Advancing a batch with nsteps = [0, 100] must leave RVE 0's state, including its
    reported contact count and kinetic energy, untouched."""
    rves, p, dt = _three()
    batch = concatenate(rves[:2])
    before = batch.copy()  # its report: the contacts of its last step's contact pass
    engine.advance(batch, np.array([0, 100]), dt, p, _control(2))
    assert np.array_equal(batch.s[0], before.s[0])  # RVE 0 really did not move
    assert batch.ncontact[0] == before.ncontact[0] > 0
    assert batch.kinetic[0] == before.kinetic[0] > 0


def test_capacity_retry_of_one_rve_keeps_the_others_reports():
    """RVE 0 (dense) overflows its neighbour rows at the first build; RVE 1 (looser) fits
    and completes its steps in the first kernel call. After the retry RVE 1's reported
    contact count, kinetic energy and unbalanced ratio must equal those of RVE 1 run
    alone (its arithmetic is bitwise the same, see above)."""
    h, pos, radii = insert_spheres(40, 1.0e-3, 1.3e-3, 0.70, 7)
    p = engine.ContactParams(young=5e6, stiffness_ratio=0.7, friction=0.4, damping=0.1,
                             skin=0.3e-3)
    dense = from_packing(h * 0.8, pos * 0.8, radii, 2500.0, capacity=64)
    loose = from_packing(h * 0.9, pos * 0.9, radii, 2500.0, capacity=64)
    engine.refresh(dense, p)
    dt = engine.critical_dt(dense, p, 0.2)
    need = 0  # the loose RVE's largest row over the whole run
    for _ in range(50):
        engine.advance(loose, 1, dt, p, engine.rate_control(1))
        need = max(need, int(loose.nbr_count.max()))
    assert dense.nbr_count.max() > need and loose.ncontact[0] > 0
    batch = concatenate([from_packing(h * f, pos * f, radii, 2500.0, capacity=need)
                         for f in (0.8, 0.9)])
    alone = from_packing(h * 0.9, pos * 0.9, radii, 2500.0, capacity=need)
    engine.advance(batch, 50, dt, p, engine.rate_control(2))
    engine.advance(alone, 50, dt, p, engine.rate_control(1))
    assert batch.capacity > need  # the retry happened
    assert np.array_equal(batch.v[1], alone.v[0])
    assert batch.ncontact[1] == alone.ncontact[0] > 0
    assert batch.kinetic[1] == alone.kinetic[0]
    assert batch.unbalanced[1] == alone.unbalanced[0]


def test_run_without_servo_does_not_depend_on_call_chunking():
    """400 steps as one call, as 200 + 200 and as 400 single steps: bitwise equal (how a
    run is cut into `advance` calls -- output rows, MPM steps, checkpoints -- is not
    physics)."""
    b, p, dt = agitated_dense_state()
    ctrl = engine.rate_control(1, l_ctrl=np.diag([-5.0, -10.0, -10.0]), max_rate=50.0)
    a, c, d = b.copy(), b.copy(), b.copy()
    engine.advance(a, 400, dt, p, ctrl)
    engine.advance(c, 200, dt, p, ctrl)
    engine.advance(c, 200, dt, p, ctrl)
    for _ in range(400):
        engine.advance(d, 1, dt, p, ctrl)
    _assert_equal(a, c)
    _assert_equal(a, d)


def test_run_with_servo_does_not_depend_on_call_chunking():
    """Same as above with a stress servo on one axis."""
    b, p, dt = agitated_dense_state()
    ctrl = engine.rate_control(1, l_ctrl=np.diag([0.0, -10.0, -10.0]), servo={0: -2e3},
                               max_rate=50.0)
    a, c = b.copy(), b.copy()
    engine.advance(a, 400, dt, p, ctrl)
    engine.advance(c, 200, dt, p, ctrl)
    engine.advance(c, 200, dt, p, ctrl)
    _assert_equal(a, c)


def test_threads_take_contiguous_ranges_of_equal_cost():
    """kernel.split_by_cost: the ranges tile the batch in order, and every thread's cost
    (nsteps + 1 per RVE) is within one RVE's cost of the total over the threads, however
    the costly RVEs are placed; an RVE too costly to share leaves the others to the
    remaining threads."""
    rng = np.random.default_rng(1)
    cases = [np.full(480, 11), np.array([8] * 4 + [1] * 12), rng.integers(0, 1000, 97),
             np.r_[np.zeros(50, int), np.full(10, 400)], np.array([100, 0, 0, 0])]
    for nsteps in cases:
        nsteps = nsteps.astype(np.int64)
        cost = nsteps + 1
        for nthr in (1, 2, 3, 8):
            b = kernel.split_by_cost(nsteps, nthr)
            assert b[0] == 0 and b[-1] == len(nsteps) and np.all(np.diff(b) >= 0)
            share = np.array([cost[b[t]:b[t + 1]].sum() for t in range(nthr)])
            assert share.sum() == cost.sum()
            # cut t sits at the prefix sum nearest t/nthr of the total: each cut is off by
            # at most half an RVE's cost, so each share by at most one RVE's cost
            assert np.all(np.abs(share - cost.sum() / nthr) <= cost.max()), (nsteps, nthr)
    assert list(kernel.split_by_cost(np.full(480, 11, np.int64), 2)) == [0, 240, 480]

"""A NaN or an infinity in one RVE stops the run with an error naming that RVE.

The kernels are compiled with fastmath, which lets LLVM assume that no value is NaN or
infinite. With numba 0.68 this broke the old in-kernel check in two ways, which these
tests catch (each failed before the check moved to numpy, engine.not_finite):
- `math.isfinite(kinetic energy)` was folded away: a NaN velocity advanced by one step
  (NaN kinetic energy, finite stress) returned with status ok and no error;
- a NaN reaching a division compared equal to zero, so numba's Python error model raised
  ZeroDivisionError inside the parallel loop: a bare SystemError naming no RVE.
"""

from __future__ import annotations

import numpy as np
import pytest
from dem_helpers import agitated_dense_state

from grainscale.dem import engine
from grainscale.dem.state import concatenate


def _batch():
    """Three different agitated 48-sphere RVEs with contacts; (batch, params, dt)."""
    out = [agitated_dense_state(seed=s) for s in (3, 4, 5)]
    return concatenate([b for b, _, _ in out]), out[0][1], out[0][2]


def _grain_in_contact(batch, r):
    """A sphere of RVE r with contacts, so that a NaN on it reaches its neighbours."""
    i = int(np.argmax(batch.nbr_count[r]))
    assert batch.ncontact[r] > 0 and batch.nbr_count[r, i] > 0
    return i


@pytest.mark.parametrize(("field", "value", "nsteps"), [
    ("v", np.nan, 1),     # old: no error at all (the isfinite was folded away)
    ("v", np.nan, 20),    # old: SystemError from a ZeroDivisionError in the kernel
    ("v", np.inf, 20),
    ("s", np.nan, 20),    # a NaN position: a rebuild would index the cell list with it
    ("w", np.nan, 20),
    ("radius", np.nan, 5),
])
def test_a_nan_in_one_rve_stops_advance_naming_it(field, value, nsteps):
    batch, p, dt = _batch()
    engine.advance(batch, 10, dt, p, engine.rate_control(3))
    before = batch.copy()
    i = _grain_in_contact(batch, 1)
    getattr(batch, field)[1, i, ...] = value
    with pytest.raises(engine.RVEError, match="RVE 1: motion became non-finite") as info:
        engine.advance(batch, nsteps, dt, p, engine.rate_control(3))
    assert info.value.rve == 1
    # the other RVEs took their steps and stayed finite
    assert not engine.not_finite(batch)[[0, 2]].any()
    assert np.all(batch.step_count[[0, 2]] == before.step_count[[0, 2]] + nsteps)


def test_a_nan_position_stops_refresh_naming_the_rve():
    batch, p, dt = _batch()
    engine.advance(batch, 10, dt, p, engine.rate_control(3))
    batch.s[2, _grain_in_contact(batch, 2), 0] = np.nan
    with pytest.raises(engine.RVEError, match="RVE 2: motion became non-finite"):
        engine.refresh(batch, p)


def test_the_check_finds_every_kind_of_non_finite_value():
    """not_finite flags exactly the RVEs with a NaN or an infinity in a checked array."""
    batch, _, _ = _batch()
    assert not engine.not_finite(batch).any()
    for field in ("h", "stress", "s", "v", "w"):
        for value in (np.nan, np.inf, -np.inf):
            b = batch.copy()
            getattr(b, field)[1].flat[-1] = value
            assert engine.not_finite(b).tolist() == [False, True, False], (field, value)

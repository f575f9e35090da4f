"""What an RVE hands to the MPM after an increment: the stress of the state it reached,
and moduli that bound its stiffness along the cell axes (kernel.py, item 8; the wave
speed the CFL step reads from them is an estimate over directions,
tests/coupling/test_wave_speed.py).

The stress is checked against the independent plain-numpy reference of
test_reference.py (all pairs by brute force over the 27 images, the contact law written
from kernel.py's docstring) evaluating the returned state, so a stress one DEM step
old, or a list that missed a contact, shows. Before the end-of-increment evaluation the
returned stress was that of the last step's start: off by the response of that step,
~1e-2 of p here, against the 1e-10 below.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from dem_helpers import SMALL_PARAMS, brute_pairs
from test_reference import reference_history, reference_step

from grainscale.dem import engine
from grainscale.dem.generate import contact_params
from grainscale.dem.neighbours import decode_shifts
from grainscale.dem.state import from_packing
from grainscale.io.packing import read_packing

DATA = Path(__file__).resolve().parents[1] / "data" / "triaxial_150"


@pytest.fixture(scope="module")
def packing():
    """The stored 150-sphere packing at 100 kPa, and its contact law with restitution 0.9
    (so that the normal dashpot, which reads the velocities and L, is in the stress)."""
    h, centres, radii = read_packing(DATA / "packing.txt")
    params = SMALL_PARAMS.model_copy(update={"restitution": 0.9, "damping": 0.0})
    b = from_packing(h, centres, radii, params.density)
    cp = contact_params(params)
    engine.refresh(b, cp)
    return b, cp


def reference_stress(b, cp):
    """Stress and contact count of RVE 0's state by test_reference.reference_step with
    dt = 0 (nothing moves, no history added), at the batch's own L (cell control lc = L
    gives L = lc h h^-1 = L)."""
    st = {"h": b.h[0].copy(), "s": b.s[0].copy(), "v": b.v[0].copy(), "w": b.w[0].copy(),
          "rot": b.rot[0].copy(), "radius": b.radius[0], "mass": b.mass[0],
          "inertia": b.inertia[0], "ft": reference_history(b)}
    _, _, stress, contacts = reference_step(st, cp, 0.0, b.L[0])
    return stress, contacts


@pytest.mark.parametrize("nsteps", [1, 2, 11])
def test_returned_stress_is_that_of_the_returned_state(packing, nsteps):
    b0, cp = packing
    b = b0.copy()
    dt = engine.critical_dt(b, cp)
    dH = np.zeros((1, 3, 3))
    dH[0, 2, 2] = -2e-4  # compression along z, sheared a little
    dH[0, 0, 1] = 5e-5
    engine.advance(b, nsteps, dt, cp, engine.increment_control(b, dH, nsteps, dt))
    expected, contacts = reference_stress(b, cp)
    p = -np.trace(expected) / 3
    assert p > 5e4
    # round-off of ~1e3 contact terms of ~p each, with fastmath's reassociation
    assert np.abs(b.stress[0] - expected).max() < 1e-10 * p
    assert b.ncontact[0] == contacts
    # the increment's response is far above that bound: a stress of the state one step
    # earlier would fail it (the step before the last moved sigma_zz by > 1e-3 p)
    start = b0.copy()
    engine.advance(start, nsteps - 1, dt, cp, engine.increment_control(start, dH, nsteps, dt))
    assert abs(start.stress[0, 2, 2] - b.stress[0, 2, 2]) > 1e-3 * p
    # refreshing the returned state changes nothing: the evaluation is read-only
    again = b.copy()
    engine.refresh(again, cp)
    assert np.array_equal(again.stress, b.stress)
    assert np.array_equal(again.ft, b.ft)


def test_one_step_modulus_is_bounded_by_the_one_the_time_step_uses():
    """The largest axial modulus an RVE can show the MPM is that of an increment taken in
    one DEM step, before any grain moves relative to the affine field: the affine modulus
    of the whole contact law, kn and kt, along that axis, which `stiffness` holds and the
    CFL step reads (RVEMaterial.wave_speed; other directions: test_wave_speed.py).
    Measured per axis as the difference between a strained and an unstrained copy (the
    packing's own out-of-balance motion cancels)."""
    h, centres, radii = read_packing(DATA / "packing.txt")
    params = SMALL_PARAMS.model_copy(update={"damping": 0.0})  # elastic contacts
    cp = contact_params(params)
    b0 = from_packing(h, centres, radii, params.density)
    engine.refresh(b0, cp)
    dt = engine.critical_dt(b0, cp)
    eps = 1e-6
    # the normal springs' (1/V) sum kn |d|^2 n_k^4
    r = b0.radius[0]
    pairs = np.array(sorted(brute_pairs(b0.h[0], b0.s[0], r, lambda i, j: r[i] + r[j])))
    i, j = pairs[:, 0], pairs[:, 1]
    d = (b0.s[0][j] - b0.s[0][i] + decode_shifts(pairs[:, 2])) @ b0.h[0].T
    dist = np.linalg.norm(d, axis=1)
    kn = cp.young * 2 * r[i] * r[j] / (r[i] + r[j])
    kn_only = (kn[:, None] * d**4 / dist[:, None] ** 2).sum(axis=0) / b0.volume()[0]
    for k in range(3):
        dH = np.zeros((2, 3, 3))
        dH[1, k, k] = -eps  # RVE 1 compressed, RVE 0 the control
        both = b0.take([0, 0])
        engine.advance(both, 1, dt, cp, engine.increment_control(both, dH, 1, dt))
        measured = (both.stress[0, k, k] - both.stress[1, k, k]) / eps
        bound = b0.stiffness[0, k, k]
        # the bound holds with a margin of round-off only where the grains do not move
        # relative to the affine field within the step; they do by O((w dt)^2)
        assert measured <= bound, (k, measured, bound)
        assert measured > 0.95 * bound, (k, measured, bound)  # and it is tight
        # the normal springs alone, what the step read before, fall short of it
        assert measured > 1.2 * kn_only[k], (k, measured, kn_only[k])

"""What an RVE hands to the MPM after an increment: the stress of the state it reached,
and moduli that bound its stiffness (kernel.py, item 8).

The stress is checked against an independent plain-numpy evaluation of the returned
state (all pairs by brute force over the 27 images, the contact law written from
kernel.py's docstring), so a stress one DEM step old, or a list that missed a contact,
shows. Before the end-of-increment evaluation the returned stress was that of the last
step's start: off by the response of that step, ~1e-2 of p here, against the 1e-10 below.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from dem_helpers import SMALL_PARAMS

from grainscale.dem import engine
from grainscale.dem.generate import contact_params
from grainscale.dem.neighbours import decode_shifts
from grainscale.dem.state import from_packing
from grainscale.io.packing import read_packing

DATA = Path(__file__).resolve().parents[1] / "data" / "triaxial_150"
IMAGES = np.array(list(itertools.product((-1, 0, 1), repeat=3)), float)


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


def touching_pairs(b):
    """(i, j, d) of every touching pair by brute force: d = x_j - x_i over the nearest of
    the 27 images (cells here are wider than 4 r_max: at most one image touches)."""
    h, s, r = b.h[0], b.s[0], b.radius[0]
    iu, ju = np.triu_indices(len(r), 1)
    dc = ((s[ju] - s[iu])[:, None, :] + IMAGES[None]) @ h.T
    dist = np.linalg.norm(dc, axis=2)
    p, k = np.nonzero(dist < (r[iu] + r[ju])[:, None])
    return iu[p], ju[p], dc[p, k]


def numpy_stress(b, cp):
    """Love-Weber stress minus the kinetic stress of RVE 0's state [Pa], tension positive:
    f_n = kn (r_i + r_j - |d|) - 2 gamma sqrt(m* kn) v_n, the stored tangential force
    projected onto the contact plane and capped at mu max(f_n, 0), relative velocity from
    v, w and D = sym L with lever arms to the middle of the overlap."""
    h, s, v, w = b.h[0], b.s[0], b.v[0], b.w[0]
    r, m, L = b.radius[0], b.mass[0], b.L[0]
    D = 0.5 * (L + L.T)
    # the history of each listed pair, keyed by the pair and its image shift in Cartesian
    # form (the list's own shift codes are only used to find the entry)
    hist = {}
    for i in range(b.n_particles):
        for k in range(b.nbr_count[0, i]):
            j = int(b.nbr_j[0, i, k])
            shift = decode_shifts(np.array([b.nbr_shift[0, i, k]]))[0]
            d = h @ (s[j] - s[i] + shift)
            hist[(i, j, tuple(np.round(d, 9)))] = b.ft[0, i, k]
    i_all, j_all, d_all = touching_pairs(b)
    sigma = np.zeros((3, 3))
    for i, j, d in zip(i_all, j_all, d_all, strict=True):
        key = (int(i), int(j), tuple(np.round(d, 9)))
        if key not in hist:  # listed the other way round
            key = (int(j), int(i), tuple(np.round(-d, 9)))
            i, j, d = j, i, -d
        ft = hist[key]
        dist = np.linalg.norm(d)
        n = d / dist
        rr = r[i] + r[j]
        kn = cp.young * 2 * r[i] * r[j] / rr
        li, lj = r[i] - 0.5 * (rr - dist), r[j] - 0.5 * (rr - dist)
        vr = v[j] - v[i] + D @ d - np.cross(li * w[i] + lj * w[j], n)
        mst = m[i] * m[j] / (m[i] + m[j])
        fn = kn * (rr - dist) - 2 * cp.gamma * np.sqrt(mst * kn) * (vr @ n)
        g = ft - (ft @ n) * n
        cap = cp.friction * max(fn, 0.0)
        if g @ g > cap * cap:
            g *= cap / np.linalg.norm(g)
        sigma += np.outer(d, g - fn * n)
    sigma -= np.einsum("i,ia,ib->ab", m, v, v)
    return sigma / np.linalg.det(h), len(i_all)


@pytest.mark.parametrize("nsteps", [1, 2, 11])
def test_returned_stress_is_that_of_the_returned_state(packing, nsteps):
    b0, cp = packing
    b = b0.copy()
    dt = engine.critical_dt(b, cp)
    dH = np.zeros((1, 3, 3))
    dH[0, 2, 2] = -2e-4  # compression along z, sheared a little
    dH[0, 0, 1] = 5e-5
    engine.advance(b, nsteps, dt, cp, engine.increment_control(b, dH, nsteps, dt))
    expected, contacts = numpy_stress(b, cp)
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
    """The largest modulus an RVE can show the MPM is that of an increment taken in one DEM
    step, before any grain moves relative to the affine field: the affine modulus of the
    whole contact law, kn and kt, which `stiffness` holds and the CFL step reads
    (RVEMaterial.wave_speed). Measured per axis as the difference between a strained and
    an unstrained copy (the packing's own out-of-balance motion cancels)."""
    h, centres, radii = read_packing(DATA / "packing.txt")
    params = SMALL_PARAMS.model_copy(update={"damping": 0.0})  # elastic contacts
    cp = contact_params(params)
    b0 = from_packing(h, centres, radii, params.density)
    engine.refresh(b0, cp)
    dt = engine.critical_dt(b0, cp)
    eps = 1e-6
    # the normal springs' (1/V) sum kn |d|^2 n_k^4
    i, j, d = touching_pairs(b0)
    r = b0.radius[0]
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

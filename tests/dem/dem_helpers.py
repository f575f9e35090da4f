"""Shared helpers of the DEM physics tests (imported by the test modules)."""

from __future__ import annotations

import itertools

import numpy as np

from grainscale.config.rve import RVEParams
from grainscale.dem import engine
from grainscale.dem.neighbours import shift_code
from grainscale.dem.state import RVEBatch, from_packing

IMAGES = np.array(list(itertools.product((-1, 0, 1), repeat=3)))  # the 27 image shifts

# parameters of the small generated packing shared by several tests (unit-element
# parameters of the seed, fewer particles)
SMALL_PARAMS = RVEParams(particles=150, preparation={"pressure": 100e3, "porosity": 0.373})


def brute_pairs(h, s, radius, cutoff_of_pair):
    """{(i, j, shift code)} of all i < j with |h (s_j - s_i + k)| < cutoff_of_pair(i, j),
    k over the 27 images (s in [0,1) so these are all candidates within half a cell)."""
    n = len(radius)
    iu, ju = np.triu_indices(n, 1)
    ds = (s[ju] - s[iu])[:, None, :] + IMAGES[None]
    dist = np.linalg.norm(ds @ h.T, axis=2)
    cut = cutoff_of_pair(iu, ju)
    p, k = np.nonzero(dist < cut[:, None])
    return {(int(iu[a]), int(ju[a]), shift_code(*IMAGES[c])) for a, c in zip(p, k, strict=True)}


def cartesian(batch: RVEBatch, r: int = 0) -> np.ndarray:
    """x = h s of RVE r (unwrapped)."""
    return batch.s[r] @ batch.h[r].T


def insert_spheres(n: int, rmin: float, rmax: float, porosity: float, seed: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random non-overlapping spheres in a cube (independent of generate.insert_random,
    which refuses cells below 8 r_max)."""
    rng = np.random.default_rng(seed)
    radii = rng.uniform(rmin, rmax, n)
    side = ((4.0 / 3.0) * np.pi * np.sum(radii**3) / (1.0 - porosity)) ** (1.0 / 3.0)
    pos = np.zeros((n, 3))
    for i in range(n):
        for _ in range(100_000):
            p = rng.uniform(0.0, side, 3)
            d = pos[:i] - p
            d -= side * np.round(d / side)
            if i == 0 or np.min(np.linalg.norm(d, axis=1) - radii[:i] - radii[i]) > 0:
                pos[i] = p
                break
        else:
            raise RuntimeError("insertion failed")
    return np.eye(3) * side, pos, radii


def agitated_dense_state(n: int = 48, seed: int = 3, damping: float = 0.0,
                         friction: float = 0.4, radii: tuple[float, float] = (1.0e-3, 1.3e-3),
                         compress_steps: int = 600) -> tuple[RVEBatch, engine.ContactParams, float]:
    """A small dense-ish RVE with contacts, tangential history and random velocities.

    Spheres (r uniform in `radii`, 1.0-1.3 mm by default, density 2500) inserted at
    porosity 0.70, then compressed by a prescribed volumetric rate with some shear so that
    many contacts form with history (over `compress_steps` steps of the critical step
    scaled by 0.1). Returns (batch, params, dt).
    """
    h, pos, radii = insert_spheres(n, radii[0], radii[1], 0.70, seed)
    b = from_packing(h, pos, radii, 2500.0)
    p = engine.ContactParams(young=5e6, stiffness_ratio=0.7, friction=friction,
                             damping=damping, skin=0.3e-3)
    dt = engine.critical_dt(b, p, 0.1)
    rng = np.random.default_rng(seed + 100)
    b.v[0] = rng.normal(0.0, 0.02, (n, 3))
    b.w[0] = rng.normal(0.0, 20.0, (n, 3))
    lc = np.array([[-80.0, 3.0, 0.0], [0.0, -80.0, 2.0], [1.0, 0.0, -80.0]])
    engine.advance(b, compress_steps, dt, p, engine.rate_control(1, l_ctrl=lc, max_rate=100.0))
    assert b.ncontact[0] > n // 2, "helper should produce a contact network"
    return b, p, dt


def contact_interval(gaps) -> tuple[float, float, int, int]:
    """(entry, exit, first, last) of a contact from a pair's gap [m] sampled once a step:
    the step indices of the first and last negative gap, and the crossings of zero
    located between steps by linear interpolation (error O(dt^2)), in steps."""
    g = np.asarray(gaps, float)
    inside = np.nonzero(g < 0)[0]
    k0, k1 = int(inside[0]), int(inside[-1])
    t_in = (k0 - 1) + g[k0 - 1] / (g[k0 - 1] - g[k0])
    t_out = k1 + g[k1] / (g[k1] - g[k1 + 1])
    return t_in, t_out, k0, k1

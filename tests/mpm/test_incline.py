"""A mu(I) layer on an incline, periodic along the slope (Jop, Forterre & Pouliquen
2006; GDR MiDi 2004): it flows only above atan(mu_s), and then reaches the Bagnold
profile u(z) = (2/3) (I/d) sqrt(phi g cos a) (H^1.5 - (H - z)^1.5), with the inertial
number fixed by mu(I) = tan a everywhere, I = I_0 (tan a - mu_s)/(mu_2 - tan a)."""

import numpy as np
import pytest

from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.materials import KINDS
from grainscale.mpm.points import fill_box, make_points
from grainscale.mpm.step import MPMState, step

RHO_S, PHI = 2450.0, 0.6  # glass beads of Jop et al. at a solid fraction of 0.6
MU_S, MU_2, I0, D = 0.3819, 0.6434, 0.279, 0.53e-3
G = 9.81


def _layer(angle_deg, H, nz):
    """Layer of height H (nz cells over it), 2 cells along the periodic x, between
    frictionless y walls on a no-slip bed, isotropic lithostatic stress to start."""
    h = H / nz
    a = np.radians(angle_deg)
    rho = PHI * RHO_S
    grid = Grid.make([0, 0, 0], h, [2, 2, nz + 2], periodic=(True, False, False))
    x, vol = fill_box(grid, [0, 0, 0], [2 * h, 2 * h, H], 2)
    keep = x[:, 0] < 2 * h  # the period is [0, 2h)
    pts = make_points(x[keep], vol[keep], rho, 0)
    mat = KINDS["mu_i"]("beads", pts.n, density=rho, youngs_modulus=1e5, poisson_ratio=0.3,
                        mu_s=MU_S, mu_2=MU_2, I_0=I0, grain_diameter=D, grain_density=RHO_S)
    s = MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None],
                 gravity=np.array([G * np.sin(a), 0.0, -G * np.cos(a)]))
    s.constraints = [boundary.constraint(boundary.face_nodes(grid, f), "roller", 1)
                     for f in ("y-", "y+")]
    s.constraints.append(boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None))
    p = rho * G * np.cos(a) * (H - pts.x[:, 2])
    for k in range(3):
        pts.stress[:, k, k] = -p
    return s


def _bagnold(angle_deg, H, z):
    t = np.tan(np.radians(angle_deg))
    inertial = I0 * (t - MU_S) / (MU_2 - t)
    return (2 / 3) * inertial / D * np.sqrt(PHI * G * np.cos(np.radians(angle_deg))) * (
        H**1.5 - (H - z) ** 1.5)


@pytest.mark.validation
def test_layer_reaches_the_bagnold_profile():
    """25 deg (tan = 0.466 between mu_s = 0.382 and mu_2 = 0.643: I = 0.133), H = 10 mm
    = 19 d, from rest to 2 s: the surface velocity approaches 0.38 m/s exponentially;
    measured 0.376 against 0.385 m/s at 2 s with 10 cells (2.2 % short, still rising by
    ~0.1 % per 0.1 s). 5 % is the issue's tolerance; the shape of the profile is checked at
    mid-depth too (it is set by the pressure-dependence of I, not by the cell count)."""
    H, nz = 0.01, 10
    s = _layer(25.0, H, nz)
    while s.time < 2.0:
        step(s, s.stable_dt())
    pts = s.points
    h = H / nz
    top = pts.x[:, 2] > H - h / 2
    u_top = pts.v[top, 0].mean()
    assert u_top == pytest.approx(_bagnold(25.0, H, pts.x[top, 2].mean()), rel=0.05)
    mid = np.abs(pts.x[:, 2] - pts.x[:, 2][np.argmin(np.abs(pts.x[:, 2] - H / 2))]) < 1e-9
    ratio = pts.v[mid, 0].mean() / u_top
    expected = _bagnold(25.0, H, pts.x[mid, 2].mean()) / _bagnold(25.0, H, pts.x[top, 2].mean())
    assert ratio == pytest.approx(expected, rel=0.03)


@pytest.mark.validation  # 5 s
def test_layer_below_the_angle_of_repose_stays():
    """20 deg < atan(mu_s) = 20.9 deg: the layer does not flow (after the release of its
    isotropic start stress it rings elastically at ~1 mm/s, against 0.25 m/s after
    0.3 s of a frictionless slide)."""
    s = _layer(20.0, 0.01, 10)
    while s.time < 0.3:
        step(s, s.stable_dt())
    assert np.abs(s.points.v[:, 0]).max() < 0.01 * G * np.sin(np.radians(20.0)) * 0.3

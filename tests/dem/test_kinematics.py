"""Kinematics and invariance: affine motion, objectivity, momentum conservation."""

from __future__ import annotations

import numpy as np
import pytest
from dem_helpers import agitated_dense_state, cartesian, insert_spheres

from grainscale.dem import engine
from grainscale.dem.state import from_packing

EPS = np.finfo(float).eps


def test_affine_deformation_without_contacts():
    """Sparse spheres at rest under dH with stretch, shear and rotation: the cell ends at
    (I + dH) h0, every sphere on the mean field, x = (I + dH) x0, no fluctuating motion
    and zero stress.

    With no contact, forces are exactly zero, so v, w and s must stay bitwise unchanged
    (any spurious mean-field term in the fluctuating velocity shows up at O(|dH| |x|)).
    h is the product of 200 equal step maps: round-off ~200 eps |h| relative; 1e-12 allowed.
    """
    h0, pos, radii = insert_spheres(30, 1.0e-3, 1.2e-3, 0.97, seed=5)
    b = from_packing(h0, pos, radii, 2500.0)
    x0 = cartesian(b).copy()
    s0 = b.s.copy()
    p = engine.ContactParams(young=1e7, stiffness_ratio=0.8, friction=0.5, damping=0.2,
                             skin=0.2e-3)
    dt = engine.critical_dt(b, p)
    dH = np.array([[0.10, 0.25, -0.05], [-0.15, -0.08, 0.10], [0.05, 0.02, 0.12]])
    engine.refresh(b, p)
    assert b.ncontact[0] == 0
    engine.advance(b, 200, dt, p, engine.increment_control(b, dH, 200, dt))
    expected_h = (np.eye(3) + dH) @ h0
    np.testing.assert_allclose(b.h[0], expected_h, rtol=0, atol=1e-12 * np.abs(h0).max())
    assert np.array_equal(b.s, s0)  # fractional positions untouched (already in [0,1))
    np.testing.assert_allclose(cartesian(b), x0 @ (np.eye(3) + dH).T, rtol=0,
                               atol=1e-12 * np.abs(h0).max())
    assert not b.v.any() and not b.w.any() and not b.stress.any()
    # the increment follows a constant velocity gradient (engine.increment_control):
    # exp(T L) = I + dH with T = 200 dt (matrix exponential by its Taylor series here,
    # |T L| ~ 0.4 so 40 terms reach round-off); 1e-10 allows for the engine's own series
    TL = 200 * dt * b.L[0]
    expm, term = np.eye(3), np.eye(3)
    for k in range(1, 40):
        term = term @ TL / k
        expm = expm + term
    np.testing.assert_allclose(expm, np.eye(3) + dH, rtol=0, atol=1e-10)


def test_a_free_grain_moves_in_a_straight_line_in_a_sheared_cell():
    """A grain that touches nothing keeps its lab-frame velocity while the cell shears
    (Newton's first law): its fluctuating velocity v' = u - L x must change as
    dv'/dt = -L v' (the pseudo-force of the co-moving frame, SLLOD). In simple shear
    L = gdot e_x e_z^T, L^2 = 0, so the leapfrog keeps u exactly: x(T) = x(0) + T u with
    u = v'(0) + L x(0) - dt L v'(0) (the half-step offset of the stored velocity).
    Round-off only (1e-12 m allowed over 20,000 steps of a 1 m cell); without the
    pseudo-force the grain drifts from the line by gdot v'_z T^2 / 2 = 2 mm."""
    h = np.eye(3)
    b = from_packing(h, np.array([[0.5, 0.5, 0.3]]), np.array([1e-3]), 2500.0)
    v0 = np.array([0.01, -0.003, 0.02])
    b.v[0, 0] = v0
    p = engine.ContactParams(young=1e7, stiffness_ratio=0.8, friction=0.5, damping=0.0,
                             skin=0.2e-3)
    gdot, dt, n = 5.0, 1e-5, 20_000
    L = np.zeros((3, 3))
    L[0, 2] = gdot
    x0 = cartesian(b)[0].copy()
    engine.refresh(b, p)
    engine.advance(b, n, dt, p, engine.rate_control(1, l_ctrl=L, max_rate=100.0))
    u = v0 + L @ x0 - dt * L @ v0
    np.testing.assert_allclose(cartesian(b)[0], x0 + n * dt * u, rtol=0, atol=1e-12)


def _rotation(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _rotated(b, R):
    c = b.copy()
    for name in ("h", "h_ref", "h0"):
        getattr(c, name)[:] = R @ getattr(b, name)
    c.v[:] = b.v @ R.T
    c.w[:] = b.w @ R.T
    c.ft[:] = b.ft @ R.T
    c.L[:] = R @ b.L @ R.T
    return c


def test_objectivity_of_a_loaded_packing():
    """Rotating a loaded packing (h -> R h; v, w, ft, L rotated; s unchanged) rotates the
    stress, forces and the whole subsequent motion: sigma -> R sigma R^T.

    Damping is off: Cundall's local damping acts per Cartesian component of v and is
    frame dependent by construction (not a bug, a property of the method).
    Tolerances: after refresh, both runs do the same arithmetic on rotated inputs, so
    they differ by a few ulp per operation (1e-12 relative to the largest entry). Over
    150 steps of a dense, agitated packing round-off grows (chaotic divergence); the
    measured difference stays below 1e-11, so 1e-8 leaves margin while any
    frame-dependent term (e.g. a history not turned with the contact) gives O(1e-3).
    """
    b, p, dt = agitated_dense_state()
    R = _rotation([0.3, -0.5, 0.8], 0.7)
    c = _rotated(b, R)
    engine.refresh(b, p)
    engine.refresh(c, p)
    smax = np.abs(b.stress).max()
    assert smax > 0
    np.testing.assert_allclose(c.stress[0], R @ b.stress[0] @ R.T, rtol=0, atol=1e-12 * smax)
    fmax = np.abs(b.force).max()
    np.testing.assert_allclose(c.force[0], b.force[0] @ R.T, rtol=0, atol=1e-12 * fmax)
    lc = np.array([[-5.0, 2.0, 0.0], [0.0, 3.0, 1.0], [-1.0, 0.0, 2.0]])
    vmax, wmax = np.abs(b.v).max(), np.abs(b.w).max()
    for _ in range(3):
        engine.advance(b, 50, dt, p, engine.rate_control(1, l_ctrl=lc, max_rate=100.0))
        engine.advance(c, 50, dt, p, engine.rate_control(1, l_ctrl=R @ lc @ R.T,
                                                         max_rate=100.0))
        np.testing.assert_allclose(c.h[0], R @ b.h[0], rtol=0, atol=1e-13 * np.abs(b.h).max())
        np.testing.assert_allclose(c.stress[0], R @ b.stress[0] @ R.T, rtol=0,
                                   atol=1e-8 * smax)
        np.testing.assert_allclose(c.v[0], b.v[0] @ R.T, rtol=0, atol=1e-8 * vmax)
        np.testing.assert_allclose(c.w[0], b.w[0] @ R.T, rtol=0, atol=1e-8 * wmax)
        # the same position up to a period: the list-rebuild test (which wraps s into
        # [0, 1)) uses norms of h that are not rotation invariant, so one copy may wrap
        # a grain a few steps before the other
        ds = c.s - b.s
        np.testing.assert_allclose(ds - np.round(ds), 0.0, rtol=0, atol=1e-10)
        assert c.ncontact[0] == b.ncontact[0]


@pytest.mark.parametrize("deforming", [False, True], ids=["fixed_cell", "deforming_cell"])
def test_fluctuating_momentum_conserved_without_damping(deforming):
    """Pairwise contact forces (each contact adds F to i and -F to j) conserve the total
    fluctuating momentum sum m v when damping is off. In a deforming cell the
    pseudo-force -m L v' is linear in v', so a zero total stays zero.

    Bound: per step round-off is a few ulp of the summed forces and momenta, so |dP| is
    compared with 1e-12 x (sum m|v| + total impulse sum dt |F_i|) (impulse sampled every
    10th step, times 10) -- ~1e4 ulp of
    accumulation headroom, while a single missing reaction force per step would be
    O(1) of the impulse.
    """
    b, p, dt = agitated_dense_state(damping=0.0)
    if deforming:
        # the claim that holds for any formulation of the fluctuating motion in a
        # deforming cell (with or without an apparent -L v term): zero total
        # fluctuating momentum stays zero. Remove the mean fluctuating velocity first.
        b.v[0] -= np.einsum("n,nd->d", b.mass[0], b.v[0]) / b.mass[0].sum()
    P0 = np.einsum("n,nd->d", b.mass[0], b.v[0])
    scale = np.einsum("n,nd->", b.mass[0], np.abs(b.v[0]))
    lc = np.array([[-10.0, 2.0, 0.0], [0.0, -10.0, 1.0], [1.0, 0.0, -10.0]]) if deforming \
        else np.zeros((3, 3))
    ctrl = engine.rate_control(1, l_ctrl=lc, max_rate=100.0)
    impulse = 0.0
    for _ in range(40):
        engine.advance(b, 10, dt, p, ctrl)
        impulse += 10 * dt * np.abs(b.force[0]).sum()  # forces of the last step
    assert b.ncontact[0] > 5
    P = np.einsum("n,nd->d", b.mass[0], b.v[0])
    assert np.abs(P - P0).max() <= 1e-12 * (scale + impulse)
    # the test has teeth: the impulse exchanged is many orders above the bound
    assert impulse > 1e-3 * scale


def test_damping_dissipates_and_is_bounded():
    """Local non-viscous damping only removes energy: with alpha > 0 and the cell fixed,
    a frictionless packing's kinetic energy plus normal-spring energy never rises (leapfrog
    energy fluctuates by O(dt) of it; checked over chunks with a 2 % allowance)."""
    b, p, dt = agitated_dense_state(damping=0.3, friction=0.0)

    def energy(batch):
        engine.refresh(batch, p)
        e_kin = 0.5 * np.sum(batch.mass[0] * np.sum(batch.v[0] ** 2, axis=1)) \
            + 0.5 * np.sum(batch.inertia[0] * np.sum(batch.w[0] ** 2, axis=1))
        from grainscale.io.rve_vtk import contact_list
        i, j, d, fn, _ = contact_list(batch, p)
        r = batch.radius[0]
        kn = p.young * 2 * r[i] * r[j] / (r[i] + r[j])
        return e_kin + 0.5 * np.sum(fn**2 / kn)

    ctrl = engine.rate_control(1)
    e = [energy(b)]
    for _ in range(10):
        engine.advance(b, 100, dt, p, ctrl)
        e.append(energy(b))
    e = np.array(e)
    assert np.all(np.diff(e) <= 0.02 * e[0])
    assert e[-1] < 0.5 * e[0]  # and it does dissipate


def test_energy_conserved_without_damping_and_friction():
    """Frictionless, undamped, fixed cell: kinetic plus normal-spring energy is a
    conserved quantity of the dynamics. Leapfrog conserves a shadow energy: with
    velocities synchronised to the positions (v_n = v_(n-1/2) + dt/2 F_n/m) the energy
    error is bounded, O((omega dt)^2) ~ 1e-3 here at dt = 0.1 sqrt(m/k); we allow 1 % with
    no secular drift over 3000 steps, while e.g. a force off by a factor or an
    integration order error (positions updated with the old velocity) drifts by tens of %.
    """
    from grainscale.io.rve_vtk import contact_list

    b, p, dt = agitated_dense_state(damping=0.0, friction=0.0)

    def energy(batch):
        c = batch.copy()
        engine.refresh(c, p)  # forces F_n at the current positions
        v = c.v[0] + 0.5 * dt * c.force[0] / c.mass[0][:, None]
        e_kin = 0.5 * np.sum(c.mass[0] * np.sum(v**2, axis=1)) \
            + 0.5 * np.sum(c.inertia[0] * np.sum(c.w[0] ** 2, axis=1))
        i, j, d, fn, _ = contact_list(c, p)
        r = c.radius[0]
        kn = p.young * 2 * r[i] * r[j] / (r[i] + r[j])
        return e_kin + 0.5 * np.sum(fn**2 / kn), 0.5 * np.sum(fn**2 / kn)

    ctrl = engine.rate_control(1)
    e0, _ = energy(b)
    elastic = 0.0
    for _ in range(30):
        engine.advance(b, 100, dt, p, ctrl)
        e, spring = energy(b)
        elastic = max(elastic, spring)
        assert abs(e / e0 - 1.0) < 0.01
    assert elastic > 0.01 * e0  # energy really was exchanged with the springs

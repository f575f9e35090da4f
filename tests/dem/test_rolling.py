"""Rolling resistance (kernel.contact_pass): the contact moment against its definition,
a spinning sphere stopped by it, angular momentum, and the keys that switch it on.

The law (YADE's Law2_ScGeom6D_CohFrictPhys_CohesionMoment, incremental form, no
cohesion, no twisting moment): each step M <- turn(M) - k_r (w_j - w_i)_bend dt with
k_r = alpha_r kt r_i r_j, capped at |M| <= eta_r min(r_i, r_j) f_n; torque M on j, -M
on i.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from grainscale.config.base import ConfigError
from grainscale.config.rve import RVEParams
from grainscale.dem import engine, kernel
from grainscale.dem.generate import contact_params
from grainscale.dem.state import HISTORY, HISTORY_ROLLING, from_packing, with_history

COMPILE_AHEAD = ("rolling",)  # tests/warm_kernels.py compiles its kernel variant early

DENSITY = 2500.0
YOUNG = 1e7
RATIO = 0.5  # kt / kn


def law(alpha=1.0, eta=0.2, friction=0.0):
    return engine.ContactParams(young=YOUNG, stiffness_ratio=RATIO, friction=friction,
                                damping=0.0, skin=0.1e-3, rolling_stiffness=alpha,
                                rolling_friction=eta)


def pair(direction, r1=1.0e-3, r2=1.6e-3, overlap=2e-6):
    """Two spheres touching along `direction` with the given overlap, at rest, their
    list built and a 6-component history; returns (batch, unit normal)."""
    n = np.asarray(direction, float)
    n /= np.linalg.norm(n)
    x1 = np.full(3, 10e-3)
    x2 = x1 + (r1 + r2 - overlap) * n
    b = from_packing(np.eye(3) * 20e-3, np.array([x1, x2]), np.array([r1, r2]), DENSITY,
                     capacity=4, history=HISTORY_ROLLING)
    engine.refresh(b, law())
    return b, n


@njit
def _committed_pass(dt, law, st, table, stress, stiff):
    # the history width as the constant contact_pass takes (called from Python, each
    # call would re-dispatch on the literal)
    return kernel.contact_pass(dt, law, st, None, 6, 0, table, stress, stiff, False, True)


def contact_step(b, p, dt):
    """One committed evaluation of the contact law at the batch's configuration and
    spins (nothing integrated): the moment history advances by one step of dt."""
    st = kernel.rve_state(engine.rve_arrays(b), 0)
    _committed_pass(dt, engine.contact_law(p), st, np.empty((27, 3)), np.empty((3, 3)),
                    np.empty((3, 3)))
    return b.ft[0, 0, 0, 3:].copy(), b.torque[0].copy(), b.force[0].copy()


def test_moment_grows_at_kr_saturates_at_the_cap_and_unloads_elastically():
    """Prescribed relative rotation rate, friction 0 (no tangential force): the moment
    must follow M_k = -k_r w_bend k dt until |M| reaches eta_r min(r) f_n, stay there,
    and on reversal come back at the same slope; the work done on the contact,
    W = -sum (M_k + M_k+1)/2 . w_rel dt (trapezoidal: exact for a linear spring), is
    stored as |M|^2 / (2 k_r) while below the cap (dissipation zero to round-off) and
    dissipated at exactly cap |w_bend| dt a step on the cap.

    The contact is oblique and the relative spin has a component along the normal
    (twist, with the mean spin about n zero, so the frame does not turn): only the
    part in the contact plane may load the moment. Unequal radii: min(r) and r_i r_j
    both matter. Mutations that fail here: k_r from kn instead of kt (slope 2x),
    max(r) in the cap (1.6x), no projection on the plane (M gains a normal part and
    a larger slope), the moment not capped, the torque on i not opposite to j's."""
    b, n = pair([1.0, 0.7, -0.4])
    r1, r2 = b.radius[0]
    p = law(alpha=1.3, eta=0.25)
    kn = YOUNG * 2 * r1 * r2 / (r1 + r2)
    kr = 1.3 * RATIO * kn * r1 * r2
    fn = kn * 2e-6
    cap = 0.25 * min(r1, r2) * fn
    dt = 1e-6
    bend = np.cross(n, [0.0, 0.0, 1.0])
    bend /= np.linalg.norm(bend)  # a direction in the contact plane
    w_rel = 3.0 * bend + 2.0 * n  # rad/s, with a twist part along n
    b.w[0, 0] = -0.5 * w_rel
    b.w[0, 1] = 0.5 * w_rel  # mean spin 0: the frame does not turn
    f_free = contact_step(b.copy(), law(alpha=0.0, eta=0.0), dt)[2]  # without rolling
    b.ft[0, 0, 0, 3:] = 0.0
    steps_to_cap = cap / (kr * 3.0 * dt)
    assert 50 < steps_to_cap < 500  # the ramp is resolved (premise of the checks)
    m_prev = np.zeros(3)
    work = 0.0
    history = []
    for k in range(2 * int(steps_to_cap) + 200):
        if k == int(1.5 * steps_to_cap):
            b.w[0] *= -1.0  # reverse: unload
        m, torque, force = contact_step(b, p, dt)
        wr = b.w[0, 1] - b.w[0, 0]
        work -= 0.5 * np.dot(m_prev + m, wr) * dt
        stored = np.dot(m, m) / (2 * kr)
        history.append((k, np.linalg.norm(m), work - stored))
        m_prev = m
        # no normal part; torques +M on j and -M on i; no force from the moment
        assert abs(np.dot(m, n)) < 1e-12 * cap
        np.testing.assert_allclose(torque[1], m, rtol=0, atol=1e-12 * cap)
        np.testing.assert_allclose(torque[0], -m, rtol=0, atol=1e-12 * cap)
        np.testing.assert_allclose(force, f_free, rtol=0, atol=1e-12 * fn)
    k, mag, diss = np.array(history).T
    ramp = k + 1 < steps_to_cap
    # 1. the elastic ramp: |M| = k_r |w_bend| (k + 1) dt
    np.testing.assert_allclose(mag[ramp], kr * 3.0 * (k[ramp] + 1) * dt, rtol=1e-12)
    np.testing.assert_allclose(diss[ramp], 0.0, atol=1e-10 * cap * cap / kr)
    # 2. on the cap: |M| = cap, dissipation cap |w_bend| dt a step
    on = (k > steps_to_cap + 1) & (k < int(1.5 * steps_to_cap))
    np.testing.assert_allclose(mag[on], cap, rtol=1e-12)
    np.testing.assert_allclose(np.diff(diss[on]), cap * 3.0 * dt, rtol=1e-9)
    # 3. unloading: back at the same slope, no further dissipation
    back = (k >= int(1.5 * steps_to_cap)) & (k < int(1.5 * steps_to_cap) + 0.9 * steps_to_cap)
    k0 = int(1.5 * steps_to_cap)
    np.testing.assert_allclose(mag[back], cap - kr * 3.0 * (k[back] - k0 + 1) * dt,
                               rtol=1e-10)
    np.testing.assert_allclose(np.diff(diss[back]), 0.0, atol=1e-10 * cap * cap / kr)
    assert diss.min() > -1e-10 * cap * cap / kr


def chain():
    """Four 1 mm spheres in a row along x, each touching its neighbours (the row closes
    through the periodic x face, overlap 2 um): 0 and 2 fixed (mass and inertia 1e30),
    1 and 3 free. A free sphere is squeezed between two fixed ones, so the normal forces
    cancel and it stays put."""
    r, overlap = 1.0e-3, 2e-6
    step = 2 * r - overlap
    pos = np.array([[k * step, 5e-3, 5e-3] for k in range(4)])
    b = from_packing(np.diag([4 * step, 10e-3, 10e-3]), pos, np.full(4, r), DENSITY,
                     capacity=4, history=HISTORY_ROLLING)
    for i in (0, 2):
        b.mass[0, i] = b.inertia[0, i] = 1e30
    return b, YOUNG * r * overlap  # f_n = kn delta, kn = E r* = E r


def test_a_spinning_sphere_is_stopped_by_the_rolling_moment():
    """A free sphere of the chain spun about z (in both contact planes) against its two
    fixed neighbours, friction 0: only the two rolling moments act, so once both sit on
    their cap the spin falls at exactly 2 eta_r r f_n / I per unit time; it stops near
    t = I w0 / (2 cap) + (the elastic ramp's half), and what is left is the elastic
    rocking of the two springs, |w| <= sqrt(2 cap^2 / (k_r I)) (their energy at the
    cap). A cap on min(r) f_n of one contact only, or a stiffness off, moves these."""
    b, fn = chain()
    p = law(alpha=1.0, eta=0.1)
    r = 1.0e-3
    inertia = b.inertia[0, 1]
    cap = 0.1 * r * fn
    kr = 1.0 * RATIO * YOUNG * r * r * r
    w0 = 500.0  # the rocking amplitude, ~20 rad/s, is small beside it
    b.w[0, 1, 2] = w0
    dt = engine.critical_dt(b, p, 0.1)
    t_stop = inertia * w0 / (2 * cap)
    n = int(1.3 * t_stop / dt)
    spin = np.empty(n)
    for k in range(n):
        engine.advance(b, 1, dt, p, engine.rate_control(1))
        spin[k] = b.w[0, 1, 2]
    t = (np.arange(n) + 1) * dt
    ramp = cap / (kr * w0)  # time to reach the cap at the initial spin
    sliding = (t > 3 * ramp) & (t < 0.8 * t_stop)
    slope = np.polyfit(t[sliding], spin[sliding], 1)[0]
    assert slope == pytest.approx(-2 * cap / inertia, rel=1e-6)
    # the sphere stayed in place, not spun about another axis
    assert np.abs(b.w[0, 1, :2]).max() < 1e-9 * w0
    stop = t[np.argmax(spin <= 0.0)]
    assert t_stop > 100 * dt  # resolved: the stop is found to one step
    assert stop == pytest.approx(t_stop + 0.5 * ramp, rel=0.01)
    rock = np.sqrt(2 * cap * cap / (kr * inertia))
    assert rock < 0.05 * w0
    assert np.abs(spin[t > 1.05 * t_stop]).max() <= 1.05 * rock


def test_angular_momentum_is_kept_with_rolling_resistance():
    """An isolated cluster (2 x 2 x 2 spheres closing in on their centre, random spins;
    no periodic image involved), friction and rolling resistance, no damping: each
    contact's forces and torques balance about any point (the moment's torques +M and
    -M, the tangential force's lever arms adding up to |d|), and the leapfrog then keeps
    L = sum m x_n x v_n+1/2 + I w_n+1/2 exactly in exact arithmetic, and the linear
    momentum too; here to round-off over 600 steps of collisions. Torque M on one grain
    only (or unequal) fails: the moments then change L by M dt a step."""
    rng = np.random.default_rng(4)
    corners = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)])
    pos = 10e-3 + 1.03e-3 * corners
    radii = rng.uniform(0.95e-3, 1.05e-3, 8)
    b = from_packing(np.eye(3) * 20e-3, pos, radii, DENSITY, capacity=8,
                     history=HISTORY_ROLLING)
    b.v[0] = -0.05 * corners / np.sqrt(3) + rng.normal(0.0, 0.005, (8, 3))
    b.w[0] = rng.normal(0.0, 30.0, (8, 3))
    p = law(alpha=1.0, eta=0.3, friction=0.4)

    def momenta():
        x = b.s[0] @ b.h[0].T
        m = b.mass[0][:, None]
        lin = np.sum(m * b.v[0], axis=0)
        ang = np.sum(np.cross(x, m * b.v[0]) + b.inertia[0][:, None] * b.w[0], axis=0)
        return lin, ang, np.sum(np.abs(np.cross(x, m * b.v[0])))

    dt = engine.critical_dt(b, p)
    p0, l0, _ = momenta()
    moments = 0
    for _ in range(600):
        engine.advance(b, 1, dt, p, engine.rate_control(1))
        m = np.linalg.norm(b.ft[0, :, :, 3:], axis=2)
        moments = max(moments, np.count_nonzero(m))
        p1, l1, scale_l = momenta()
        assert np.abs(l1 - l0).max() < 1e-12 * scale_l
        assert np.abs(p1 - p0).max() < 1e-13 * np.sum(b.mass[0][:, None] * np.abs(b.v[0]))
    assert moments >= 2  # rolling moments of two contacts at once were loaded
    assert np.all((b.s[0] > 0.2) & (b.s[0] < 0.8))  # nothing crossed a periodic face


def test_time_step_accounts_for_the_rolling_stiffness():
    """dt = safety sqrt(m_min / (E r_max)) / sqrt(1 + alpha_r r_max / r_min) with
    rolling resistance; unchanged without."""
    b = from_packing(np.eye(3) * 20e-3, np.array([[5e-3] * 3, [12e-3] * 3]),
                     np.array([1.0e-3, 2.0e-3]), DENSITY)
    base = engine.critical_dt(b, law(alpha=0.0, eta=0.0), 0.3)
    assert base == 0.3 * np.sqrt(b.mass.min() / (YOUNG * 2.0e-3))
    assert engine.critical_dt(b, law(alpha=1.5), 0.3) == pytest.approx(
        base / np.sqrt(1.0 + 1.5 * 2.0), rel=1e-14)


def test_rolling_keys_are_checked_and_enter_the_packing_recipe():
    with pytest.raises(ValueError, match="rolling_friction = 0.1 has no effect"):
        RVEParams(rolling_friction=0.1)
    with pytest.raises(ValueError, match="rolling_stiffness = 1.0 with rolling_friction = 0"):
        RVEParams(rolling_stiffness=1.0)
    with pytest.raises(ValueError, match="rolling_stiffness"):
        RVEParams(rolling_stiffness=-1.0, rolling_friction=0.1)
    off = RVEParams()
    on = RVEParams(rolling_stiffness=1.0, rolling_friction=0.1)
    assert "rolling_stiffness" not in off.recipe()  # the keys of packings made before
    assert on.recipe()["rolling_friction"] == 0.1 and on.recipe() != off.recipe()
    cp = contact_params(on)
    assert (cp.rolling_stiffness, cp.rolling_friction, cp.history) == (1.0, 0.1, 6)
    # compaction at a lower friction lowers the rolling friction in proportion
    assert contact_params(on, friction=0.25).rolling_friction == pytest.approx(0.05)
    assert contact_params(off).history == HISTORY


def test_history_width_is_widened_with_zero_moments_and_never_silently_dropped():
    b = from_packing(np.eye(3) * 20e-3, np.array([[5e-3] * 3, [12e-3] * 3]),
                     np.array([1.0e-3, 2.0e-3]), DENSITY)
    b.ft[0, 0, 0] = [1.0, 2.0, 3.0]
    with_history(b, HISTORY_ROLLING)
    assert b.ft.shape[3] == 6 and list(b.ft[0, 0, 0]) == [1, 2, 3, 0, 0, 0]
    with_history(b, HISTORY)  # zero moments: nothing is lost
    assert b.ft.shape[3] == 3
    with_history(b, HISTORY_ROLLING)
    b.ft[0, 0, 0, 4] = 1e-9
    with pytest.raises(ValueError, match="holds rolling moments"):
        with_history(b, HISTORY)


def test_a_packing_with_moments_is_refused_by_a_material_without_rolling(tmp_path):
    from grainscale.coupling.rve_material import RVEMaterial

    b, _ = pair([1.0, 0.0, 0.0])
    b.ft[0, 0, 0, 3:] = [0.0, 1e-9, 0.0]
    params = RVEParams(particles=20, radius_min=1e-3, radius_max=1.6e-3)
    with pytest.raises(ConfigError, match="materials.sand: a packing of its library "
                                          "holds rolling moments"):
        RVEMaterial("sand", params, [b], 1)


def test_a_packing_file_with_moments_is_refused_without_rolling(tmp_path):
    """`grainscale rve ... --packing` and a case's `packings`: a clear error naming the
    file and the key, not a traceback from inside a step."""
    from grainscale.io.packing import load_packing
    from grainscale.io.rve_h5 import write_rve_state

    b, _ = pair([1.0, 0.0, 0.0])
    b.ft[0, 0, 0, 3:] = [0.0, 1e-9, 0.0]
    path = tmp_path / "rolled.h5"
    write_rve_state(path, b)
    with pytest.raises(ConfigError, match="rolled.h5' holds rolling moments .* "
                                          "rolling_stiffness = 0.0"):
        load_packing(path, RVEParams())
    again = load_packing(path, RVEParams(rolling_stiffness=1.0, rolling_friction=0.1))
    assert again.ft.shape[3] == 6 and again.ft[0, 0, 0, 4] == 1e-9


def _axis_rotation(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _loaded_pinned_pair():
    """A pair (pair()) whose grains cannot move (mass and inertia 1e30) with a tangential
    force f0 and a rolling moment M0 in its contact plane, both below their caps
    (friction 0.5, eta_r 0.25); returns (batch, law, n, f0, M0)."""
    b, n = pair([1.0, 0.7, -0.4])
    b.mass[0] = b.inertia[0] = 1e30
    p = law(alpha=1.3, eta=0.25, friction=0.5)
    engine.refresh(b, p)
    r1, r2 = b.radius[0]
    fn = YOUNG * 2 * r1 * r2 / (r1 + r2) * 2e-6
    e1 = np.cross(n, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    f0 = 0.3 * fn * (0.8 * e1 + 0.6 * e2)
    m0 = 0.15 * min(r1, r2) * fn * (-0.6 * e1 + 0.8 * e2)
    b.ft[0, 0, 0, :3], b.ft[0, 0, 0, 3:] = f0, m0
    return b, p, n, f0, m0


@pytest.mark.parametrize("motion", ["mean_spin", "twist"])
def test_tangential_force_and_rolling_moment_turn_with_the_contact(motion):
    """Objectivity of the contact history under a superposed rigid rotation: a loaded
    contact (tangential force f0 and rolling moment M0 in its plane) that turns rigidly
    by R, with no relative motion of its grains, must carry R f0 and R M0. Two rigid
    rotations: 'mean_spin', the cell rotating (dH = R - I over the steps; the grains ride
    with it, their spins fluctuations about the cell's are 0) about an axis oblique to
    the normal; 'twist', both grains spinning at w n about the normal in a fixed cell.
    The kernel turns both histories by (W + w_n n) dt each step and keeps them in the
    contact plane: first order in the step, so over 0.6 rad in 600 steps the error is
    ~ (angle x W dt) / 2 ~ 3e-4 of the vector; 2e-3 is allowed. A history not turned
    (the moment, the force, or the twist part left out) stays fixed in space and misses
    by ~0.3-0.6 of the vector."""
    b, p, n, f0, m0 = _loaded_pinned_pair()
    angle, steps, dt = 0.6, 600, 1e-6
    if motion == "mean_spin":
        axis = np.array([0.2, -0.9, 0.4])
        R = _axis_rotation(axis, angle)
        third = _axis_rotation(axis, angle / 3)  # increments below the engine's 0.5
        for _ in range(3):
            ctrl = engine.increment_control(b, (third - np.eye(3))[None], steps // 3, dt)
            engine.advance(b, steps // 3, dt, p, ctrl)
        np.testing.assert_allclose(b.h[0], R @ (np.eye(3) * 20e-3), atol=1e-15)
    else:
        R = _axis_rotation(n, angle)
        b.w[0] = angle / (steps * dt) * n
        engine.advance(b, steps, dt, p, engine.increment_control(b, np.zeros((1, 3, 3)),
                                                                  steps, dt))
    f, m = b.ft[0, 0, 0, :3], b.ft[0, 0, 0, 3:]
    np.testing.assert_allclose(f, R @ f0, rtol=0, atol=2e-3 * np.linalg.norm(f0))
    np.testing.assert_allclose(m, R @ m0, rtol=0, atol=2e-3 * np.linalg.norm(m0))
    # the torques they exert are turned alike: l_i n x f - M on the first grain,
    # l_j n x f + M on the second (lever arms to the middle of the overlap, 2 um)
    r1, r2 = b.radius[0]
    nf = np.cross(R @ n, R @ f0)
    scale = np.linalg.norm(m0) + r2 * np.linalg.norm(f0)
    np.testing.assert_allclose(b.torque[0, 0], (r1 - 1e-6) * nf - R @ m0, rtol=0,
                               atol=2e-3 * scale)
    np.testing.assert_allclose(b.torque[0, 1], (r2 - 1e-6) * nf + R @ m0, rtol=0,
                               atol=2e-3 * scale)

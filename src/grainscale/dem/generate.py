"""Packing generation: random insertion, servo consolidation, friction control of porosity.

1. Radii uniform in [r_min, r_max]; spheres inserted at random without overlap (largest
   first) in a cubic periodic cell at a loose `initial_porosity`.
2. Servo-controlled isotropic compression to the consolidation pressure with a
   compaction friction (default: the real friction) until equilibrium. Very stiff grains
   at low pressure (stiffness number E/p above 2e4, e.g. the column-collapse RVE at 500
   Pa; (E*/p)^(2/3) for Hertz-Mindlin) jam only slowly under a stress servo, so by
   default they are consolidated where it is 2e4 (`jamming_pressure`) and unloaded to
   the target pressure at the end; unloading is elastic (strain ~ 1/2e4), so it changes
   the porosity by well under 1e-3.
3. If a target porosity is given and the packing is looser, the compaction friction is
   lowered step by step, re-equilibrating at the target pressure each time: lower
   friction lets the packing densify. A step that overshoots the target is undone from a
   snapshot and retried with a smaller friction decrement, so porosity approaches the
   target from above. Small packings can collapse past the target at any decrement;
   then the compaction friction is bisected instead, each trial compressing the gas
   state afresh.
4. The real friction is restored and the packing relaxed (and unloaded) to the target
   pressure until the unbalanced-force ratio is below `preparation.unbalanced`.

Deterministic for a seed (one RNG, fixed operation order). If the target porosity
cannot be reached, a GenerationError says which porosity range was reachable.
"""

from __future__ import annotations

import numpy as np

from grainscale.config.base import ConfigError
from grainscale.config.rve import RVEParams, min_particles
from grainscale.dem import clump, engine, hertz, homogenise
from grainscale.dem.quaternion import matrix
from grainscale.dem.state import RVEBatch, from_clumps, from_packing


class GenerationError(ConfigError):
    """The requested packing state could not be reached (an input error: the message
    names the key and the reachable range)."""


def contact_params(params: RVEParams, friction: float | None = None,
                   damping: float | None = None) -> engine.ContactParams:
    """The kernel's contact parameters from an [rve] table. A `friction` other than the
    table's (compaction) scales the rolling friction by the same factor, so that a
    frictionless compaction is also free to roll (the densest packings stay reachable)."""
    mu = params.friction if friction is None else friction
    eta = params.rolling_friction
    if friction is not None and params.friction > 0.0:
        eta *= friction / params.friction
    return engine.ContactParams(
        young=params.young_modulus, stiffness_ratio=params.stiffness_ratio, friction=mu,
        damping=params.damping if damping is None else damping,
        skin=params.numerics.skin * params.radius_min, restitution=params.restitution,
        rolling_stiffness=params.rolling_stiffness, rolling_friction=eta,
        contact_law=params.contact_law, poisson=params.poisson_ratio or 0.0,
        max_overlap=params.numerics.max_overlap)


def jamming_pressure(params: RVEParams) -> float:
    """The pressure [Pa] at which the stiffness number is 2e4 (module docstring, 2): E/p
    for the linear law (kn/(p d) up to a constant), (E*/p)^(2/3) for Hertz-Mindlin
    (the form of Agnolin & Roux 2007's kappa, whose modulus E/(1 - nu^2) is twice this
    E*; overlaps delta/d ~ 1/kappa in both laws)."""
    if params.contact_law == "hertz_mindlin":
        return hertz.effective_modulus(params.young_modulus, params.poisson_ratio) / 2e4**1.5
    return params.young_modulus / 2e4


def insert_random(n: int, rmin: float, rmax: float, porosity: float,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Non-overlapping random spheres in a cubic periodic cell at the given porosity.

    Returns (h, centres, radii). Radii are uniform in [rmin, rmax].
    """
    radii = rng.uniform(rmin, rmax, n)
    solid = (4.0 / 3.0) * np.pi * np.sum(radii**3)
    side = (solid / (1.0 - porosity)) ** (1.0 / 3.0)
    if side < 4.0 * (2.0 * rmax):
        raise GenerationError(
            f"rve.particles = {n} is too few for radius_max = {rmax}: the cell side "
            f"{side:.4g} m would be below 8 r_max (these random radii); valid: more, "
            f"at least {min_particles(rmin, rmax, porosity)} on average and a few more")
    order = np.argsort(-radii, kind="stable")
    pos = np.empty((n, 3))
    placed = 0
    for idx in order:
        r = radii[idx]
        for _ in range(100_000):
            trial = rng.uniform(0.0, side, 3)
            if placed:
                d = pos[order[:placed]] - trial
                d -= side * np.round(d / side)
                gap = np.einsum("ij,ij->i", d, d) - (radii[order[:placed]] + r) ** 2
                if gap.min() <= 0.0:
                    continue
            pos[idx] = trial
            placed += 1
            break
        else:
            raise GenerationError(
                f"could not insert sphere {placed + 1} of {n} without overlap at "
                f"rve.preparation.initial_porosity = {porosity}; raise it")
    return np.eye(3) * side, pos, radii


def insert_clumps(n: int, rmin: float, rmax: float, shape, porosity: float,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    """n clumps of the template `shape` (clump.Template of unit member radius), each
    scaled by a factor uniform in [rmin, rmax] and turned at random (uniform on the
    rotations), in a cubic periodic cell at the given porosity of their solid volume;
    no member of one overlaps a member of another. Returns (h, centres, quaternions,
    grains)."""
    sizes = rng.uniform(rmin, rmax, n)
    grains = [clump.scaled(shape, s) for s in sizes]
    reach = float(np.max(np.linalg.norm(shape.offsets, axis=1) + shape.radii))
    solid = sum(g.volume for g in grains)
    side = (solid / (1.0 - porosity)) ** (1.0 / 3.0)
    if side < 8.0 * reach * rmax:
        raise GenerationError(
            f"rve.particles = {n} clumps are too few for their size: the cell side "
            f"{side:.4g} m would be below 8 times their largest reach from the centre "
            f"{reach * rmax:.4g} m; valid: more clumps")
    quats = rng.standard_normal((n, 4))  # normalised Gaussian: uniform on rotations
    quats /= np.linalg.norm(quats, axis=1)[:, None]
    order = np.argsort(-sizes, kind="stable")
    pos = np.empty((n, 3))
    members = np.empty((0, 3))
    radii = np.empty(0)
    rot = np.empty((3, 3))
    for placed, idx in enumerate(order):
        g = grains[idx]
        matrix(quats[idx], rot)
        off = g.offsets @ rot.T
        for _ in range(100_000):
            trial = rng.uniform(0.0, side, 3)
            if placed:
                d = members[:, None, :] - (trial + off)[None, :, :]
                d -= side * np.round(d / side)
                gap = np.einsum("ijk,ijk->ij", d, d) - (radii[:, None] + g.radii[None, :]) ** 2
                if gap.min() <= 0.0:
                    continue
            pos[idx] = trial
            members = np.concatenate([members, trial + off])
            radii = np.concatenate([radii, g.radii])
            break
        else:
            raise GenerationError(
                f"could not insert clump {placed + 1} of {n} without overlap at "
                f"rve.preparation.initial_porosity = {porosity}; raise it")
    return np.eye(3) * side, pos, quats, grains


def consolidate(batch: RVEBatch, cp: engine.ContactParams, pressure: float, dt: float,
                max_rate: float, gain: float, unbalanced: float,
                max_steps: int = 3_000_000, chunk: int = 500, tol: float = 0.01) -> int:
    """Servo all three normal stresses to -pressure until static; returns steps taken.

    Shear stresses are servoed to zero (the cell may shear), so the state is isotropic.
    Static: every stress component within `tol` x pressure of its target and the
    unbalanced-force ratio below `unbalanced`, for two consecutive checks.
    """
    servo = {0: -pressure, 1: -pressure, 2: -pressure, (0, 1): 0.0, (0, 2): 0.0, (1, 2): 0.0}
    ctrl = engine.rate_control(batch.n_rve, servo=servo, max_rate=max_rate, gain=gain)
    steps = 0
    calm = 0
    while steps < max_steps:
        engine.advance(batch, chunk, dt, cp, ctrl)
        steps += chunk
        err = np.abs(batch.stress + pressure * np.eye(3)) / pressure
        ok = np.all(err < tol) and np.all(batch.unbalanced < unbalanced)
        calm = calm + 1 if ok else 0
        if calm >= 2:
            return steps
    raise GenerationError(
        f"no static state at p = {pressure:g} Pa after {max_steps} steps (p = "
        f"{homogenise.mean_stress(batch.stress)[0]:.4g} Pa, unbalanced = "
        f"{batch.unbalanced[0]:.3g}); check rve.preparation.max_strain_rate")


def generate(params: RVEParams, progress=None) -> RVEBatch:
    """A consolidated packing (batch of one RVE) as the [rve] table asks; with
    [rve.clump] of params.particles clumps of its template, each scaled by a factor
    uniform in [radius_min, radius_max] (insert_clumps).

    `progress(text)` is called with a status line after each stage if given.
    """
    prep = params.preparation
    say = progress or (lambda text: None)
    rng = np.random.default_rng(params.seed)
    cp = contact_params(params, damping=prep.damping)
    if params.clump is None:
        h, pos, radii = insert_random(params.particles, params.radius_min,
                                      params.radius_max, prep.initial_porosity, rng)
        batch = from_packing(h, pos, radii, params.density, history=cp.history)
    else:
        h, pos, quats, grains = insert_clumps(params.particles, params.radius_min,
                                              params.radius_max, params.clump.shape(),
                                              prep.initial_porosity, rng)
        batch = from_clumps(h, pos, quats, grains, params.density, history=cp.history)
    dt = engine.critical_dt(batch, cp, params.numerics.timestep_safety)
    mu = params.friction if prep.compaction_friction is None else prep.compaction_friction

    p_cons = prep.consolidation_pressure or max(prep.pressure, jamming_pressure(params))

    def settle_from(state: RVEBatch, friction: float) -> tuple[RVEBatch, float]:
        nonlocal batch
        batch = state.copy()
        return batch, settle(friction)

    def settle(friction: float, pressure: float = p_cons) -> float:
        consolidate(batch, contact_params(params, friction, prep.damping), pressure, dt,
                    prep.max_strain_rate, params.numerics.servo_gain, prep.unbalanced)
        n = float(batch.porosity()[0])
        say(f"compaction friction {friction:.4f}: porosity {n:.4f} at "
            f"p = {homogenise.mean_stress(batch.stress)[0]:.4g} Pa")
        return n

    gas = batch.copy()
    mu_start = mu
    n = settle(mu)
    target, tol = prep.porosity, prep.porosity_tolerance
    if target is not None:
        if n < target - tol:
            raise GenerationError(
                f"rve.preparation.porosity = {target} is looser than what compaction "
                f"reaches: compaction friction {mu} gives porosity {n:.4f} at p = "
                f"{p_cons:g} Pa; reachable here: porosity <= {n:.4f} (raise "
                f"rve.preparation.compaction_friction for looser packings)")
        factor = 0.7
        while n > target + 0.5 * tol:
            if mu == 0.0:
                raise GenerationError(
                    f"rve.preparation.porosity = {target} is denser than what frictionless "
                    f"compaction reaches: porosity {n:.4f} at p = {p_cons:g} Pa; "
                    f"reachable here: porosity >= {n:.4f}")
            snapshot = batch.copy()
            trial = mu * factor if mu * factor > 1e-3 else 0.0
            n_trial = settle(trial)
            if n_trial < target - tol:  # overshoot: undo, take a smaller step
                batch = snapshot
                factor = factor ** 0.5
                if factor > 0.999 and abs(n - target) <= tol:
                    break  # within tolerance and no finer step exists: keep it
                if factor > 0.999:
                    say(f"porosity jumps past the target ({n:.4f} -> {n_trial:.4f}): "
                        "bisecting the compaction friction from the gas state")
                    batch, n = _bisect(gas, settle_from, mu_start, target, tol)
                    break
                continue
            mu, n = trial, n_trial
    # real friction restored, relaxed (and unloaded) to equilibrium at the target pressure
    n = settle(params.friction, prep.pressure)
    if target is not None and abs(n - target) > tol:
        raise GenerationError(
            f"restoring friction {params.friction} moved the porosity to {n:.4f}, outside "
            f"rve.preparation.porosity = {target} ± {tol}")
    batch.h0[:] = batch.h
    batch.rot[:] = 0.0
    return batch


def _bisect(gas: RVEBatch, settle_from, mu_hi: float, target: float, tol: float,
            max_trials: int = 12):
    """Compaction friction in [0, mu_hi] (frictionless compaction is the densest, the
    starting friction gave a looser packing than the target), each trial compressing the
    gas state afresh; returns (batch, porosity)."""
    mu_lo = 0.0
    best = None
    for _ in range(max_trials):
        mu = 0.5 * (mu_lo + mu_hi)
        batch, n = settle_from(gas, mu)
        if best is None or abs(n - target) < abs(best[1] - target):
            best = (batch, n)
        if abs(n - target) <= tol:
            return batch, n
        if n > target:
            mu_hi = mu
        else:
            mu_lo = mu
    raise GenerationError(
        f"rve.preparation.porosity = {target} ± {tol} not reached by bisecting the "
        f"compaction friction in [{mu_lo:.4g}, {mu_hi:.4g}]: closest {best[1]:.4f}; this "
        "packing is too small to set its porosity this finely (raise "
        "rve.particles or rve.preparation.porosity_tolerance)")

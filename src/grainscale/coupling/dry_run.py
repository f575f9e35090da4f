"""`grainscale check CASE.toml`: what a run would be, without running it (docs/case-files.md).

The case is validated as a run validates it (every input error, before any work), its
points counted per material, and for each "dem" material its first packing prepared (or
read from the packing store) and a few DEM steps of it timed on this machine. From those:

    MPM step dt = cfl h_min / c_max   (c_max the largest wave speed: the RVE's affine
                                       sqrt(max_k M_k / rho_bulk) of its first packing, a
                                       continuum's P-wave sqrt(E (1 - nu) / ((1 + nu)
                                       (1 - 2 nu)) / rho); solver.dt where it is fixed)
    MPM steps = (time.end - time.start) / dt
    DEM steps per RVE and MPM step: dynamic RVEs max(min_substeps, ceil(dt / dt_crit));
        quasi-static ones an assumption (`dem_steps`, default 6: the intrusions measured
        4.8-9.4, docs/performance.md), stated as such
    DEM wall time = sum over materials of RVEs x spheres x DEM steps x MPM steps x the
        timed wall time per particle-step (this machine, these threads)

It is an estimate: the wave speed grows as the RVEs are compressed (more MPM steps),
the MPM's own work is left out (2-10 % of a multiscale run's step, docs/performance.md
§1.5), and adaptive updates or sleeping RVEs skip DEM steps (fewer).
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from grainscale.config.case import Case
from grainscale.dem import engine
from grainscale.dem.generate import contact_params
from grainscale.dem.state import concatenate

QUASI_STATIC_DEM_STEPS = 6.0  # assumed DEM steps per RVE and MPM step (module docstring)


def _points_per_material(case: Case, case_dir: Path) -> tuple[dict[str, int], float]:
    """Material points of each material, from the solver's own set-up with stand-in
    materials (driver.stand_in_state: every check a run makes before its packings, no
    packing made; the probes resolved on it), and the grid's smallest cell [m]."""
    from grainscale.coupling.driver import stand_in_state
    from grainscale.coupling.probes import resolve

    s = stand_in_state(case, case_dir)
    resolve(case, s)
    out = {mat.name: int(s.points.n if ids is None else len(ids))
           for mat, ids in zip(s.materials, s.mat_points, strict=True)}
    return out, float(min(np.min(np.diff(a)) for a in s.grid.node_axes() if len(a) > 1))


def _continuum_wave_speed(cfg) -> float:
    e, nu, rho = (getattr(cfg, k, None) for k in ("youngs_modulus", "poisson_ratio",
                                                     "density"))
    if e is None or nu is None or not rho:
        return 0.0
    return math.sqrt(e * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / rho)


def _time_dem(params, rves: int, steps: int = 20) -> dict:
    """The first packing of the recipe (the store's, or generated), its critical step,
    affine wave speed, state bytes, and the wall seconds per particle-step of a batch of
    min(8, rves) copies advanced `steps` steps (after two to compile)."""
    from grainscale.coupling.materials import cached_packing
    from grainscale.coupling.rve_material import rve_state_bytes

    with tempfile.TemporaryDirectory() as tmp:
        p0 = cached_packing(params, 0, Path(tmp) / "p0.h5", progress=False)
    cp = contact_params(params)
    engine.refresh(p0, cp)
    dt_crit = engine.critical_dt(p0, cp, params.numerics.timestep_safety)
    rho = float(p0.mass[0].sum() / p0.volume()[0])
    c = math.sqrt(float(np.diagonal(p0.stiffness[0]).max()) / rho)
    batch = concatenate([p0] * max(1, min(8, rves)))
    zero = np.zeros((batch.n_rve, 3, 3))
    for n in (2, steps):  # the first call compiles; the second is timed
        ctrl = engine.increment_control(batch, zero, np.full(batch.n_rve, n), dt_crit)
        t0 = time.perf_counter()
        engine.advance(batch, n, dt_crit, cp, ctrl)
        wall = time.perf_counter() - t0
    return {"dt_crit": dt_crit, "wave_speed": c, "spheres": p0.n_particles,
            "bytes_per_rve": rve_state_bytes(p0),
            "wall_per_particle_step": wall / (steps * batch.n_rve * p0.n_particles)}


def check(case: Case, dem_steps: float | None = None) -> dict:
    """The dry run's figures (module docstring) of a validated case."""
    case = case.check()
    case_dir = case._case_dir or Path.cwd()
    counts, h_min = _points_per_material(case, case_dir)
    speeds, materials = [], {}
    for name, cfg in case.materials.items():
        if cfg.type != "dem":
            speeds.append(_continuum_wave_speed(cfg))
            materials[name] = {"points": counts.get(name, 0), "type": cfg.type}
            continue
        n = counts.get(name, 0)
        timed = _time_dem(case.rve, n) if n else None
        if timed:
            speeds.append(timed["wave_speed"])
        materials[name] = {"points": n, "type": "dem", "rves": n, "dem": timed,
                           "time_integration": cfg.time_integration}
    c = max(speeds) if speeds else 0.0
    dt = case.solver.dt if case.solver.dt is not None else (
        case.solver.cfl * h_min / c if c > 0 else math.nan)
    steps = (case.time.end - case.time.start) / dt
    wall = 0.0
    for name, m in materials.items():
        if m["type"] != "dem" or not m["dem"]:
            continue
        cfg, d = case.materials[name], m["dem"]
        if m["time_integration"] == "dynamic":
            m["dem_steps_per_step"] = float(max(cfg.min_substeps,
                                                math.ceil(dt / d["dt_crit"] - 1e-9)))
            m["dem_steps_assumed"] = False
        else:
            m["dem_steps_per_step"] = float(dem_steps or QUASI_STATIC_DEM_STEPS)
            m["dem_steps_assumed"] = True
        m["dem_wall_seconds"] = (m["rves"] * d["spheres"] * m["dem_steps_per_step"] * steps
                                 * d["wall_per_particle_step"])
        m["memory_bytes"] = m["rves"] * d["bytes_per_rve"]
        wall += m["dem_wall_seconds"]
    return {"title": case.title, "points": sum(counts.values()), "h_min": h_min,
            "wave_speed": c, "dt": dt, "mpm_steps": steps, "materials": materials,
            "dem_wall_seconds": wall}


def format_check(r: dict) -> str:
    lines = [f"{r['title']}: {r['points']} material points; MPM step {r['dt']:.3g} s "
             f"(cfl x h_min {r['h_min']:.3g} m / c {r['wave_speed']:.3g} m/s), "
             f"{r['mpm_steps']:.0f} MPM steps to the end"]
    for name, m in r["materials"].items():
        if m["type"] != "dem" or not m.get("dem"):
            lines.append(f"  {name} ({m['type']}): {m['points']} points")
            continue
        d = m["dem"]
        how = "assumed (quasi-static RVEs)" if m["dem_steps_assumed"] else "dt / dt_crit"
        lines.append(
            f"  {name} (dem, {m['time_integration']}): {m['rves']} RVEs of {d['spheres']} "
            f"spheres, {m['memory_bytes'] / 1e9:.3g} GB of RVE state (a checkpoint holds "
            f"as much before compression); DEM step {d['dt_crit']:.3g} s, "
            f"{m['dem_steps_per_step']:.3g} DEM steps per RVE and MPM step ({how}); "
            f"{1e9 * d['wall_per_particle_step']:.3g} ns per particle-step here")
    lines.append(f"estimated DEM wall time on this machine: {r['dem_wall_seconds'] / 3600:.3g} h "
                 "(an estimate: docs/case-files.md, grainscale check)")
    return "\n".join(lines)

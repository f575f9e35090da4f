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
        quasi-static ones an assumption (`dem_steps`, default 4.6: with adaptive
        updates runs measured 2.28 (examples/footing), 2.5-2.6 (the no-slip
        intrusions), 4.89 (the quick intrusion) and 9.42 (seed_quick.toml), and 4.6 is
        within a factor 2.05 of each; docs/performance.md), stated as such
    DEM wall time = sum over materials of RVEs x spheres x DEM steps x MPM steps x the
        timed wall time per particle-step (this machine, these threads)

It is an estimate: the wave speed grows as the RVEs are compressed (more MPM steps),
the MPM's own work is left out (2-10 % of a multiscale run's step, docs/performance.md
§1.5), and adaptive updates or sleeping RVEs skip DEM steps (fewer).

Warnings (`warnings`, each a sentence naming the key and what to change), for a case
that is valid but likely not what its author wants (docs/guide.md):
- one point per cell (`bodies[i].points_per_cell = 1`) in a flowing material (dynamic
  RVEs, mu_i, nonlocal_mu_i): a cell's stress is one sample, and points crossing cell
  boundaries make the grid forces jump (cell-crossing noise), which large deformation
  does all the time; in a static problem one point a cell is fine (the strip footing of
  docs/validation.md §3.3 lands closer to the exact limit load with one than with 8);
- a body spanning fewer than MIN_CELLS_ACROSS cells along an axis in which the grid has
  more: a GIMP point's weight reaches one cell beyond its own, so such a body has no
  interior along that axis and its stress gradient (gravity's, a footing's) is not
  resolved (a one-cell slice between walls, an axis of 1-2 cells, is not warned);
- an RVE cell that retiles early: its packing's narrowest width W0 (mean diameters)
  under RETILE_EARLY x `retile_width`, i.e. a stretch of W0 / retile_width (< 1.25)
  across a face pair doubles the cell (8 x the spheres at most, `retile_max_factor`);
- Hertz-Mindlin grains whose largest overlap (hertz.largest_overlap) at the highest
  pressure a packing is prepared at (the preparation's or a geostatic library's) exceeds
  half of `rve.numerics.max_overlap`: a run that doubles the stress would stop there.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from grainscale.config.case import Case
from grainscale.config.rve import min_particles
from grainscale.dem import engine, hertz
from grainscale.dem.cell import perpendicular_widths
from grainscale.dem.generate import contact_params
from grainscale.dem.state import concatenate

QUASI_STATIC_DEM_STEPS = 4.6  # assumed DEM steps per RVE and MPM step (module docstring)
MIN_CELLS_ACROSS = 4  # cells a body should span along an axis (module docstring)
RETILE_EARLY = 1.25  # a packing narrower than this x retile_width retiles early


def _points_per_material(case: Case, case_dir: Path
                         ) -> tuple[dict[str, int], float, list[str]]:
    """Material points of each material, from the solver's own set-up with stand-in
    materials (driver.stand_in_state: every check a run makes before its packings, no
    packing made; the probes resolved on it), the grid's smallest cell [m] and the
    grid's warnings (module docstring)."""
    from grainscale.coupling.driver import stand_in_state
    from grainscale.coupling.probes import resolve

    s = stand_in_state(case, case_dir)
    resolve(case, s)
    out = {mat.name: int(s.points.n if ids is None else len(ids))
           for mat, ids in zip(s.materials, s.mat_points, strict=True)}
    axes = s.grid.node_axes()
    return (out, float(min(np.min(np.diff(a)) for a in axes if len(a) > 1)),
            _grid_warnings(case, s.points, axes))


def _grid_warnings(case: Case, points, axes) -> list[str]:
    """One point per cell, and bodies that span too few cells (module docstring)."""
    warn = []
    for i, body in enumerate(case.bodies):
        m = case.materials[body.material]
        flows = m.type in ("mu_i", "nonlocal_mu_i") or (
            m.type == "dem" and m.time_integration == "dynamic")
        if body.points_per_cell == 1 and flows:
            warn.append(f"bodies[{i}].points_per_cell = 1 in a flow ({body.material!r}: "
                        f"{m.type}{', dynamic' if m.type == 'dem' else ''}): each cell's "
                        "stress is one sample and points crossing cell boundaries make the "
                        "grid forces jump; 2 (8 points a cell) is the usual choice")
    for k, name in enumerate("xyz"):
        cells = len(axes[k]) - 1
        if cells < MIN_CELLS_ACROSS or (case.grid.periodic and name in case.grid.periodic):
            continue
        h = float(np.min(np.diff(axes[k])))
        for m, mat in enumerate(case.materials):
            sel = points.mat == m
            if not sel.any():
                continue
            span = float(np.ptp(points.x[sel, k]) + 2 * points.lp[sel, k].max())
            if span < MIN_CELLS_ACROSS * h * (1 - 1e-9):
                warn.append(
                    f"material {mat!r} spans {span / h:.3g} cells along {name} (grid.cell_size "
                    f"{h:g} m): a GIMP point reaches one cell beyond its own, so the body has "
                    f"no interior along {name} and its stress gradient is not resolved; "
                    f"give it at least {MIN_CELLS_ACROSS} cells")
    return warn


def _continuum_wave_speed(cfg) -> float:
    e, nu, rho = (getattr(cfg, k, None) for k in ("youngs_modulus", "poisson_ratio",
                                                     "density"))
    if e is None or nu is None or not rho:
        return 0.0
    return math.sqrt(e * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / rho)


def _time_dem(params, rves: int, steps: int = 50, repeats: int = 3) -> dict:
    """The first packing of the recipe (the store's, or generated), its critical step,
    affine wave speed, state bytes, and the wall seconds per particle-step of a batch of
    min(32, rves) copies advanced `steps` steps, the least of `repeats` timings (after
    two steps to compile: the least is the one other work on the machine disturbed
    least)."""
    from grainscale.coupling.materials import cached_packing
    from grainscale.coupling.rve_material import rve_state_bytes

    with tempfile.TemporaryDirectory() as tmp:
        p0 = cached_packing(params, 0, Path(tmp) / "p0.h5", progress=False)
    cp = contact_params(params)
    engine.refresh(p0, cp)
    dt_crit = engine.critical_dt(p0, cp, params.numerics.timestep_safety)
    rho = float(p0.mass[0].sum() / p0.volume()[0])
    c = math.sqrt(float(np.diagonal(p0.stiffness[0]).max()) / rho)
    batch = concatenate([p0] * max(1, min(32, rves)))
    zero = np.zeros((batch.n_rve, 3, 3))
    walls = []
    for n in (2, *[steps] * repeats):  # the first call compiles
        ctrl = engine.increment_control(batch, zero, np.full(batch.n_rve, n), dt_crit)
        t0 = time.perf_counter()
        engine.advance(batch, n, dt_crit, cp, ctrl)
        walls.append(time.perf_counter() - t0)
    width = float(perpendicular_widths(p0.h[0]).min() / (2 * p0.radius[0].mean()))
    return {"dt_crit": dt_crit, "wave_speed": c, "spheres": p0.n_particles,
            "bytes_per_rve": rve_state_bytes(p0), "width_in_diameters": width,
            "wall_per_particle_step": min(walls[1:]) / (steps * batch.n_rve * p0.n_particles)}


def check(case: Case, dem_steps: float | None = None) -> dict:
    """The dry run's figures (module docstring) of a validated case."""
    case = case.check()
    case_dir = case._case_dir or Path.cwd()
    counts, h_min, warnings = _points_per_material(case, case_dir)
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
        if timed and 0 < timed["width_in_diameters"] < RETILE_EARLY * cfg.retile_width:
            w = timed["width_in_diameters"]
            warnings.append(
                f"materials.{name}.retile_width = {cfg.retile_width:g}: the packing's cell is "
                f"{w:.3g} mean diameters wide, so a stretch of {w / cfg.retile_width:.3g} "
                "across a face pair doubles it (up to retile_max_factor x the spheres); "
                "more rve.particles, or a smaller retile_width (docs/coupling.md)")
    rve = case.rve
    if rve is not None and rve.contact_law == "hertz_mindlin" and counts:
        # the highest pressure a packing is prepared at: the preparation's, or a
        # geostatic library's deepest level
        key, p = "rve.preparation.pressure", rve.preparation.pressure
        for name, cfg in case.materials.items():
            if cfg.type == "dem" and counts.get(name) and cfg.geostatic_pressures:
                if max(cfg.geostatic_pressures) > p:
                    key, p = f"materials.{name}.geostatic_pressures", max(
                        cfg.geostatic_pressures)
        est = hertz.largest_overlap(p, rve.young_modulus, rve.poisson_ratio)
        if est > 0.5 * rve.numerics.max_overlap:
            warnings.append(
                f"rve.numerics.max_overlap = {rve.numerics.max_overlap:g}: at {key} "
                f"({p:g} Pa) the largest Hertzian overlap is about {est:.3g} of R*, and a "
                "run that doubles the stress stops past max_overlap; raise it (a shorter "
                "DEM step) or stiffer grains (rve.young_modulus)")
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
    smallest = min_particles(rve.radius_min, rve.radius_max,
                             rve.preparation.initial_porosity, 3.0) if rve else None
    return {"title": case.title, "points": sum(counts.values()), "h_min": h_min,
            "wave_speed": c, "dt": dt, "mpm_steps": steps, "materials": materials,
            "dem_wall_seconds": wall, "smallest_valid_particles": smallest,
            "warnings": warnings}


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
        lines.append(f"    the packing's cell is {d['width_in_diameters']:.3g} mean diameters "
                     f"wide; rve.particles must be at least {r['smallest_valid_particles']} "
                     "for these radii")
    if any(m["type"] == "dem" for m in r["materials"].values()):
        lines.append(f"estimated DEM wall time on this machine: "
                     f"{r['dem_wall_seconds'] / 3600:.3g} h (an estimate: "
                     "docs/case-files.md, grainscale check)")
    else:
        lines.append("no 'dem' material: no DEM work (the MPM's is not estimated)")
    lines += [f"warning: {w}" for w in r["warnings"]]
    return "\n".join(lines)

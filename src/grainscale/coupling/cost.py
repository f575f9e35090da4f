"""The cost report (cost.json, docs/coupling.md "Cost report"): where a run's time went.

A run's cost is kept as additive totals (`totals`, over the ranks), so that the totals of
the run so far travel in each checkpoint and a resumed run reports the whole history's
cost (`report` of `add(before, this invocation's)`) beside its own invocation's. The
figures derived from them (`report`): time per step split into MPM, DEM, communication,
waiting and everything else (outputs, checkpoints), averaged over ranks; the core-time
one RVE costs per step; DEM steps per RVE and MPM step; the share of RVEs stepped (adaptive
updates and sleeping RVEs skip some); core-ns per particle-step.
"""

from __future__ import annotations

import numba
import numpy as np

from grainscale.coupling.rve_material import RVEMaterial

# additive totals: MPM steps, wall seconds, mean seconds over ranks of each part, core
# seconds of the DEM and of everything, DEM steps and updates summed over RVEs, particle-
# steps, and RVEs x MPM steps (the denominator of the per-RVE figures)
KEYS = ("steps", "wall", "mpm", "dem", "comm", "wait", "other", "core_dem", "core_all",
        "dem_steps", "rve_updates", "particle_steps", "rve_steps")
PARTS = ("mpm", "dem", "comm", "wait", "other")


def totals(s, steps: int, step_seconds: float, wall_seconds: float,
           comm_seconds: float = 0.0, wait_seconds: float = 0.0) -> dict | None:
    """This invocation's totals over `steps` MPM steps (a step that failed counts: its time
    is in step_seconds); comm_seconds and wait_seconds are those spent inside the steps.
    Collective: the result (with the report's descriptive keys: points, rves, ranks,
    threads, reduced bytes) is on rank 0, None on the others."""
    rve = [m for m in s.materials if isinstance(m, RVEMaterial)]
    dem = sum(m.seconds for m in rve)
    c = s.comm
    mine = {"dem": dem, "comm": comm_seconds, "wait": wait_seconds,
            "mpm": step_seconds - dem - comm_seconds - wait_seconds,
            "other": wall_seconds - step_seconds,
            "rves": sum(m.n_rve for m in rve), "dem_steps": sum(m.rve_steps for m in rve),
            "rve_updates": sum(m.rve_updates for m in rve),
            "particle_steps": sum(m.particle_steps for m in rve),
            "reduced_bytes": c.bytes_reduced}
    ranks = c.gather(mine)
    if ranks is None:
        return None
    threads = numba.get_num_threads()
    rves = int(sum(r["rves"] for r in ranks))
    out = {k: float(np.mean([r[k] for r in ranks])) for k in PARTS}
    out.update(steps=float(steps), wall=float(wall_seconds),
               core_dem=sum(r["dem"] for r in ranks) * threads,
               core_all=float(wall_seconds) * threads * c.size,
               dem_steps=float(sum(r["dem_steps"] for r in ranks)),
               rve_updates=float(sum(r["rve_updates"] for r in ranks)),
               particle_steps=float(sum(r["particle_steps"] for r in ranks)),
               rve_steps=float(rves * steps))
    out["about"] = {"points": int(s.n_global), "rves": rves, "ranks": c.size,
                    "threads": threads,
                    "dem_seconds_max_rank": max(r["dem"] for r in ranks),
                    "reduced_bytes": float(np.mean([r["reduced_bytes"] for r in ranks]))}
    return out


def add(before: dict | None, now: dict) -> dict:
    """Totals of the run so far: `before` (a checkpoint's) plus this invocation's."""
    if before is None:
        return {k: now[k] for k in KEYS}
    return {k: before[k] + now[k] for k in KEYS}


def report(t: dict) -> dict:
    """The figures of totals `t` (module docstring). Every part is >= 0 and every share
    within [0, 1] when the totals count the same steps: a step that failed counts in
    `steps` and in the step time as its DEM work does (driver._run)."""
    n = max(t["steps"], 1.0)
    out = {"steps": int(t["steps"]), "wall_seconds": t["wall"],
           "core_hours": t["core_all"] / 3600.0,
           "seconds_per_step": {**{k: t[k] / n for k in PARTS}, "total": t["wall"] / n}}
    if t["rve_steps"] > 0:
        out["core_seconds_per_rve_per_step"] = t["core_dem"] / t["rve_steps"]
        out["dem_steps_per_rve_per_step"] = t["dem_steps"] / t["rve_steps"]
        # adaptive updates and sleeping RVEs step only some RVEs each MPM step
        out["fraction_of_rves_stepped"] = t["rve_updates"] / t["rve_steps"]
        if t["particle_steps"]:  # the kernel's own figure is their floor
            out["particle_steps"] = int(t["particle_steps"])
            out["core_ns_per_particle_step"] = {
                "dem": 1e9 * t["core_dem"] / t["particle_steps"],
                "all_in": 1e9 * t["core_all"] / t["particle_steps"]}
    return out


def cost_json(now: dict, before: dict | None, failed: bool, extra: dict) -> dict:
    """cost.json: the whole run's figures (this invocation's added to the totals of the
    checkpoint it resumed from; `whole_run` False where that checkpoint predates them and
    the figures are this invocation's only), this invocation's under `this_invocation`,
    what the run is (points, RVEs, ranks, threads), and `extra` (rebalancing)."""
    about = now["about"]
    out = report(add(before, now))
    out.update(points=about["points"], rves=about["rves"], ranks=about["ranks"],
               threads=about["threads"], whole_run=before is not None or
               not extra.pop("resumed", False))
    this = report(now)
    this["dem_seconds_per_step_max_rank"] = about["dem_seconds_max_rank"] / max(
        now["steps"], 1.0)
    this["reduced_bytes_per_rank_per_step"] = about["reduced_bytes"] / max(now["steps"], 1.0)
    if failed:
        this["failed_step"] = True  # its time and DEM work are counted in its figures
    out["this_invocation"] = this
    out.update(extra)
    return out


def format_cost(r: dict) -> str:
    """One line of this invocation's cost (stderr at the end of a run)."""
    t = r["this_invocation"]
    p = t["seconds_per_step"]
    text = (f"cost per step: total {p['total'] * 1e3:.3g} ms = MPM {p['mpm'] * 1e3:.3g} ms + "
            f"DEM {p['dem'] * 1e3:.3g} ms + communication {p['comm'] * 1e3:.3g} ms + waiting "
            f"{p['wait'] * 1e3:.3g} ms + other {p['other'] * 1e3:.3g} ms ({t['steps']} steps, "
            f"{r['ranks']} rank(s) x {r['threads']} thread(s))")
    if "core_seconds_per_rve_per_step" in t:
        text += (f"; {r['rves']} RVEs: {t['core_seconds_per_rve_per_step'] * 1e3:.3g} "
                 f"core-ms per RVE per step ({t['dem_steps_per_rve_per_step']:.3g} DEM steps, "
                 f"{100 * t['fraction_of_rves_stepped']:.3g} % of the RVEs stepped)")
    if "core_ns_per_particle_step" in t:
        ns = t["core_ns_per_particle_step"]
        text += (f"; {ns['all_in']:.3g} core-ns per particle-step all in "
                 f"({ns['dem']:.3g} in the DEM)")
    return text

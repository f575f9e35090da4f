"""`grainscale run`: load a case, build the solver, step it with progress, write outputs.

Outputs in --out: `case.resolved.toml` (every default filled in, package version),
`history.csv` (a row every output.interval, plus a final row when the run stops),
`frames/frame_NNNNN.vtu` + `frames.pvd` (and `frames/rigid_NNNNN.vtu` + `rigid.pvd`
for a rigid body), `cost.json` (time per step split into MPM, DEM and other), and
`checkpoint.h5` every N steps (and at the end of the run) when checkpointing is on.
`--resume` continues from checkpoint.h5: history rows and frames written after it are
dropped, so the continued run writes the same history.csv as an uninterrupted one.
"""

from __future__ import annotations

import json
import math
import sys
import time as wallclock
from pathlib import Path

import numba
import numpy as np
from tqdm import tqdm

from grainscale.config.base import ConfigError, resolved_toml
from grainscale.config.case import HISTORY_DEM, Case, load_case
from grainscale.coupling import materials as dem_materials
from grainscale.coupling.rve_material import RVEMaterial
from grainscale.io.checkpoint import read_checkpoint, write_checkpoint
from grainscale.io.history import History
from grainscale.io.vtk import PVDSeries, write_points_vtu
from grainscale.mpm.materials import KINDS
from grainscale.mpm.materials.base import p_q
from grainscale.mpm.setup import AXES, build_state
from grainscale.mpm.step import MPMState, SimulationError, kinetic_energy, step

CHECKPOINT = "checkpoint.h5"


# ----------------------------------------------------------------------- outputs
def history_values(case: Case, s: MPMState) -> dict[str, float]:
    """Every history quantity available for this case at the current state."""
    pts = s.points
    out = {"step": s.step, "time": s.time, "dt": s.last_dt,
           "kinetic_energy": kinetic_energy(pts)}
    # the body as one element: volume-averaged stress, mean strains (seed §4.1)
    vol = pts.vol.sum()
    sigma = np.einsum("p,pab->ab", pts.vol, pts.stress) / vol
    p, q = p_q(sigma[None])
    a = AXES[case.output.axial_axis]
    out.update(p=float(p[0]), q=float(q[0]), q_over_p=float(q[0] / p[0]) if p[0] > 0 else 0.0,
               axial_strain=float(1.0 - np.average(pts.F[:, a, a], weights=pts.vol0)),
               volumetric_strain=float(np.log(vol / pts.vol0.sum())))
    rve_fields = [m.point_fields() for m in s.materials if isinstance(m, RVEMaterial)]
    for key in HISTORY_DEM:  # means over the RVEs of every DEM material
        values = [f[key] for f in rve_fields if key in f]
        if values:
            out[key] = float(np.mean(np.concatenate(values)))
    col = case.output.column
    if col is not None:
        fa, ua = AXES[col.flow_axis], AXES[col.up_axis]
        edge = pts.x[:, fa] + pts.lp  # particle-domain edge, so the initial runout is 0
        front = float(np.quantile(edge, col.front_quantile)) if col.front_quantile < 1 \
            else float(edge.max())
        height = float((pts.x[:, ua] + pts.lp).max()) - col.base
        g = float(np.linalg.norm(case.solver.gravity))
        out.update(front=front, column_height=height,
                   runout_ratio=(front - col.wall - col.length) / col.length,
                   height_ratio=height / col.height,
                   t_over_tc=s.time / math.sqrt(col.height / g) if g > 0 else math.nan)
    if s.rigid is not None:
        f = s.rigid.force
        v = s.rigid.velocity
        n = v / np.linalg.norm(v) if np.any(v) else np.zeros(3)
        depth = float(np.dot(s.rigid.displacement, n))
        out.update(rigid_fx=f[0], rigid_fy=f[1], rigid_fz=f[2], rigid_depth=depth,
                   depth=depth, force=-float(np.dot(f, n)))  # resistance to the motion
    return out


def point_fields(s: MPMState) -> dict[str, np.ndarray]:
    """Per-point output: position, velocity, displacement, stress, p, q,
    eps_v = ln(V/V0), material index, and the materials' own fields."""
    pts = s.points
    p, q = p_q(pts.stress)
    fields = {"position": pts.x, "velocity": pts.v, "displacement": pts.x - pts.x0,
              "stress": pts.stress, "p": p, "q": q, "eps_v": np.log(pts.vol / pts.vol0),
              "material": pts.mat}
    for mat, ids in zip(s.materials, s.mat_points, strict=True):
        for k, a in mat.point_fields().items():
            if ids is None:
                fields[k] = a
            else:
                full = fields.setdefault(k, np.full((pts.n, *a.shape[1:]), np.nan))
                full[ids] = a
    return fields


# ---------------------------------------------------------------------- checkpoint
def save(path: Path, s: MPMState, counters: dict[str, int | float]) -> None:
    groups = {"points": s.points.arrays()}
    for i, m in enumerate(s.materials):
        groups[f"material_{i}"] = m.state()
    if s.rigid is not None:
        groups["rigid"] = {"x": s.rigid.x, "displacement": s.rigid.displacement,
                           "force": s.rigid.force}
    attrs = {"time": s.time, "step": s.step, "vmax": s.vmax, **counters}
    write_checkpoint(path, groups, attrs)


def restore(path: Path, s: MPMState) -> dict:
    groups, attrs = read_checkpoint(path)
    if groups["points"]["x"].shape != s.points.x.shape:
        raise ConfigError(f"{path}: checkpoint has {groups['points']['x'].shape[0]} points, "
                          f"the case builds {s.points.n}; was the case file changed?")
    for k, a in groups["points"].items():
        getattr(s.points, k)[...] = a
    for i, m in enumerate(s.materials):
        m.load_state(groups.get(f"material_{i}", {}))
    if s.rigid is not None:
        s.rigid.x[...] = groups["rigid"]["x"]
        s.rigid.displacement[...] = groups["rigid"]["displacement"]
        s.rigid.force[...] = groups["rigid"]["force"]
    s.time = float(attrs["time"])
    s.step = int(attrs["step"])
    s.vmax = float(attrs["vmax"])
    return attrs


# --------------------------------------------------------------------------- cost
def cost_report(s: MPMState, steps: int, step_seconds: float, wall_seconds: float) -> dict:
    """Time per step split into MPM, DEM and everything else (outputs, checkpoints), and
    the core-time one RVE costs per step (DEM wall time x threads / RVEs / steps)."""
    dem = sum(m.seconds for m in s.materials if isinstance(m, RVEMaterial))
    n_rve = sum(m.batch.n_rve for m in s.materials
                if isinstance(m, RVEMaterial) and m.batch is not None)
    threads = numba.get_num_threads()
    report = {
        "steps": steps, "points": int(s.points.n), "rves": int(n_rve), "threads": threads,
        "wall_seconds": wall_seconds,
        "seconds_per_step": {"mpm": (step_seconds - dem) / steps, "dem": dem / steps,
                             "other": (wall_seconds - step_seconds) / steps,
                             "total": wall_seconds / steps},
    }
    if n_rve:
        dem_steps = sum(m.rve_steps for m in s.materials if isinstance(m, RVEMaterial))
        report["core_seconds_per_rve_per_step"] = dem * threads / (n_rve * steps)
        report["dem_steps_per_rve_per_step"] = dem_steps / (n_rve * steps)
    return report


def format_cost(r: dict) -> str:
    t = r["seconds_per_step"]
    text = (f"cost per step: total {t['total'] * 1e3:.3g} ms = MPM {t['mpm'] * 1e3:.3g} ms + "
            f"DEM {t['dem'] * 1e3:.3g} ms + other {t['other'] * 1e3:.3g} ms "
            f"({r['steps']} steps, {r['threads']} threads)")
    if "core_seconds_per_rve_per_step" in r:
        text += (f"; {r['rves']} RVEs: {r['core_seconds_per_rve_per_step'] * 1e3:.3g} "
                 f"core-ms per RVE per step ({r['dem_steps_per_rve_per_step']:.0f} DEM steps)")
    return text


# --------------------------------------------------------------------------- run
def check_geometry(case: Case, case_dir: Path) -> None:
    """All checks of the solver set-up (points in the grid, boxes that select nodes, ...)
    before the packings of DEM materials are generated, which can take minutes."""
    probe = case.model_copy(deep=True)
    for m in probe.materials.values():
        if m.type == "dem":
            m.density = 1.0

    def stand_in(name, cfg, n, local=None):
        return KINDS["linear_elastic"](name, n, density=1.0, youngs_modulus=1.0,
                                       poisson_ratio=0.0)

    build_state(probe, case_dir, material_factory=stand_in)


def run_case(case_path, out, *, max_steps: int | None = None,
             checkpoint_every: int | None = None, resume: bool = False,
             progress: bool = True) -> int:
    """Run a case file; returns the exit code (0 done, 1 stopped by a simulation error)."""
    case_path = Path(case_path)
    out = Path(out)
    case = load_case(case_path)
    if case.solver.threads:
        numba.set_num_threads(min(case.solver.threads, numba.config.NUMBA_NUM_THREADS))
    every = checkpoint_every if checkpoint_every is not None else case.output.checkpoint_every
    ckpt = out / CHECKPOINT
    if resume and not ckpt.is_file():
        raise ConfigError(f"--resume: no checkpoint {str(ckpt)!r} to resume from")
    check_geometry(case, case_path.parent)  # every input check before long computations
    out.mkdir(parents=True, exist_ok=True)
    factory = dem_materials.prepare(case, case_path.parent, out, progress)
    s = build_state(case, case_path.parent, n_threads=numba.get_num_threads(),
                    material_factory=factory)
    for mat, ids in zip(s.materials, s.mat_points, strict=True):
        if hasattr(mat, "initial_stress"):  # RVEs start from their prepared stress
            s.points.stress[slice(None) if ids is None else ids] = mat.initial_stress()
    (out / "frames").mkdir(exist_ok=True)
    (out / "case.resolved.toml").write_text(resolved_toml(case))

    columns = ["step", *case.output.history]
    o = case.output
    t0, t_end = case.time.start, case.time.end
    frame_dt = o.frame_interval or o.interval
    if resume:
        c = restore(ckpt, s)
        # output slots (a step can span several intervals) and what was actually written
        n_rows, n_frames = int(c["rows"]), int(c["frames"])
        history = History(out / "history.csv", columns, case.title,
                          resume_rows=int(c["rows_written"]))
        pvd = PVDSeries.load(out / "frames.pvd", keep=int(c["frames_written"]))
        rigid_pvd = PVDSeries.load(out / "rigid.pvd", keep=int(c["rigid_frames_written"]))
    else:
        n_rows = n_frames = 0
        history = History(out / "history.csv", columns, case.title)
        pvd = PVDSeries(out / "frames.pvd")
        rigid_pvd = PVDSeries(out / "rigid.pvd")

    def write_row():
        history.write(history_values(case, s))

    def write_frame(k: int):
        f = out / "frames" / f"frame_{k:05d}.vtu"
        write_points_vtu(f, s.points.x, point_fields(s))
        pvd.add(s.time, f)
        if s.rigid is not None:  # the body's points as their own series
            f = out / "frames" / f"rigid_{k:05d}.vtu"
            v = np.tile(s.rigid.velocity_at(s.time), (len(s.rigid.x), 1))
            write_points_vtu(f, s.rigid.x, {"velocity": v})
            rigid_pvd.add(s.time, f)

    def counters() -> dict[str, int]:
        return {"rows": n_rows, "frames": n_frames, "rows_written": history.rows,
                "frames_written": len(pvd.entries),
                "rigid_frames_written": len(rigid_pvd.entries)}

    def due(n_done: int, interval: float) -> bool:
        return s.time >= t0 + n_done * interval - 1e-9 * interval

    fixed_dt = case.solver.dt
    steps_run = 0
    last_row_step = -1
    code = 0
    bar = tqdm(total=t_end - t0, initial=s.time - t0, disable=not progress, file=sys.stderr,
               unit="s", dynamic_ncols=True,
               bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} s [{elapsed}<{remaining}"
                          "{postfix}]")
    tick = wallclock.perf_counter()
    tick_step = s.step
    run_start = tick
    step_seconds = 0.0
    try:
        while True:
            # scheduled outputs at t0 + k * interval (the row of step 0 included)
            if due(n_rows, o.interval):
                write_row()
                last_row_step = s.step
                while due(n_rows, o.interval):
                    n_rows += 1
            if o.frames and due(n_frames, frame_dt):
                write_frame(n_frames)
                while due(n_frames, frame_dt):
                    n_frames += 1
            if every and s.step % every == 0 and s.step > 0 and steps_run > 0:
                save(ckpt, s, counters())
            if s.time >= t_end - 1e-12 * (t_end - t0) or (
                    max_steps is not None and steps_run >= max_steps):
                break
            limit = s.stable_dt()
            if fixed_dt is not None:
                if fixed_dt > limit:
                    raise SimulationError(f"step {s.step}: solver.dt = {fixed_dt} is above the "
                                          f"CFL limit {limit:.6g} s at t = {s.time:.6g} s")
                dt = fixed_dt
            else:
                dt = limit
            dt = min(dt, t_end - s.time)
            t_step = wallclock.perf_counter()
            step(s, dt)
            step_seconds += wallclock.perf_counter() - t_step
            steps_run += 1
            bar.update(dt)
            now = wallclock.perf_counter()
            if now - tick > 1.0:
                bar.set_postfix_str(f"step {s.step}, {(s.step - tick_step) / (now - tick):.0f} "
                                    "steps/s", refresh=False)
                tick, tick_step = now, s.step
    except SimulationError as err:
        print(f"grainscale: error: {err}", file=sys.stderr)
        code = 1
    finally:
        bar.close()
    if code == 0:
        if every:  # saved before the final row, so a resume drops that row again
            save(ckpt, s, counters())
        if last_row_step != s.step:
            write_row()  # final row (unscheduled)
    history.close()
    if steps_run:
        report = cost_report(s, steps_run, step_seconds, wallclock.perf_counter() - run_start)
        (out / "cost.json").write_text(json.dumps(report, indent=2) + "\n")
        if progress:
            print(format_cost(report), file=sys.stderr)
    return code

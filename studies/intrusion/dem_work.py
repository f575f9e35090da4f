"""Where a multiscale intrusion run spends its DEM work, and what that projects for a
larger case on the same near-field cells (seed.toml from a seed_quick.toml run).

    python studies/intrusion/dem_work.py RUN [--between 0.1 0.6]
        [--project examples/intrusion/seed.toml] [--ns 95]

The frames' `rve_steps` (the DEM steps each point's RVE has taken) at the frames nearest
the two d/R of `--between`, over the MPM steps between them (history.csv), give each
point's DEM steps per MPM step. Printed: their mean, median and the share of the work
done by the 10 % busiest points, in the fine cells (the smallest) and outside them, and
the particle-steps between the two frames (DEM steps x each RVE's spheres).

`--project CASE`: each point of CASE (filled as the loader does: points_per_cell^3 a
cell, at the sub-cell centres) takes the DEM steps per MPM step of the RUN's point
whose cell holds the same place relative to the intruder's axis and the bed's surface;
points beyond the RUN's bed take the RUN's median. This assumes a point's strain
increments are set by where it is, not by how many points share its cell (one point a
cell in RUN, points_per_cell^3 in CASE). The MPM steps of CASE are RUN's rate of steps
per simulated second (the same smallest cell) over CASE's time span; particle-steps are
the DEM steps times CASE's [rve] particles; core-hours at `--ns` ns per particle-step
(docs/performance.md: 94-99 ns for batches of 800-sphere RVEs on one core). The last
printed line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import grainscale as gs


def nearest_frame(result: gs.Result, d_over_r: float) -> tuple[float, object]:
    """(time, frame) of the frame whose d/R (history) is nearest d_over_r."""
    hist = result.history
    frames = result.frames()
    if not frames:
        raise SystemExit(f"{result.out}: no frames")
    d = np.interp([t for t, _ in frames], hist["time"], hist["depth_over_R"])
    return frames[int(np.argmin(np.abs(d - d_over_r)))]


def cells_of(axes: list[np.ndarray], x: np.ndarray) -> np.ndarray:
    """(N,3) indices of the grid cells holding the positions x (clipped to the grid)."""
    return np.stack([np.clip(np.searchsorted(a, x[:, k], side="right") - 1, 0, len(a) - 2)
                     for k, a in enumerate(axes)], axis=1)


def fill(case: gs.Case) -> np.ndarray:
    """(N,3) the points the loader puts in the case's first body (a box): n^3 at the
    sub-cell centres of every cell inside it, n = points_per_cell."""
    body = case.bodies[0]
    n = body.points_per_cell
    axes = case.grid.node_axes()
    sub = []
    for k, a in enumerate(axes):
        inside = (a[:-1] >= body.lo[k] - 1e-9) & (a[1:] <= body.hi[k] + 1e-9)
        a0, h = a[:-1][inside], np.diff(a)[inside]
        sub.append((a0[:, None] + (np.arange(n) + 0.5)[None, :] * (h / n)[:, None]).ravel())
    return np.stack(np.meshgrid(*sub, indexing="ij"), axis=-1).reshape(-1, 3)


def relative(case: gs.Case, x: np.ndarray) -> np.ndarray:
    """Positions relative to the intruder's axis (x, y) and the bed's surface (z)."""
    rigid = case.rigid
    axis = (rigid.center if rigid.shape == "cylinder" else
            [(lo + hi) / 2 for lo, hi in zip(rigid.lo, rigid.hi, strict=True)])
    return x - np.array([axis[0], axis[1], case.bodies[0].hi[2]])


def project(run_case: gs.Case, x0: np.ndarray, work: np.ndarray, target: gs.Case):
    """(work per target point, mask of those inside the run's grid): each point of
    `target` (fill()) takes `work` of the run's point (initially at x0, one a cell) whose
    cell holds the same place relative to the intruder and the surface; the others the
    median of `work`."""
    axes = run_case.grid.node_axes()
    origin = relative(run_case, np.array([[a[0] for a in axes]]))[0]
    rel_axes = [a - a[0] + origin[k] for k, a in enumerate(axes)]
    per_cell = np.full([len(a) - 1 for a in axes], np.nan)
    c = cells_of(rel_axes, relative(run_case, x0))
    per_cell[c[:, 0], c[:, 1], c[:, 2]] = work
    rel = relative(target, fill(target))
    inside = np.all([(rel[:, k] >= rel_axes[k][0]) & (rel[:, k] <= rel_axes[k][-1])
                     for k in range(3)], axis=0)
    fallback = float(np.median(work))
    out = np.full(len(rel), fallback)
    ci = cells_of(rel_axes, rel[inside])
    got = per_cell[ci[:, 0], ci[:, 1], ci[:, 2]]
    out[inside] = np.where(np.isnan(got), fallback, got)
    return out, inside


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--between", type=float, nargs=2, default=[0.1, 0.6], metavar="D_OVER_R")
    ap.add_argument("--project", type=Path, help="a larger case on the same near-field cells")
    ap.add_argument("--ns", type=float, default=95.0, help="ns per particle-step on one core")
    args = ap.parse_args()
    if not args.between[0] < args.between[1]:
        raise SystemExit(f"--between {args.between}: the first d/R must be the smaller")
    if not 0.0 < args.ns < 1e6:
        raise SystemExit(f"--ns {args.ns}: valid 0 < ns < 1e6")
    target = None
    if args.project is not None:
        try:
            target = gs.load_case(args.project)
        except gs.ConfigError as err:
            raise SystemExit(str(err)) from None
    try:
        result = gs.open_result(args.run)
        case, hist = result.case, result.history
    except (ValueError, gs.ConfigError) as err:
        raise SystemExit(str(err)) from None
    (t0, f0), (t1, f1) = (nearest_frame(result, d) for d in args.between)
    if "rve_steps" not in f1.point_data or "rve_steps" not in f0.point_data:
        raise SystemExit(f"{args.run}: the frames at t = {t0:g}, {t1:g} s have no rve_steps "
                         "(written by grainscale since the field was added)")
    if t1 <= t0:
        raise SystemExit(f"--between {args.between}: both d/R fall on the frame at t = {t0:g}")
    steps = np.interp([t0, t1], hist["time"], hist["step"])
    mpm_steps = steps[1] - steps[0]
    work = (np.ravel(f1.point_data["rve_steps"]) - np.ravel(f0.point_data["rve_steps"])) \
        / mpm_steps
    spheres = np.ravel(f1.point_data["rve_particles"])
    x0 = np.asarray(f0.points) - np.asarray(f0.point_data["displacement"])
    axes = case.grid.node_axes()
    ijk = cells_of(axes, x0)
    h = np.stack([np.diff(a)[ijk[:, k]] for k, a in enumerate(axes)], axis=1)
    fine = np.isclose(h.max(axis=1), min(np.diff(a).min() for a in axes))
    d = np.interp([t0, t1], hist["time"], hist["depth_over_R"])
    print(f"{args.run}: frames at t = {t0:.3f} and {t1:.3f} s (d/R {d[0]:.3f} to {d[1]:.3f}), "
          f"{mpm_steps:.0f} MPM steps; DEM steps per RVE and MPM step:")
    regions = {}
    for name, mask in (("all", np.ones(len(work), bool)), ("fine cells", fine),
                       ("graded cells", ~fine)):
        if not mask.any():  # a uniform grid: every cell is a fine one
            continue
        w = np.sort(work[mask])[::-1]
        top = w[:max(1, len(w) // 10)].sum() / w.sum() if w.sum() > 0 else float("nan")
        regions[name] = {"points": int(mask.sum()), "mean": float(w.mean()),
                         "median": float(np.median(w)), "max": float(w.max()),
                         "top10_share": float(top)}
        print(f"  {name:12s} {mask.sum():6d} points: mean {w.mean():7.2f}, median "
              f"{np.median(w):6.2f}, max {w.max():7.1f}; the busiest 10 % do {top:.0%}")
    out = {"run": str(args.run), "d_over_R": [float(v) for v in d], "mpm_steps": mpm_steps,
           "regions": regions}
    out["particle_steps"] = float((work * spheres).sum() * mpm_steps)
    print(f"  {out['particle_steps']:.3e} particle-steps between the two frames")
    if target is not None:
        tw, inside = project(case, x0, work, target)
        fallback = float(np.median(work))
        rate = mpm_steps / (t1 - t0)  # MPM steps per simulated second
        n_steps = rate * (target.time.end - target.time.start)
        ps = float(tw.mean() * len(tw) * n_steps * target.rve.particles)
        core_h = ps * args.ns * 1e-9 / 3600.0
        out["projection"] = {
            "case": str(args.project), "points": len(tw), "inside_run": int(inside.sum()),
            "dem_steps_per_rve_step": float(tw.mean()), "mpm_steps": n_steps,
            "particle_steps": ps, "core_hours": core_h, "ns": args.ns}
        print(f"{args.project}: {len(tw):,} points ({inside.sum():,} inside the run's bed, the "
              f"rest at its median {fallback:.2f}); {tw.mean():.2f} DEM steps per RVE and MPM "
              f"step; {n_steps:,.0f} MPM steps; {ps:.2e} particle-steps of "
              f"{target.rve.particles} spheres: {core_h:,.0f} core-hours at {args.ns:g} ns "
              f"({core_h / 64:.1f} h on 64 cores)")
    print(json.dumps(out))


if __name__ == "__main__":
    main()

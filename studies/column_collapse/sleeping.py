"""Sleeping RVEs in the quick column collapse (docs/coupling.md, docs/validation.md §2.3).

    python studies/column_collapse/sleeping.py run --out DIR [--tolerance 1e-6]
        [--max-deferred 20] [--cfl-offset 0] [--threads N] [--case quick.toml]
        [--velocity-update apic] [--particles N] [--one-layer] [--rve-seed N]
        [--points-per-cell N]
    python studies/column_collapse/sleeping.py compare RUN [RUN ...] [--after 3]
    python studies/column_collapse/sleeping.py why RUN --out COPY [--steps 100]

`run`: the case (default examples/column_collapse/quick.toml) with sleeping RVEs
(materials.sand.update_tolerance, max_deferred_steps; --tolerance 0: every RVE every
step, the case as shipped) and the cost columns (dem_steps_per_rve, updates_per_rve) in
its history, cfl times (1 + --cfl-offset) (a round-off realisation: 1e-9 and -1e-9 give
the realisations of §2.3), with APIC where --velocity-update apic, RVEs of --particles
spheres where given, with --one-layer the slice one point thick (half the RVEs: the
bodies end half a cell above their base in y, one layer of points between the side walls
at the nodes y = 0 and one cell, which hold every point's v_y at 0), with --rve-seed the
RVE packings generated from another seed ([rve] seed: a packing realisation, where the
cfl offset leaves the packings as they are), with --points-per-cell N^3 points a cell
(N = 1: the cell's one point cannot carry a share of its cell's weight apart from the
others', validation §2.3), into DIR; resumed from
DIR's newest checkpoint where it holds one. `compare`: per run,
studies/column_spread.py's measures at the last row (front, 99 % and 95 % of the mass,
H_f/H_i) and the DEM cost: DEM steps per RVE and MPM step, and the
share of RVEs stepped, over the run and after --after tau_c (from the history's
cumulative cost columns; cost.json covers one invocation). The last line is one JSON
object. `why`: what keeps RVEs of a finished run awake (the function's docstring), over
--steps more MPM steps of a copy of it; one JSON object.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np

import grainscale as gs
from grainscale.analysis import read_columns

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "studies"))
from column_spread import measures  # noqa: E402

QUICK = ROOT / "examples" / "column_collapse" / "quick.toml"
COST = ["dem_steps_per_rve", "updates_per_rve"]


def with_apic(c: gs.Case) -> gs.Case:
    """`c` with APIC instead of its transfer, in place (APIC has no relaxation time: the
    solver table rebuilt without it)."""
    keep = c.solver.model_dump(exclude_unset=True)
    keep.pop("velocity_relaxation_time", None)
    c.solver = type(c.solver)(**{**keep, "velocity_update": "apic"})
    c.title += ", APIC"
    return c


def with_points_per_cell(c: gs.Case, n: int) -> gs.Case:
    """The case with n^3 points a cell in every body (in place; returned)."""
    for b in c.bodies:
        b.points_per_cell = n
    return c


def with_one_layer(c: gs.Case) -> gs.Case:
    """The slice one point thick: each box body, one cell thick in y from a node plane,
    ends one sub-cell above its base, so one layer of points lies between the side walls
    (the case's rollers at both node planes, v_y = 0). With v_y = 0 and no stress
    coupling the planes (sigma_xy = sigma_yz = 0), both node planes get mass and force in
    proportion to their weight S_y and so the same acceleration, with one point layer as
    with n: a continuum flows the same to round-off (tests/test_grid_twin.py). An RVE's
    sigma_xy and sigma_yz (fabric, noise) are not zero: they push the two planes apart,
    in the two-layer slice from the sum of two RVEs on planes of equal mass, here from one
    RVE on planes of mass 3:1. So RVEs are sampled once per (x, z) place instead of
    twice, and their out-of-plane shear drives the planes somewhat harder: a
    discretisation of its own, compared with the two-layer slice in docs/validation.md
    §2.3."""
    h = c.grid.cell_size[1] if isinstance(c.grid.cell_size, tuple) else c.grid.cell_size
    if h is None:
        raise SystemExit("--one-layer: the grid is not uniform (no grid.cell_size)")
    for b in c.bodies:
        y = (b.lo[1], b.hi[1]) if b.shape == "box" else None
        planes = (y[0] - c.grid.origin[1]) / h if y else 0.0
        if not y or abs(y[1] - y[0] - h) > 1e-9 * h or abs(planes - round(planes)) > 1e-9:
            raise SystemExit(f"--one-layer: a body must be a box one cell ({h} m) thick in y "
                             f"from a node plane, not a {b.shape} with y in {y}")
    n = [b.points_per_cell for b in c.bodies]

    def tables(t: dict) -> None:
        for b, k in zip(t["bodies"], n, strict=True):
            b["hi"][1] = b["lo"][1] + h / k

    c = c.edited(tables)
    c.title += ", one layer of points"
    return c


def sleeping_case(case: Path, tolerance: float, max_deferred: int, cfl_offset: float,
                  velocity_update: str | None = None, particles: int | None = None,
                  one_layer: bool = False, rve_seed: int | None = None,
                  points_per_cell: int | None = None) -> gs.Case:
    c = gs.load_case(case)
    if points_per_cell is not None:
        with_points_per_cell(c, points_per_cell)
        c.title += f", {points_per_cell}^3 points a cell"
    if rve_seed is not None:
        c.rve.seed = rve_seed
        c.title += f", packings of seed {rve_seed}"
    if one_layer:
        c = with_one_layer(c)
    if particles is not None:  # RVEs of another size, generated at it
        c.rve.particles = particles
        c.title += f", RVEs of {particles} spheres"
    if velocity_update == "apic":
        with_apic(c)
    elif velocity_update is not None and velocity_update != c.solver.velocity_update:
        raise SystemExit(f"--velocity-update {velocity_update}: the case has "
                         f"{c.solver.velocity_update!r}; only 'apic' is substituted")
    for m in c.materials.values():
        if m.type == "dem":
            m.update_tolerance = tolerance
            m.max_deferred_steps = max_deferred
    c.solver.cfl *= 1.0 + cfl_offset
    c.output.history = [*c.output.history, *(k for k in COST if k not in c.output.history)]
    if tolerance > 0:
        c.title += f", sleeping RVEs (tolerance {tolerance:g}, {max_deferred} steps)"
    return c


def run(args) -> None:
    case = sleeping_case(args.case, args.tolerance, args.max_deferred, args.cfl_offset,
                         args.velocity_update, args.particles, args.one_layer,
                         args.rve_seed, args.points_per_cell).check()
    resume = any((args.out / n).is_file() for n in ("checkpoint.h5", "checkpoint.prev.h5"))
    gs.run(case, args.out, resume=resume, threads=args.threads)


def cost(run_dir: Path, after: float) -> dict:
    """DEM steps per RVE and MPM step and the share of RVEs stepped, over the run and
    after t/tau_c = `after`, from the history's cumulative columns."""
    h = read_columns(run_dir / "history.csv")
    missing = [k for k in COST if k not in h]
    if missing:
        raise SystemExit(f"{run_dir}/history.csv: no {missing} (run it with this script)")
    step = h["step"]
    out = {"dem_steps_per_rve_per_step": float(h["dem_steps_per_rve"][-1] / step[-1]),
           "fraction_of_rves_stepped": float(h["updates_per_rve"][-1] / step[-1])}
    k = int(np.searchsorted(h["t_over_tc"], after))
    if k < len(step) - 1:
        n = step[-1] - step[k]
        out[f"after_{after:g}_tau_c"] = {
            "dem_steps_per_rve_per_step": float(
                (h["dem_steps_per_rve"][-1] - h["dem_steps_per_rve"][k]) / n),
            "fraction_of_rves_stepped": float(
                (h["updates_per_rve"][-1] - h["updates_per_rve"][k]) / n),
            "from_t_over_tc": float(h["t_over_tc"][k])}
    return out


def why(args) -> None:
    """`why`: a copy of a finished sleeping run (args.run) continued --steps MPM steps into
    args.out, recording after each step, from the points' increments (s.dH) and DEM update
    counters (the material's `rve_updates` field): which RVEs were stepped, which of those
    had composed an increment of at least the tolerance since their last update or had
    waited max_deferred_steps (the rest were stepped because their grains were not at
    rest), which took more than the tolerance in that one step, and which points are
    loose (every stress component at most 0.01 of the preparation pressure). The first
    continued step only gives the counters the others start from: `steps` - 1 are measured."""
    if args.out.exists():
        raise SystemExit(f"--out {args.out}: exists (a copy of RUN is made there)")
    if args.steps < 2:
        raise SystemExit(f"--steps {args.steps}: at least 2 (the first gives the state "
                         "the others start from)")
    ran = gs.open_result(args.run)

    def as_given(t: dict) -> None:  # a dem material's density is its packings'
        for m in t["materials"].values():
            if m.get("type") == "dem":
                m.pop("density", None)

    case = ran.case.edited(as_given)
    dem = next(m for m in case.materials.values() if m.type == "dem")
    tol, cap = dem.update_tolerance, dem.max_deferred_steps
    if tol <= 0:
        raise SystemExit(f"{args.run}: update_tolerance = {tol}: no sleeping RVEs")
    shutil.copytree(args.run, args.out)
    last = int(ran.history["step"][-1])
    case.time.end += 1.0  # the step count ends it
    loose_scale = 0.01 * case.rve.preparation.pressure
    seen = {}
    rows = []

    def on_step(st) -> None:
        m = st.materials[0]
        if len(st.dH) != m.n_points:
            raise SystemExit(f"{args.run}: {len(st.dH)} points, {m.n_points} in its first "
                             "material: `why` reads runs of one material")
        updates = m.point_fields()["rve_updates"]
        if seen:  # the step just taken, judged from the state it started from
            dH = st.dH
            H = dH + seen["H"] + np.einsum("pab,pbc->pac", dH, seen["H"])
            stepped = updates > seen["updates"]
            by_increment = np.abs(H).max(axis=(1, 2)) >= tol
            by_cap = seen["waited"] + 1 >= cap
            size = np.abs(dH).max(axis=(1, 2))
            sigma = st.points.stress
            rows.append({"stepped": stepped.mean(),
                         "stepped_by_increment": (stepped & by_increment).mean(),
                         "stepped_by_cap": (stepped & by_cap & ~by_increment).mean(),
                         "stepped_not_at_rest": (stepped & ~by_increment & ~by_cap).mean(),
                         "one_step_above_tolerance": (size >= tol).mean(),
                         "loose": (np.abs(sigma).max(axis=(1, 2)) <= loose_scale).mean(),
                         "increment_median": float(np.median(size)),
                         "increment_p90": float(np.quantile(size, 0.9))})
        # what the solver carries into the next step: each RVE's composed increment since
        # its last update and the steps it has waited (restored from the checkpoint too)
        seen.update(H=m.H_acc.copy(), waited=m.deferred.copy(), updates=updates)

    gs.run(case, args.out, resume=True, allow_changed=["time.end"],
           max_steps=last + args.steps, progress=False, on_step=on_step)
    out = {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}
    out.update(run=str(args.run), from_step=last, steps=len(rows), tolerance=tol,
               t_over_tc=float(gs.open_result(args.out).history["t_over_tc"][-1]))
    print(json.dumps(out))


def compare(args) -> None:
    rows = []
    for r in args.runs:
        length = gs.open_result(r).case.output.column.length
        rows.append({**measures(r, length), **cost(r, args.after)})
        print(json.dumps(rows[-1]))
    print(json.dumps({"runs": rows}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--case", type=Path, default=QUICK)
    r.add_argument("--tolerance", type=float, default=1e-6)
    r.add_argument("--max-deferred", type=int, default=20)
    r.add_argument("--cfl-offset", type=float, default=0.0)
    r.add_argument("--velocity-update", choices=["apic", "aflip"],
                   help="apic: the case with APIC (no relaxation time) instead of its own")
    r.add_argument("--particles", type=int,
                   help="the case's RVEs at this size ([rve] particles), generated at it")
    r.add_argument("--one-layer", action="store_true",
                   help="the slice one point thick instead of the case's one cell")
    r.add_argument("--rve-seed", type=int,
                   help="[rve] seed: the packings of another seed (a packing realisation)")
    r.add_argument("--points-per-cell", type=int,
                   help="n of the bodies' n^3 points a cell instead of the case's")
    r.add_argument("--threads", type=int)
    c = sub.add_parser("compare")
    c.add_argument("runs", type=Path, nargs="+")
    c.add_argument("--after", type=float, default=3.0, help="t/tau_c of the late window")
    w = sub.add_parser("why")
    w.add_argument("run", type=Path, help="a finished run of `run` with a tolerance")
    w.add_argument("--out", type=Path, required=True, help="its copy, continued")
    w.add_argument("--steps", type=int, default=100)
    args = ap.parse_args()
    {"run": run, "compare": compare, "why": why}[args.cmd](args)


if __name__ == "__main__":
    main()

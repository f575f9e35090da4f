"""Adaptive RVE updates: what they save and what they change, on a quasi-static case.

Runs a case file's first N MPM steps with its DEM materials' `update_tolerance` set to
the given value (0: every RVE every step), and prints the DEM steps per RVE and MPM
step, the fraction of RVEs stepped per MPM step, the wall time and the last history
row (the intruder's force and depth where the case has them). `--compare` reads two or
more such outputs and prints each against the first as ratios. DEM step counts are
deterministic (they do not depend on the machine or its load); wall times do, so
compare those only between runs made side by side on one machine. The last line
printed is one JSON object.

    python benchmarks/adaptive_updates.py examples/intrusion/quick.toml --steps 2000 \\
        --tolerance 0 --out /tmp/full
    python benchmarks/adaptive_updates.py examples/intrusion/quick.toml --steps 2000 \\
        --tolerance 2e-6 --out /tmp/adaptive
    python benchmarks/adaptive_updates.py --compare /tmp/full /tmp/adaptive
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import grainscale as gs
from grainscale.analysis import read_columns


def run(case_path: str, steps: int, tolerance: float, deferred: int, out: Path,
        threads: int | None, strain: float | None = None, damping: float | None = None
        ) -> dict:
    """One run of the case's first `steps` MPM steps (with `strain` per DEM step and the
    RVE's local `damping` where given); its figures, also written to out/adaptive.json."""
    case = gs.load_case(case_path)
    if damping is not None:
        case.rve.damping = damping
    dem = [name for name, m in case.materials.items() if m.type == "dem"]
    if not dem:
        raise SystemExit(f"{case_path}: no dem material")
    for name in dem:
        if strain is not None:
            case.materials[name].strain_per_substep = strain
        case.materials[name].update_tolerance = tolerance
        case.materials[name].max_deferred_steps = deferred
    t0 = time.perf_counter()
    gs.run(case, out, max_steps=steps, progress=False, threads=threads)
    wall = time.perf_counter() - t0
    cost = json.loads((out / "cost.json").read_text())
    hist = read_columns(out / "history.csv")
    last = {k: float(v[-1]) for k, v in hist.items()}
    res = {"case": case_path, "steps": cost["steps"], "tolerance": tolerance,
           "strain_per_substep": case.materials[dem[0]].strain_per_substep,
           "rve_damping": case.rve.damping,
           "max_deferred_steps": deferred, "wall_seconds": wall, "threads": cost["threads"],
           "dem_steps_per_rve_per_step": cost["dem_steps_per_rve_per_step"],
           "fraction_of_rves_stepped": cost["fraction_of_rves_stepped"],
           "seconds_per_step": cost["seconds_per_step"], "last_row": last}
    (out / "adaptive.json").write_text(json.dumps(res, indent=1))
    return res


def compare(outs: list[Path]) -> list[dict]:
    """Each run against the first: ratios of DEM steps and wall time, and the relative
    change of the last row's force (where there is one)."""
    runs = [json.loads((o / "adaptive.json").read_text()) for o in outs]
    ref = runs[0]
    rows = []
    for r in runs:
        row = {"out": str(r.get("out", "")), "tolerance": r["tolerance"],
               "dem_steps_per_rve_per_step": r["dem_steps_per_rve_per_step"],
               "fraction_of_rves_stepped": r["fraction_of_rves_stepped"],
               "dem_steps_ratio": ref["dem_steps_per_rve_per_step"]
               / r["dem_steps_per_rve_per_step"],
               "wall_ratio": ref["wall_seconds"] / r["wall_seconds"]}
        if "force" in r["last_row"] and ref["last_row"].get("force"):
            row["force"] = r["last_row"]["force"]
            row["force_change"] = r["last_row"]["force"] / ref["last_row"]["force"] - 1.0
        rows.append(row)
        print(f"tolerance {r['tolerance']:g}, {r.get('strain_per_substep', 2e-6):g} per DEM "
              f"step, damping {r.get('rve_damping', 0.2):g}: "
              f"{r['dem_steps_per_rve_per_step']:.3f} DEM steps "
              f"per RVE and MPM step ({row['dem_steps_ratio']:.2f}x fewer), "
              f"{100 * r['fraction_of_rves_stepped']:.1f} % of RVEs stepped, wall "
              f"{r['wall_seconds']:.0f} s ({row['wall_ratio']:.2f}x)"
              + (f", force {row['force']:.6g} N ({100 * row['force_change']:+.2f} %)"
                 if "force" in row else ""))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", nargs="?", help="a case file with a quasi-static dem material")
    ap.add_argument("--steps", type=int, default=2000, help="MPM steps to run")
    ap.add_argument("--tolerance", type=float, default=0.0, help="update_tolerance")
    ap.add_argument("--max-deferred", type=int, default=20, help="max_deferred_steps")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--strain-per-substep", type=float, help="instead of the case's")
    ap.add_argument("--rve-damping", type=float, help="[rve] damping instead of the case's")
    ap.add_argument("--out", type=Path, help="the run's folder")
    ap.add_argument("--compare", type=Path, nargs="+", help="outputs of earlier runs")
    args = ap.parse_args()
    if args.compare:
        print(json.dumps(compare(args.compare)))
        return
    if args.case is None or args.out is None:
        raise SystemExit("give a case and --out, or --compare OUT OUT ...")
    if args.steps < 1:
        raise SystemExit(f"--steps {args.steps}: valid >= 1")
    res = run(args.case, args.steps, args.tolerance, args.max_deferred, args.out,
              args.threads, args.strain_per_substep, args.rve_damping)
    res["out"] = str(args.out)
    (args.out / "adaptive.json").write_text(json.dumps(res, indent=1))
    print(json.dumps(res))


if __name__ == "__main__":
    main()

"""An intrusion case on another grid, in another bed or with another intruder surface,
written as a new case file.

    python studies/intrusion/reshape.py CASE --out NEW.toml
        [--cell-size H] [--points-per-cell N] [--quarter WIDTH DEPTH] [--to-depth D_OVER_R]
        [--contact nodes|penalty] [--friction MU]

`--quarter` sets the quarter's side and the bed's depth [m]; the intruder's base stays
on the bed's surface and the probes keep their depth below it, so the new case is the
same experiment in a wider or deeper bed. `--to-depth` ends the run when the intruder
reaches that d/R (time.end from its ramp and velocity). `--contact` and `--friction`
replace the intruder's contact (`nodes`: no-slip; `penalty` with the Coulomb coefficient
`--friction`, default 0: smooth). For example the quick multiscale cylinder in the
seed's 5 x 5 m quarter of a 4 m bed (51,200 RVEs; docs/validation.md §3), or
seed_quick's cylinder made rough:

    python studies/intrusion/reshape.py examples/intrusion/quick.toml --quarter 5 4 \
        --out seed_bed.toml
    python studies/intrusion/reshape.py examples/intrusion/seed_quick.toml \
        --contact penalty --friction 0.5 --to-depth 0.45 --out rough.toml
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import grainscale as gs

ABOVE = 1.25  # m of grid above the bed's surface (room for the intruder)


def reshape(case: gs.Case, cell: float | None = None, points_per_cell: int | None = None,
            width: float | None = None, depth: float | None = None) -> gs.Case:
    """The intrusion case on cells of `cell` m with `points_per_cell`^3 points a cell, a
    width x width quarter of a bed `depth` deep [m] (each default: the case's own), the
    intruder's base and the probes kept at their depth below the bed's surface. Changes
    `case` in place (each edit validated) and returns it. A graded grid (node lists) is
    kept as it is; its cells or bed are not rescaled (SystemExit naming the option)."""
    body, rigid = case.bodies[0], case.rigid
    if points_per_cell is not None:
        body.points_per_cell = points_per_cell
    if cell is None and width is None and depth is None:
        return case
    if case.grid.cell_size is None:
        asked = "--cell-size" if cell is not None else "--quarter"
        raise SystemExit(f"{asked}: {case.title!r} has a graded grid (nodes_x/y/z), which "
                         "is not rescaled; valid only for a case with cell_size and cells")
    cell = case.grid.cell_size if cell is None else cell
    width = body.hi[0] if width is None else width
    lift = 0.0 if depth is None else depth - body.hi[2]
    depth = body.hi[2] + lift
    case.grid.cell_size = cell
    case.grid.cells = [round(width / cell), round(width / cell), round((depth + ABOVE) / cell)]
    body.hi = [width, width, depth]
    for key in ("center", "lo", "hi"):
        if getattr(rigid, key, None) is not None:
            x, y, z = getattr(rigid, key)
            setattr(rigid, key, [x, y, z + lift])
    for probe in case.output.probes:
        x, y, z = probe.position
        probe.position = [x, y, z + lift]
    return case


def end_time_for(case: gs.Case, depth_over_r: float) -> float:
    """time.end [s] at which the intruder, ramped linearly from start_time (default
    time.start) to its velocity over ramp_time and steady after, has gone
    depth_over_r x R deep."""
    rigid = case.rigid
    speed = math.hypot(*rigid.velocity)
    ramp = rigid.ramp_time
    start = case.time.start if rigid.start_time is None else rigid.start_time
    depth = depth_over_r * rigid.radius
    if depth <= speed * ramp / 2:
        return start + (2 * depth * ramp / speed) ** 0.5
    return start + ramp / 2 + depth / speed


def to_depth(case: gs.Case, depth_over_r: float) -> gs.Case:
    """End the case when the intruder is depth_over_r radii deep (in place); SystemExit
    naming --to-depth where that is not inside the bed."""
    bed, radius = case.bodies[0].hi[2], getattr(case.rigid, "radius", None)
    if radius is None:
        raise SystemExit(f"--to-depth {depth_over_r}: d/R needs a cylinder's radius; the "
                         f"intruder of {case.title!r} is a {case.rigid.shape}")
    if not 0.0 < depth_over_r * radius < bed:
        raise SystemExit(f"--to-depth {depth_over_r}: valid 0 < d/R < {bed / radius:g} "
                         "(the bed's depth over R)")
    case.time.end = end_time_for(case, depth_over_r)
    case.title += f", to d/R = {depth_over_r:g}"
    return case


def surface(case: gs.Case, contact: str, friction: float = 0.0) -> gs.Case:
    """The intruder's contact replaced (in place): `nodes` (no-slip) or `penalty` with
    Coulomb coefficient `friction`; the title says which."""
    rigid = case.rigid
    if contact == "nodes":
        for key in ("penalty", "damping_ratio", "friction"):  # penalty-only keys
            if key in rigid.model_fields_set:
                setattr(rigid, key, type(rigid).model_fields[key].default)
        rigid.contact = "nodes"
        case.title += ", no-slip intruder"
    else:
        rigid.contact = "penalty"
        rigid.friction = friction
        case.title += f", penalty contact with friction {friction:g}"
    return case


def check_args(cell: float | None, points_per_cell: int | None,
               quarter: list[float] | None, contact: str | None = None,
               friction: float | None = None) -> None:
    """Refuse a grid or bed the intruder (R = 0.5 m) does not fit, or a friction without
    the penalty contact, naming the option."""
    if cell is not None and not 0.0 < cell <= 0.5:
        raise SystemExit(f"--cell-size {cell}: valid 0 < h <= 0.5 m")
    if points_per_cell is not None and not 1 <= points_per_cell <= 4:
        raise SystemExit(f"--points-per-cell {points_per_cell}: valid 1 to 4")
    if quarter is not None and not all(x > 1.0 for x in quarter):
        raise SystemExit(f"--quarter {quarter}: valid side and depth > 1 m (R = 0.5 m)")
    if friction is not None and not (0.0 <= friction <= 2.0 and contact == "penalty"):
        raise SystemExit(f"--friction {friction}: valid 0 to 2, with --contact penalty")


def add_args(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--cell-size", type=float, help="m (default: the case's)")
    ap.add_argument("--points-per-cell", type=int, help="n: n^3 points a cell")
    ap.add_argument("--quarter", type=float, nargs=2, metavar=("WIDTH", "DEPTH"),
                    help="the quarter's side and the bed's depth, m")
    ap.add_argument("--to-depth", type=float, metavar="D_OVER_R",
                    help="end when the intruder is this many radii deep")
    ap.add_argument("--contact", choices=["nodes", "penalty"],
                    help="the intruder's contact (default: the case's)")
    ap.add_argument("--friction", type=float, help="penalty contact's Coulomb coefficient")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", type=Path)
    ap.add_argument("--out", type=Path, required=True, help="the new case file")
    add_args(ap)
    args = ap.parse_args()
    check_args(args.cell_size, args.points_per_cell, args.quarter, args.contact,
               args.friction)
    if args.out.exists():
        raise SystemExit(f"--out {args.out}: exists; not overwritten")
    try:
        case = gs.load_case(args.case)
    except gs.ConfigError as err:
        raise SystemExit(f"{args.case}: {err}") from None
    width, depth = args.quarter if args.quarter is not None else (None, None)
    reshape(case, args.cell_size, args.points_per_cell, width, depth)
    if args.to_depth is not None:
        to_depth(case, args.to_depth)
    if args.contact is not None:
        surface(case, args.contact, args.friction or 0.0)
    if args.quarter is not None:
        case.title += f" in a {width:g} x {width:g} m quarter of a {depth:g} m bed"
    case.check().save(args.out)
    print(args.out)


if __name__ == "__main__":
    main()

"""How much the pressure scatters from point to point under an intruder, frame by frame.

    python studies/intrusion/stress_scatter.py RUN [RUN ...] [--depth 0.3] [--width 1.0]

For every frame during the intrusion (d/R > 0), the points below the intruder's base (at
most `--depth` m below it) and within `--width` radii of its axis (x, y >= 0, the
quarter model) are compared with their neighbours by initial position (the face
neighbours on the grid, analysis.neighbour_median): printed are the points' median
pressure, the median of |p - p_nb| / p_nb (p_nb the neighbours' median pressure) and
the share of points with p < 0.2 p_nb, which on a smooth field would be ~0 and ~0; in
a multiscale run also the share of RVEs with a coordination number below 2 (a contact
network that has opened), among all and among those low points. It tells what one probe RVE's
stress (examples/intrusion/force_chains.py) samples: a field, or a point of a field
that jumps from point to point. Works on multiscale and continuum runs alike. The last
printed line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import grainscale as gs
from grainscale import analysis


def scatter(x: np.ndarray, x0: np.ndarray, p: np.ndarray, base: float, radius: float,
            depth: float, width: float, coordination: np.ndarray | None = None) -> dict:
    """The measures of one frame: positions x and initial positions x0 (N,3) [m],
    pressure p (N) [Pa], the intruder's base height `base` [m] and radius [m]; with the
    RVEs' coordination numbers (N), also the share of the points below Z = 2 (an RVE
    whose contact network has opened)."""
    r = np.hypot(x[:, 0], x[:, 1])
    which = np.flatnonzero((r < width * radius) & (x[:, 2] < base) & (x[:, 2] > base - depth))
    if which.size == 0:
        return {"points": 0}
    nb = analysis.neighbour_median(x0, p, which)
    ok = nb > 0.0
    low = p[which] < 0.2 * nb
    m = {"points": int(which.size), "median_p": float(np.median(p[which])),
         "median_rel_dev": float(np.median(np.abs(p[which][ok] - nb[ok]) / nb[ok])),
         "share_below_fifth": float(np.mean(low))}
    if coordination is not None:
        z = coordination[which]
        m["share_z_below_2"] = float(np.mean(z < 2.0))
        m["share_below_fifth_with_z_below_2"] = float(np.mean(z[low] < 2.0)) if low.any() \
            else float("nan")
    return m


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--depth", type=float, default=0.3, help="m below the base")
    ap.add_argument("--width", type=float, default=1.0, help="radii from the axis")
    args = ap.parse_args(argv)
    if args.depth <= 0 or args.width <= 0:
        raise SystemExit(f"--depth {args.depth} --width {args.width}: valid: both > 0")
    report = {}
    for run in args.runs:
        try:
            result = gs.open_result(run)
            hist, case = result.history, result.case
        except (ValueError, gs.ConfigError) as err:
            raise SystemExit(str(err)) from None
        if case.rigid is None or case.rigid.shape != "cylinder":
            raise SystemExit(f"{run}: the case has no [rigid] cylinder")
        rows = []
        print(f"{run}:\n     t (s)   d/R  points  median p (kPa)  median |p-p_nb|/p_nb"
              "  share p < p_nb/5  share Z < 2 (of those)")
        for t, mesh in result.frames():
            d_over_r = float(np.interp(t, hist["time"], hist["depth_over_R"]))
            if d_over_r <= 0.0:
                continue
            x = np.asarray(mesh.points, float)
            x0 = x - np.asarray(mesh.point_data["displacement"], float)
            base = case.rigid.center[2] - float(np.interp(t, hist["time"], hist["depth"]))
            z = mesh.point_data.get("coordination")
            m = scatter(x, x0, np.asarray(mesh.point_data["p"], float).ravel(), base,
                        case.rigid.radius, args.depth, args.width,
                        None if z is None else np.asarray(z, float).ravel())
            if m["points"] == 0:
                continue
            rows.append(m | {"time": float(t), "depth_over_R": d_over_r})
            print(f"  {t:8.3f} {d_over_r:5.2f} {m['points']:7d} {m['median_p'] / 1e3:12.1f}"
                  f" {m['median_rel_dev']:18.2f} {m['share_below_fifth']:17.2f}"
                  + (f" {m['share_z_below_2']:12.2f} ({m['share_below_fifth_with_z_below_2']:.2f})"
                     if "share_z_below_2" in m else ""))
        report[str(run)] = rows
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

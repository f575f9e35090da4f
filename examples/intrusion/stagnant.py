"""The stagnant zone under an intruder: the RVEs' rotation rate on the symmetry plane
(seed Fig. 15).

    python examples/intrusion/stagnant.py OUT [--depths 0.5 1.0] [--box X0 X1 Z0 Z1]
        [--field rotation_rate|velocity] [--png OUT/stagnant.png]

Reads the run's VTK frames (frames.pvd) and, for the frames nearest the requested d/R,
draws the points of the first layer next to the symmetry plane y = 0 (y below one point
spacing of the first cell along y) as tiles of their point spacing in x and z (on a
graded grid, their cell's), coloured by `rotation_rate`, the mean angular speed of the
RVE's grains (rad/s, seed Eq. 15), with the intruder's section outlined: a stagnant cone
moves with the intruder and its grains barely roll, while the shear zone around it rolls
fast. `--field velocity` colours the points instead by the share of the intruder's
speed they move with along its direction (v . e / |v_rigid|, e its direction of travel:
1 in a zone carried along with it), which a continuum run has too. `--box` draws only
that part of the plane [m] (default: the grid). Depth and d/R come from history.csv.

For each frame it also measures the zone carried with the intruder (`carried_depth`):
how far below the base, next to the axis (0.05 R) and at 0.9 R, the points move with
at least `--carried` (default 0.6) of its velocity, counted down from the base to the
first point that does not. A stagnant cone reaches deeper on the axis than at the edge; a layer
pushed ahead of a smooth base is as deep at both. Prints the frames used and these
depths; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PatchCollection  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

import grainscale as gs  # noqa: E402
from grainscale.analysis import read_frame  # noqa: E402


def frames(out: Path) -> list[tuple[float, Path]]:
    text = (out / "frames.pvd").read_text()
    found = re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', text)
    return [(float(t), out / f) for t, f in found]


def point_spacing(case: gs.Case, x: np.ndarray) -> np.ndarray:
    """(N, 3) spacing [m] of the points at positions x: the size of the grid cell each
    lies in over the body's points a cell (a uniform grid: cell_size / points_per_cell)."""
    n = case.bodies[0].points_per_cell
    out = np.empty_like(x)
    for a, nodes in enumerate(case.grid.node_axes()):
        k = np.clip(np.searchsorted(nodes, x[:, a], side="right") - 1, 0, len(nodes) - 2)
        out[:, a] = np.diff(nodes)[k] / n
    return out


def intruder_section(case: gs.Case, depth: float) -> tuple[float, float, float, float]:
    """(x0, z0, width, height) [m] of the intruder's section by y = 0, `depth` below
    its initial place (a cylinder about z or a box)."""
    rigid = case.rigid
    if rigid.shape == "cylinder":
        cx, _, cz = rigid.center
        return cx - rigid.radius, cz - depth, 2.0 * rigid.radius, rigid.height
    return rigid.lo[0], rigid.lo[2] - depth, rigid.hi[0] - rigid.lo[0], rigid.hi[2] - rigid.lo[2]


def carried_depth(x: np.ndarray, spacing: np.ndarray, share: np.ndarray, base_z: float,
                  x_col: float, threshold: float = 0.6) -> float:
    """Depth [m] below the intruder's base (at height base_z, m) to which the points of
    the column at x_col (those whose tile, x +- spacing/2, spans it) move with at least
    `threshold` of the intruder's velocity: counting down from the base, the lower face
    of the last point's tile before the first point that moves slower (0 if the first
    one does). x (N,3) and spacing (N,3) [m], share (N,) (v . e / |v_rigid|)."""
    col = (np.abs(x[:, 0] - x_col) <= spacing[:, 0] / 2) & (x[:, 2] < base_z)
    depth = 0.0
    for k in np.flatnonzero(col)[np.argsort(-x[col, 2])]:
        if share[k] < threshold:
            break
        depth = base_z - (x[k, 2] - spacing[k, 2] / 2)
    return depth


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--depths", type=float, nargs="+", default=[0.5, 1.0], help="d/R")
    ap.add_argument("--box", type=float, nargs=4, metavar=("X0", "X1", "Z0", "Z1"),
                    help="the part of the plane drawn, m (default: the grid)")
    ap.add_argument("--field", choices=["rotation_rate", "velocity"], default="rotation_rate")
    ap.add_argument("--carried", type=float, default=0.6,
                    help="share of the intruder's velocity that counts as carried")
    ap.add_argument("--png", type=Path, default=None)
    args = ap.parse_args()
    if not 0.0 < args.carried < 1.0:
        raise SystemExit(f"--carried {args.carried}: valid 0 < share < 1")
    if args.box and not (args.box[0] < args.box[1] and args.box[2] < args.box[3]):
        raise SystemExit(f"--box {args.box}: valid X0 < X1 and Z0 < Z1 (m)")
    try:
        result = gs.open_result(args.out)
        hist, case = result.history, result.case
    except (ValueError, gs.ConfigError) as err:
        raise SystemExit(str(err)) from None
    for col in ("time", "depth", "depth_over_R"):
        if col not in hist:
            raise SystemExit(f"{args.out / 'history.csv'}: no column {col!r}")
    if case.rigid is None:
        raise SystemExit(f"{args.out}: the case has no [rigid] intruder")
    series = frames(args.out)
    times = np.array([t for t, _ in series])
    d_of_t = np.interp(times, hist["time"], hist["depth_over_R"])
    chosen = []
    for target in args.depths:
        k = int(np.argmin(np.abs(d_of_t - target)))
        chosen.append((target, float(d_of_t[k]), float(times[k]), series[k][1],
                       float(np.interp(times[k], hist["time"], hist["depth"]))))
    fig, axes = plt.subplots(1, len(chosen), figsize=(4.6 * len(chosen) + 1, 4.2),
                             squeeze=False, constrained_layout=True)
    vmax = 0.0
    data, carried = [], []
    first_y = point_spacing(case, np.zeros((1, 3)))[0, 1]  # the layer next to y = 0
    v_rigid = np.asarray(case.rigid.velocity, float)
    for *_, f, depth in chosen:
        x, fields = read_frame(f)
        for name in {args.field, "velocity"}:
            if name not in fields:
                raise SystemExit(f"{f}: no field {name!r} (rotation_rate: a multiscale run)")
        share = np.asarray(fields["velocity"]) @ v_rigid / float(v_rigid @ v_rigid)
        value = share if args.field == "velocity" else np.asarray(fields["rotation_rate"]).ravel()
        near = x[:, 1] < first_y
        h = point_spacing(case, x[near])
        section = intruder_section(case, depth)
        data.append((x[near], h, value[near], section))
        bx, bz, w, _ = section
        half = w / 2  # the section spans the axis +- R (+- the half-width of a box)
        carried.append({where: carried_depth(x[near], h, share[near], bz, bx + half + frac * half,
                                             args.carried)
                        for where, frac in (("axis", 0.05), ("edge", 0.9))})
        vmax = max(vmax, float(np.nanpercentile(value[near], 98)))
    if args.field == "velocity":
        vmax = 1.0
    lo, hi, _ = case.grid.extent()
    x0, x1, z0, z1 = args.box if args.box else (lo[0], hi[0], lo[2], hi[2])
    for ax, (target, d, t, f, _), (x, h, rate, section) in zip(axes[0], chosen, data,
                                                               strict=True):
        tiles = PatchCollection([Rectangle((px - hx / 2, pz - hz / 2), hx, hz) for px, pz, hx, hz
                                 in zip(x[:, 0], x[:, 2], h[:, 0], h[:, 2], strict=True)],
                                cmap="viridis", linewidth=0, antialiased=False)
        tiles.set_array(rate)
        tiles.set_clim(0.0, vmax)
        ax.add_collection(tiles)
        bx, bz, w, ht = section
        ax.add_patch(Rectangle((bx, bz), w, ht, fill=False, edgecolor="w", lw=1.2))
        ax.set(title=f"d/R = {d:.2f} (t = {t:.2f} s)", xlabel="x (m)", ylabel="z (m)",
               aspect="equal", xlim=(x0, x1), ylim=(z0, z1), facecolor="0.85")
        print(f"d/R {target}: frame {f.name}, d/R {d:.3f}, t {t:.3f} s", flush=True)
    for (_, d, *_), c in zip(chosen, carried, strict=True):
        print(f"d/R {d:.3f}: moving with >= {args.carried:g} of the intruder's velocity to "
              f"{c['axis']:.3f} m below the base on the axis, {c['edge']:.3f} m at 0.9 R")
    fig.colorbar(tiles, ax=axes[0].tolist(), label="grain rotation rate (rad/s)"
                 if args.field == "rotation_rate" else "share of the intruder's velocity")
    png = args.png or args.out / "stagnant.png"
    fig.savefig(png, dpi=120)
    print(json.dumps({"png": str(png), "carried_share": args.carried, "frames": [
        {"depth_over_R": round(d, 4), "time": t, "file": f.name,
         "carried_depth_axis": round(c["axis"], 4), "carried_depth_edge": round(c["edge"], 4)}
        for (_, d, t, f, _), c in zip(chosen, carried, strict=True)]}))


if __name__ == "__main__":
    main()

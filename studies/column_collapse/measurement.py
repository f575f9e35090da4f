"""The column collapse as a measurement (seed §4.2, Fig. 5-6; docs/validation.md §2.3):
runout against time, final runout against the experiments' band, H_f/H_i, the deposit
and the failure surface of each run, in one table and two figures.

    python studies/column_collapse/measurement.py RUN [RUN ...] [--label NAME ...]
        [--png PREFIX]

Per run (a finished or interrupted `quick.toml`-like run: history.csv with t_over_tc,
runout_ratio and height_ratio; VTK frames):
- the runout (L - L_i)/L_i at t/tau_c = 0.5, 1, 2, ..., 7 (history rows, interpolated);
- the final runout against the band of the experiments for a = 0.6: 0.72 (Lube et al.
  2005, 1.2 a) to 1.08 (Lajeunesse et al. 2005, 1.8 a), "in", "below" or "above";
- H_f/H_i at the last row;
- the failure surface at the frames nearest 0.5, 2 and 3 tau_c: the points that started
  in the column and move faster than 0.1 sqrt(g H_i) (8 cm/s) against those slower; in
  each 5 mm layer of the initial column the rearmost moving point's initial x; a line
  fitted to those (x, z) from the top down to where the layers stop moving; its angle
  from the horizontal (the experiments' failure plane is seen from the column's upper
  edge going down and back), with its standard error (failure_surface: through few
  layers one point a spacing (5 mm) off tilts it by degrees); None where fewer than 3
  layers move;
- the deposit at the last frame: the height of the highest point centre over 10 mm
  bins of x (one cell of quick.toml's grid; half a cell is a point spacing).
`--png PREFIX` writes PREFIX_runout.png (runout against t/tau_c with the band) and
PREFIX_deposit.png (the deposits). The last line is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

import grainscale as gs

sys.path.insert(0, str(Path(__file__).resolve().parent))
from convergence import point_spacing  # noqa: E402

BAND = (0.72, 1.08)  # final runout for a = 0.6: Lube et al. 2005, Lajeunesse et al. 2005
TIMES = (0.5, 1, 2, 3, 4, 5, 6, 7)  # t / tau_c
SURFACE_TIMES = (0.5, 2.0, 3.0)
LAYER = 0.005  # m


def runout_at(h: dict, times=TIMES) -> dict:
    t, r = h["t_over_tc"], h["runout_ratio"]
    return {f"{x:g}": (round(float(np.interp(x, t, r)), 3) if t[-1] >= x - 1e-2 else None)
            for x in times}  # (a run ends within round-off of 7 tau_c)


def failure_surface(x0: np.ndarray, v: np.ndarray, speed: float, length: float,
                    height: float, spacing: float) -> dict | None:
    """The boundary between moving and resting points of the initial column (module
    docstring): its fitted angle [deg], the angle's standard error [deg] and the layers
    it spans. `spacing` [m]: the points' initial spacing along x, to which each layer's
    boundary is known."""
    inside = (x0[:, 0] <= length) & (x0[:, 2] <= height)
    moving = inside & (np.linalg.norm(v, axis=1) > speed)
    xs, zs = [], []
    for z in np.arange(0.0, height, LAYER):
        lay = moving & (x0[:, 2] >= z) & (x0[:, 2] < z + LAYER)
        if lay.any():
            xs.append(float(x0[lay, 0].min()))
            zs.append(z + 0.5 * LAYER)
    if len(xs) < 3:
        return None
    slope = np.polyfit(xs, zs, 1)[0]  # dz/dx of the boundary
    # The error is in x (z is each layer's centre): fitted as x(z) = a + b z, b's standard
    # error is s / sqrt(sum (z - mean z)^2), s^2 the residual variance over n - 2, at least
    # a uniform error over one spacing (spacing^2 / 12), which a boundary lying exactly on
    # the points' lattice (a residual of 0) still has. d(atan(1/b))/db = -1 / (1 + b^2).
    x, z = np.asarray(xs), np.asarray(zs)
    b, a = np.polyfit(z, x, 1)
    s2 = max(float(np.sum((x - a - b * z) ** 2)) / (len(x) - 2), spacing ** 2 / 12.0)
    se_b = math.sqrt(s2 / float(np.sum((z - z.mean()) ** 2)))
    return {"angle_deg": round(math.degrees(math.atan(abs(slope))), 1),
            "angle_se_deg": round(math.degrees(se_b / (1.0 + b * b)), 1),
            "layers": len(xs), "from_z": round(min(zs), 4), "to_z": round(max(zs), 4),
            "x_at_top": round(xs[int(np.argmax(zs))], 4)}


def measure(run: Path) -> dict:
    r = gs.open_result(run)
    col = r.case.output.column
    length, height = col.length, col.height
    g = float(np.linalg.norm(r.case.solver.gravity))
    tau = math.sqrt(height / g)
    h = r.history
    frames = r.frames()
    x0 = frames[0][1].points
    spacing = point_spacing(r.case)
    out = {"run": str(run), "steps": int(h["step"][-1]),
           "t_over_tc_end": round(float(h["t_over_tc"][-1]), 3),
           "runout": runout_at(h), "final": round(float(h["runout_ratio"][-1]), 3),
           "height_ratio": round(float(h["height_ratio"][-1]), 3)}
    f = out["final"]
    out["band"] = "below" if f < BAND[0] else "above" if f > BAND[1] else "in"
    out["surface"] = {}
    for ts in SURFACE_TIMES:
        k = int(np.argmin([abs(t / tau - ts) for t, _ in frames]))
        t, mesh = frames[k]
        s = failure_surface(x0, mesh.point_data["velocity"], 0.1 * math.sqrt(g * height),
                            length, height, spacing)
        out["surface"][f"{ts:g}"] = {"t_over_tc": round(t / tau, 3), **(s or {})}
    last = frames[-1][1]
    edge = last.points[:, 2]
    bins = np.arange(0.0, float(last.points[:, 0].max()) + 2 * LAYER, 2 * LAYER)
    which = np.digitize(last.points[:, 0], bins) - 1
    out["deposit"] = {"x": [round(float(b + LAYER), 4) for b in bins[:-1]],
                      "height": [round(float(edge[which == i].max()), 4)
                                 if (which == i).any() else 0.0
                                 for i in range(len(bins) - 1)]}
    out["_curve"] = (h["t_over_tc"], h["runout_ratio"])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--label", nargs="+", help="one name per run (default its folder)")
    ap.add_argument("--png", help="prefix of the two figures")
    args = ap.parse_args()
    labels = args.label or [p.name for p in args.runs]
    if len(labels) != len(args.runs):
        raise SystemExit(f"--label: {len(labels)} names for {len(args.runs)} runs")
    rows = [measure(run) for run in args.runs]
    print(f"{'run':>24} {'final':>6} {'band':>6} {'H_f/H_i':>7}  runout at "
          + " ".join(f"{t:g}" for t in TIMES) + " tau_c;  failure surface angle at "
          + ", ".join(f"{t:g}" for t in SURFACE_TIMES) + " tau_c")
    for name, row in zip(labels, rows, strict=True):
        runs = " ".join("-" if v is None else f"{v:.3f}" for v in row["runout"].values())
        ang = ", ".join(f"{s['angle_deg']} +- {s['angle_se_deg']}" if s.get("angle_deg")
                        is not None else "-" for s in row["surface"].values())
        print(f"{name:>24} {row['final']:6.3f} {row['band']:>6} {row['height_ratio']:7.3f}"
              f"  {runs};  {ang}")
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6.5, 4))
        for name, row in zip(labels, rows, strict=True):
            t, r = row["_curve"]
            ax.plot(t[t >= 0], r[t >= 0], lw=1.2, label=name)
        ax.axhspan(*BAND, color="0.88", label="experiments, a = 0.6 (Lube 2005 - "
                                              "Lajeunesse 2005)")
        ax.set(xlabel="t / tau_c", ylabel="(L - L_i) / L_i", xlim=(0, 7), ylim=(0, None),
               title="column collapse, a = 0.6")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
        fig.tight_layout()
        fig.savefig(f"{args.png}_runout.png", dpi=120)
        fig, ax = plt.subplots(figsize=(6.5, 3))
        for name, row in zip(labels, rows, strict=True):
            ax.step(row["deposit"]["x"], row["deposit"]["height"], where="mid", lw=1.0,
                    label=name)
        ax.set(xlabel="x [m]", ylabel="deposit height [m]", ylim=(0, None),
               title="deposits at the last frame")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(f"{args.png}_deposit.png", dpi=120)
    for row in rows:
        row.pop("_curve")
    print(json.dumps({"runs": dict(zip(labels, rows, strict=True))}))


if __name__ == "__main__":
    main()

"""The stagnant zone under an intruder: the RVEs' rotation rate on the symmetry plane
(seed Fig. 15).

    python examples/intrusion/stagnant.py OUT [--depths 0.5 1.0] [--png OUT/stagnant.png]

Reads the run's VTK frames (frames.pvd) and, for the frames nearest the requested d/R,
draws the points of the first layer next to the symmetry plane y = 0 (y below one point
spacing) coloured by `rotation_rate`, the mean angular speed of the RVE's grains
(rad/s, seed Eq. 15): a stagnant cone moves with the intruder and its grains barely
roll, while the shear zone around it rolls fast. Depth and d/R come from history.csv.
Prints the frames used; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import re
import tomllib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import grainscale as gs  # noqa: E402
from grainscale.analysis import read_frame  # noqa: E402


def frames(out: Path) -> list[tuple[float, Path]]:
    text = (out / "frames.pvd").read_text()
    found = re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', text)
    return [(float(t), out / f) for t, f in found]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--depths", type=float, nargs="+", default=[0.5, 1.0], help="d/R")
    ap.add_argument("--png", type=Path, default=None)
    args = ap.parse_args()
    try:
        hist = gs.open_result(args.out).history
    except ValueError as err:
        raise SystemExit(str(err)) from None
    for col in ("time", "depth_over_R"):
        if col not in hist:
            raise SystemExit(f"{args.out / 'history.csv'}: no column {col!r}")
    case = tomllib.loads((args.out / "case.resolved.toml").read_text())
    spacing = case["grid"]["cell_size"] / case["bodies"][0]["points_per_cell"]
    series = frames(args.out)
    times = np.array([t for t, _ in series])
    d_of_t = np.interp(times, hist["time"], hist["depth_over_R"])
    chosen = []
    for target in args.depths:
        k = int(np.argmin(np.abs(d_of_t - target)))
        chosen.append((target, float(d_of_t[k]), float(times[k]), series[k][1]))
    fig, axes = plt.subplots(1, len(chosen), figsize=(4.6 * len(chosen) + 1, 4.2),
                             squeeze=False, constrained_layout=True)
    vmax = 0.0
    data = []
    for *_, f in chosen:
        x, fields = read_frame(f)
        rate = np.asarray(fields["rotation_rate"]).ravel()
        near = x[:, 1] < spacing
        data.append((x[near], rate[near]))
        vmax = max(vmax, float(np.nanpercentile(rate[near], 98)))
    for ax, (target, d, t, f), (x, rate) in zip(axes[0], chosen, data, strict=True):
        sc = ax.scatter(x[:, 0], x[:, 2], c=rate, s=12, cmap="viridis", vmin=0.0, vmax=vmax)
        ax.set(title=f"d/R = {d:.2f} (t = {t:.2f} s)", xlabel="x (m)", ylabel="z (m)",
               aspect="equal")
        print(f"d/R {target}: frame {f.name}, d/R {d:.3f}, t {t:.3f} s", flush=True)
    fig.colorbar(sc, ax=axes[0].tolist(), label="grain rotation rate (rad/s)")
    png = args.png or args.out / "stagnant.png"
    fig.savefig(png, dpi=120)
    print(json.dumps({"png": str(png), "frames": [
        {"depth_over_R": round(d, 4), "time": t, "file": f.name} for _, d, t, f in chosen]}))


if __name__ == "__main__":
    main()

"""Where finished column runs ended: the spread of a column collapse over realisations.

    python studies/column_spread.py RUN [RUN ...] [--length 0.1]

For each finished run folder (history.csv with runout_ratio and height_ratio, frames.pvd)
prints one JSON line at its last row: the front (runout ratio of the outermost point),
the runout ratios behind which 99 % and 95 % of the points of the last frame lie (equal
point masses: every column body is one uniform box), H_f/H_i, the kinetic energy there
over its peak, the MPM steps, and the same measures for each layer of points across the
slice (`layers`, layer_measures); then one line with the range of each measure over the
runs. docs/validation.md §2.3 ("Round-off") compares realisations that differ only at
round-off with it.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import grainscale as gs
from grainscale.analysis import read_columns


def layer_measures(points: np.ndarray, length: float, height: float, spacing: float
                   ) -> list[dict]:
    """Front, 99 % and 95 % of the mass and H_f/H_i of each layer of points across the
    slice (y, which a planar column's points keep), from point centres plus half a point
    spacing: a slice two layers thick holds two samples of every place, and a front or
    height (a maximum) over two samples lies further out than over one, so a one-layer
    slice compares with each layer of a two-layer one."""
    layer = np.round(points[:, 1] / spacing - 0.5).astype(int)
    rows = []
    for k in np.unique(layer):
        x, z = points[layer == k, 0], points[layer == k, 2]
        q99, q95 = np.quantile(x, [0.99, 0.95])
        rows.append({"front": round(float((x.max() + spacing / 2 - length) / length), 3),
                     "mass99": round(float((q99 - length) / length), 3),
                     "mass95": round(float((q95 - length) / length), 3),
                     "height_ratio": round(float((z.max() + spacing / 2) / height), 3)})
    return rows


def measures(run: Path, length: float) -> dict:
    """The run's measures at its last history row and last frame (see the module)."""
    h = read_columns(run / "history.csv")
    result = gs.open_result(run)
    points = result.frames()[-1][1].points
    x = points[:, 0]
    q99, q95 = np.quantile(x, [0.99, 0.95])
    ke = h["kinetic_energy"]
    body = result.case.bodies[0]
    spacing = result.case.grid.cell_size / body.points_per_cell
    return {"run": str(run), "t_over_tc": round(float(h["t_over_tc"][-1]), 3),
            "front": round(float(h["runout_ratio"][-1]), 3),
            "mass99": round(float((q99 - length) / length), 3),
            "mass95": round(float((q95 - length) / length), 3),
            "height_ratio": round(float(h["height_ratio"][-1]), 3),
            "kinetic_end_over_peak": float(ke[-1] / ke.max()) if ke.max() > 0 else 0.0,
            "steps": int(h["step"][-1]),
            "layers": layer_measures(points, length, body.hi[2] - body.lo[2], spacing)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--length", type=float, default=0.1, help="L_i, the column's length [m]")
    args = ap.parse_args()
    rows = [measures(run, args.length) for run in args.runs]
    for row in rows:
        print(json.dumps(row))
    keys = ("front", "mass99", "mass95", "height_ratio")
    print(json.dumps({k: [min(r[k] for r in rows), max(r[k] for r in rows)] for k in keys}))


if __name__ == "__main__":
    main()

"""How the front of a column collapse moves: by sliding on the floor or by shearing.

    python studies/column_collapse/front_layers.py RUN CELL [--length 0.02]

RUN is an output folder (frames.pvd and frame_NNNNN.vtu), CELL its cell size (m). Per
frame after release: t / tau_c, the front's x (m), the top of the material within
--length (m) behind the front, and for each layer half a cell thick from the floor up
(L0, L1, ...) the mean x-velocity of its points (m/s) and the share of them that carry
no stress (p < 1 Pa: separated). A front whose bottom layer moves nearly as fast as its
top slides on the floor (docs/validation.md §2.1).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import grainscale as gs

TAU_C = math.sqrt(0.06 / 9.81)  # s, the column's H_i = 60 mm


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("cell", type=float, help="m, the run's cell size")
    ap.add_argument("--length", type=float, default=0.02, help="m behind the front")
    ap.add_argument("--layers", type=int, default=6, help="layers shown, from the floor")
    args = ap.parse_args()
    for t, mesh in gs.open_result(args.run).frames():
        if t < 0:
            continue
        x, f = mesh.points, mesh.point_data
        front = float(x[:, 0].max())
        sel = x[:, 0] > front - args.length
        z, vx, free = x[sel, 2], f["velocity"][sel, 0], f["p"][sel] < 1.0
        layer = np.floor(z / (0.5 * args.cell)).astype(int)
        cols = " ".join(f"L{k}: {vx[layer == k].mean():6.3f} {free[layer == k].mean():4.0%}"
                        for k in sorted(set(layer))[:args.layers])
        print(f"t/tau_c {t / TAU_C:5.2f}  front {front:.3f}  top {z.max() * 1e3:5.1f} mm  {cols}")


if __name__ == "__main__":
    main()

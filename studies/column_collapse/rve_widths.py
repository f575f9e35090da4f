"""How thin the RVE cells of a run have become, against the stress ratio they carry.

Reads the latest checkpoint of an output folder (every RVE's cell and stress; a case
whose only material is the "dem" one, as the column's) and
groups the RVEs that carry stress by the narrowest width of their periodic cell, in
grain diameters (docs/validation.md §2.5: a cell stretched to 2-3 grains thick reads too
strong, as it jams against its own periodic images).

    python studies/column_collapse/rve_widths.py OUT [--min-p 20]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import h5py
import numpy as np

from grainscale.analysis import p_q
from grainscale.blocks import latest_checkpoint, perpendicular_widths


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="output folder of a run with checkpoints")
    ap.add_argument("--min-p", type=float, default=20.0, help="Pa: RVEs below are skipped")
    args = ap.parse_args()
    attrs, parts = latest_checkpoint(args.out)
    x, width, aspect, stretch, p, q = [], [], [], [], [], []
    for part in parts:
        with h5py.File(part) as f:
            pts, rve = f["points"], f["material_0"]
            for k, h in enumerate(rve["rve_h"][()]):
                w = perpendicular_widths(np.ascontiguousarray(h))
                width.append(w.min() / (2 * rve["rve_radius"][k].max()))
                aspect.append(w.max() / w.min())
                sv = np.linalg.svd(pts["F"][k], compute_uv=False)
                stretch.append(sv[0] / sv[2])
                pk, qk = p_q(rve["rve_stress"][k][None])
                p.append(pk[0])
                q.append(qk[0])
                x.append(pts["x"][k, 0])
    x, width, stretch, p, q = map(np.asarray, (x, width, stretch, p, q))
    print(f"step {attrs['step']}, t = {attrs['time']:.4g} s: {len(x)} RVEs")
    print("narrowest width [grain diameters], quantiles 0/5/25/50 %:",
          np.quantile(width, [0, 0.05, 0.25, 0.5]).round(2))
    print("stretch of F (largest / smallest singular value), 50/75/95/100 %:",
          np.quantile(stretch, [0.5, 0.75, 0.95, 1]).round(2))
    loaded = p > args.min_p
    for lo, hi in [(0, 2), (2, 3), (3, 4), (4, np.inf)]:
        sel = loaded & (width >= lo) & (width < hi)
        if sel.any():
            print(f"width {lo}-{hi}: {sel.sum():4d} RVEs, median q/p "
                  f"{np.median(q[sel] / p[sel]):.3f}, mean x {x[sel].mean():.3f} m")


if __name__ == "__main__":
    main()

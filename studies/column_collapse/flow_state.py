"""The state of the flowing material, frame by frame: how many points flow, how many of
them carry no stress, their pressure, stress ratio, volume change and (for RVEs) porosity.

    python studies/column_collapse/flow_state.py RUN [RUN ...] [--speed 0.05]

RUN is an output folder (frames.pvd and frame_NNNNN.vtu). A point flows where its speed
exceeds --speed (m/s). Per frame after release: t / tau_c (the column's H_i = 60 mm),
the front's x (m), the number of flowing points, the share of them with p < 1 Pa
(separated, or an RVE without contacts), and their medians of p (Pa), sqrt(J2)/p over
those with p >= 1 Pa, eps_v (the point's volumetric strain, ln J) and, where the run
has RVEs, porosity (docs/validation.md §2.3 compares a multiscale column with the
continuum that carries its RVE's mu(I) this way).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import grainscale as gs

TAU_C = math.sqrt(0.06 / 9.81)  # s, the column's H_i = 60 mm


def frame_state(x: np.ndarray, fields: dict[str, np.ndarray], speed: float) -> dict:
    """Medians over the points faster than `speed` (m/s) of one frame."""
    v = np.linalg.norm(fields["velocity"], axis=1)
    flow = v > speed
    row = {"front": float(x[:, 0].max()), "flowing": int(flow.sum())}
    if not flow.any():
        return row
    p, q = fields["p"][flow], fields["q"][flow]
    loaded = p >= 1.0
    row.update(stress_free=float(np.mean(~loaded)), p=float(np.median(p)),
               eps_v=float(np.median(fields["eps_v"][flow])))
    if loaded.any():  # sqrt(J2) = q / sqrt(3)
        row["sqrt_j2_over_p"] = float(np.median(q[loaded] / math.sqrt(3) / p[loaded]))
    if "porosity" in fields and fields["porosity"].max() > 0:
        row["porosity"] = float(np.median(fields["porosity"][flow]))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--speed", type=float, default=0.05, help="m/s: flowing above")
    args = ap.parse_args()
    for run in args.runs:
        print(run)
        print(f"{'t/tau_c':>8} {'front':>6} {'flowing':>7} {'p<1Pa':>6} {'p':>6} "
              f"{'sqrtJ2/p':>8} {'eps_v':>6} {'porosity':>8}")
        for t, mesh in gs.open_result(run).frames():
            if t < 0:
                continue
            r = frame_state(mesh.points, mesh.point_data, args.speed)
            if not r["flowing"]:
                print(f"{t / TAU_C:8.2f} {r['front']:6.3f} {0:7d}")
                continue
            print(f"{t / TAU_C:8.2f} {r['front']:6.3f} {r['flowing']:7d} "
                  f"{r['stress_free']:6.2f} {r['p']:6.1f} {r.get('sqrt_j2_over_p', math.nan):8.2f} "
                  f"{r['eps_v']:6.3f} {r.get('porosity', math.nan):8.3f}")


if __name__ == "__main__":
    main()

"""The RVE's friction angles under several quasi-static loadings, against a slow reference.

    python studies/intrusion/loading_table.py REF.json OTHER.json ... [--limit 0.3]

Each file is a `friction_angle.py --realisations N` result (phi.json) of the same
packings (the same case and N: its `packings` and seeds) at some `--strain-rate` and
`--damping`. Prints, for each, the strain per DEM step, the local damping, the steady and
peak angles with their 95 % bands, and their paired change from the reference (the mean
over packings of the per-packing differences, with its 95 % band): the measure of what a
loading moves, free of the scatter between packings. A loading keeps the physics where
both changes lie within `--limit` degrees (default 0.3) of the slow reference.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from friction_angle import summary  # noqa: E402


def _packings(r: dict) -> tuple:
    """What identifies the packings a result tested: the files, the case, and the
    method's last clause (how many of which recipe, with which seeds)."""
    return r["packings"], r.get("case"), r.get("method", "").split(";")[-1]


def paired(ref: dict, other: dict, key: str) -> tuple[float, float]:
    """Mean and 95 % band of other - ref over the packings (the same packings)."""
    if _packings(ref) != _packings(other):
        raise SystemExit("the results test different packings: pair only runs of one "
                         "case with the same --realisations")
    a = np.asarray(ref[f"{key}_per_packing_deg"])
    b = np.asarray(other[f"{key}_per_packing_deg"])
    return summary(b - a)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, nargs="+", help="phi.json files; the first is "
                    "the slow reference")
    ap.add_argument("--limit", type=float, default=0.3, help="deg (default 0.3)")
    args = ap.parse_args(argv)
    runs = [json.loads(p.read_text()) for p in args.results]
    ref = runs[0]
    rows = []
    print("| strain per DEM step | rate (1/s) | damping | steady phi (deg) | change | "
          f"peak phi (deg) | change | both means within {args.limit:g} deg |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    for r in runs:
        steady = paired(ref, r, "phi")
        peak = paired(ref, r, "peak_phi")
        ok = abs(steady[0]) <= args.limit and abs(peak[0]) <= args.limit
        rows.append({"strain_per_dem_step": r["strain_per_dem_step"],
                     "strain_rate": r["strain_rate"], "damping": r.get("damping"),
                     "phi_deg": r["phi_deg"], "peak_phi_deg": r["peak_phi_deg"],
                     "phi_change": steady, "peak_change": peak, "within": ok})
        print(f"| {r['strain_per_dem_step']:.2g} | {r['strain_rate']:g} | "
              f"{r.get('damping', '(recipe)')} | {r['phi_deg']:.2f} +- "
              f"{r['phi_band95_deg']:.2f} | {steady[0]:+.2f} +- {steady[1]:.2f} | "
              f"{r['peak_phi_deg']:.2f} +- {r['peak_phi_band95_deg']:.2f} | "
              f"{peak[0]:+.2f} +- {peak[1]:.2f} | {'yes' if ok else 'no'} |")
    print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""How far apart two 8-realisation means of the demo's RVE lie by chaos alone: the
reference for the demo's verdict (`grainscale demo`, metrics.json).

    python studies/demo_noise.py --groups 6 [--out noise.json]

Runs the demo's drained triaxial test (300 spheres, 100 kPa, 0.5 /s to 30 %) on
8 x GROUPS copies of its packing whose grain velocities differ by ~1e-9 m/s (chaos
makes each a realisation, as triaxial_ensemble does), splits them into GROUPS disjoint
ensembles of 8, and for every pair of ensembles prints the demo's measures
(grainscale.analysis.unit_element_metrics): the peak q/p difference and the mean
deviations of q/p and eps_v over their ranges, each also as a multiple of the noise
the demo's verdict estimates from one ensemble's spread. Two ensembles differ only by
chaos, so these ratios are what the verdict's noise band (analysis.NOISE_BAND) must tolerate.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from grainscale import blocks, rve
from grainscale.analysis import unit_element_metrics

REPLICAS = 8  # the demo's ensemble size


def ensembles(groups: int, seed: int) -> list[dict[str, np.ndarray]]:
    """GROUPS disjoint 8-realisation means of the demo's RVE, with their standard errors
    (the columns triaxial_ensemble returns)."""
    with tempfile.TemporaryDirectory() as tmp:  # the demo's own case file
        subprocess.run([sys.executable, "-m", "grainscale", "demo", "--out", tmp,
                        "--case-only"], check=True, capture_output=True)
        case = rve.load(Path(tmp) / "case.toml")
    packing = rve.generate(case, progress=False)
    rng = np.random.default_rng(seed)
    copies = []
    for _ in range(REPLICAS * groups):
        b = packing.copy()
        b.v += rng.normal(0.0, 1e-9, b.v.shape)
        copies.append(b)
    per_rve = rve.triaxial(case, blocks.concatenate(copies), per_rve=True)
    paths = {k: np.array([curve[k] for curve in per_rve]) for k in per_rve[0]}
    out = []
    for g in range(groups):
        part = {k: v[g * REPLICAS:(g + 1) * REPLICAS] for k, v in paths.items()}
        ens = {k: v.mean(axis=0) for k, v in part.items()}
        for k in ("q_over_p", "volumetric_strain"):
            ens[f"{k}_sem"] = part[k].std(axis=0, ddof=1) / math.sqrt(REPLICAS)
        out.append(ens)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--groups", type=int, default=6)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    if args.groups < 2:
        ap.error(f"--groups = {args.groups}: must be at least 2")
    ens = ensembles(args.groups, args.seed)
    rows = []
    print("pair  peak diff  MAD q/p  MAD eps_v  (of range)  MAD/noise: q/p  eps_v")
    for i, j in itertools.combinations(range(len(ens)), 2):
        m = unit_element_metrics(ens[i], ens[j])
        r = {"pair": [i, j], "peak_relative_difference": m["peak_relative_difference"]}
        for k in ("q_over_p", "volumetric_strain"):
            r[f"mad_{k}_over_dem_range"] = m[f"mad_{k}_over_dem_range"]
            r[f"mad_over_noise_{k}"] = m[f"mad_{k}_over_dem_range"] / m[
                f"noise_{k}_over_dem_range"]
        rows.append(r)
        print(f"{i}-{j}   {100 * r['peak_relative_difference']:8.2f} %"
              f"  {100 * r['mad_q_over_p_over_dem_range']:6.2f} %"
              f"  {100 * r['mad_volumetric_strain_over_dem_range']:7.2f} %"
              f"              {r['mad_over_noise_q_over_p']:5.2f}"
              f"  {r['mad_over_noise_volumetric_strain']:5.2f}")
    summary = {k: {"median": float(np.median([r[k] for r in rows])),
                   "max": float(max(r[k] for r in rows))}
               for k in rows[0] if k != "pair"}
    print(json.dumps(summary, indent=1))
    if args.out:
        args.out.write_text(json.dumps({"pairs": rows, "summary": summary}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

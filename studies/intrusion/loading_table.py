"""The RVE's friction angles under several quasi-static loadings, against a slow reference.

    python studies/intrusion/loading_table.py REF.json OTHER.json ... [--limit 0.3]

Each file is a `friction_angle.py --realisations N` result (phi.json) of the same
packings (the same case and N: its `packings` and seeds) at some `--strain-rate` and
`--damping`. Prints, for each, the strain per DEM step, the local damping, the steady and
peak angles with their 95 % bands, and their paired change from the reference (the mean
over packings of the per-packing differences, with its 95 % band): the measure of what a
loading moves, free of the scatter between packings. A loading keeps the physics where
both changes lie within `--limit` degrees (default 0.3) of the slow reference. With 16
packings a change is resolved to ~0.2 deg only (its 95 % band 0.4-0.8 deg), so the rows
at the reference's damping are also fitted with a line through the reference, change =
k (strain per DEM step - the reference's), steady and peak, the trend's value at each
row printed beside the fit: the noise of single rows averaged out.

Where the results hold the packings' paths (`paths`: friction_angle.py writes them for
packings at one pressure), a second table compares the triaxial curves: for the
mobilised angle and the volumetric strain, the paired difference from the reference at
each of 40 axial strains (the two results' paths interpolated to a common range), its
mean over the packings and that mean's 95 % band;
printed as the rms over the strains of each (the band's rms is the realisation noise
left in a paired mean of N packings) and the difference at the test's end. A curve is
"within realisation noise" where the mean difference's rms does not exceed its band's.
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


def paired_paths(ref: dict, other: dict, key: str) -> dict[str, float]:
    """rms over the strains of the mean paired difference other - ref of a path and of
    its 95 % band, and the mean difference with its band at the last strain."""
    xa, xb = np.asarray(ref["paths"]["axial_strain"]), np.asarray(other["paths"]["axial_strain"])
    grid = np.linspace(0.0, min(xa[-1], xb[-1]), len(xa))[1:]  # strain 0: both 0

    def on_grid(x, paths):
        return np.array([np.interp(grid, x, p) for p in paths])

    d = (on_grid(xb, other["paths"][f"{key}_per_packing"])
         - on_grid(xa, ref["paths"][f"{key}_per_packing"]))
    mean, band = np.array([summary(column) for column in d.T]).T
    return {"rms": float(np.sqrt(np.mean(mean**2))), "band_rms": float(np.sqrt(np.mean(
        band**2))), "end": float(mean[-1]), "end_band": float(band[-1])}


def trend(runs: list[dict]) -> dict[str, list[float]]:
    """Least-squares slopes k [deg per unit strain per DEM step] (with standard errors)
    of the paired steady and peak changes against the strain per DEM step beyond the
    reference's, over the results at the reference's damping (module docstring)."""
    ref = runs[0]
    same = [r for r in runs[1:] if r.get("damping") == ref.get("damping")]
    if len(same) < 2:
        return {}
    x = np.array([r["strain_per_dem_step"] - ref["strain_per_dem_step"] for r in same])
    out = {}
    for key in ("phi", "peak_phi"):
        y = np.array([paired(ref, r, key)[0] for r in same])
        k = float(x @ y / (x @ x))
        res = y - k * x
        out[key] = [k, float(np.sqrt(res @ res / (len(x) - 1) / (x @ x)))]
    print(f"\ntrend at damping {ref.get('damping')}: steady {out['phi'][0] * 1e-6:+.3f} +- "
          f"{out['phi'][1] * 1e-6:.3f}, peak {out['peak_phi'][0] * 1e-6:+.3f} +- "
          f"{out['peak_phi'][1] * 1e-6:.3f} deg per 1e-6 of strain per DEM step; at "
          + ", ".join(f"{r['strain_per_dem_step']:.2g}: {out['phi'][0] * d:+.2f} / "
                      f"{out['peak_phi'][0] * d:+.2f}"
                      for r, d in zip(same, x, strict=True)))
    return out


def curves_table(runs: list[dict]) -> list[dict]:
    """The second table (module docstring); prints it and returns its rows."""
    ref = runs[0]
    print("\n| strain per DEM step | rate (1/s) | damping | phi path: mean change, rms "
          "(deg) | its band | at the end | eps_v path: mean change, rms | its band | at "
          "the end | both within realisation noise |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    rows = []
    for r in runs:
        phi = paired_paths(ref, r, "phi_deg")
        ev = paired_paths(ref, r, "volumetric_strain")
        ok = phi["rms"] <= phi["band_rms"] and ev["rms"] <= ev["band_rms"]
        rows.append({"strain_per_dem_step": r["strain_per_dem_step"], "phi_path": phi,
                     "volumetric_strain_path": ev, "within_noise": ok})
        print(f"| {r['strain_per_dem_step']:.2g} | {r['strain_rate']:g} | "
              f"{r.get('damping', '(recipe)')} | {phi['rms']:.2f} | {phi['band_rms']:.2f} | "
              f"{phi['end']:+.2f} +- {phi['end_band']:.2f} | {ev['rms']:.2e} | "
              f"{ev['band_rms']:.2e} | {ev['end']:+.1e} +- {ev['end_band']:.1e} | "
              f"{'yes' if ok else 'no'} |")
    return rows


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
    fit = trend(runs)
    if all("paths" in r for r in runs):
        for row, c in zip(rows, curves_table(runs), strict=True):
            row.update(c)
    print(json.dumps({"rows": rows, "trend": fit}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

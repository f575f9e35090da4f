"""Unit element test (seed §4.1, Fig. 3): the multiscale run against the pure DEM
triaxial test of the same RVE, both from case.toml, and the comparison plot.

    python examples/unit_element/compare.py [--case case.toml] [--out ue_compare]

Writes OUT/multiscale/ (history.csv, frames, ...), OUT/dem.csv, OUT/comparison.png and
OUT/metrics.json (peak q/p difference, mean absolute deviations relative to each
curve's range; acceptance: all within 3 %).

With --replicas R the pure DEM test is also run on R copies of the packing whose grain
velocities differ by 1e-9 m/s (chaos makes each a different realisation, as the 8 RVEs
of the multiscale run become) and their mean is compared too (OUT/dem_ensemble.csv).
"""

import argparse
import json
from pathlib import Path

import grainscale as gs
from grainscale import rve
from grainscale.analysis import (
    plot_stress_path,
    read_columns,
    unit_element_metrics,
    write_columns,
)

HERE = Path(__file__).resolve().parent


def compare(case: Path, out: Path, quiet: bool = False, replicas: int = 0) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    try:
        gs.run(case, out / "multiscale", progress=not quiet)
    except gs.RunError:
        raise SystemExit("the multiscale run failed") from None
    params = rve.load(case)
    packing = rve.generate(params, progress=not quiet)  # as `grainscale rve triaxial` does
    dem = rve.triaxial(params, packing, progress=not quiet)
    write_columns(out / "dem.csv", dem)
    ms = read_columns(out / "multiscale" / "history.csv")
    metrics = unit_element_metrics(dem, ms)
    curves = {"pure DEM (drained triaxial)": dem, "MPM x DEM (8 points)": ms}
    if replicas:
        ens = rve.triaxial_ensemble(params, packing, replicas=replicas, progress=False)
        write_columns(out / "dem_ensemble.csv", ens)
        metrics["against_dem_ensemble"] = unit_element_metrics(ens, ms)
        metrics["dem_replicas"] = replicas
        curves[f"pure DEM, mean of {replicas} realisations"] = ens
    plot_stress_path(out / "comparison.png", curves,
                     title="Unit element test: multiscale vs pure DEM (seed Fig. 3)")
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=Path, default=HERE / "case.toml")
    ap.add_argument("--out", type=Path, default=Path("ue_compare"))
    ap.add_argument("--replicas", type=int, default=0,
                    help="also compare with the mean of this many pure DEM realisations")
    args = ap.parse_args()
    print(json.dumps(compare(args.case, args.out, replicas=args.replicas), indent=2))

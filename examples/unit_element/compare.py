"""Unit element test (seed §4.1, Fig. 3): the multiscale run against the pure DEM
triaxial test of the same RVE, both from case.toml, and the comparison plot.

    python examples/unit_element/compare.py [--case case.toml] [--out ue_compare]

Writes OUT/multiscale/ (history.csv, frames, ...), OUT/dem.csv, OUT/comparison.png and
OUT/metrics.json (peak q/p difference, mean absolute deviations relative to each
curve's range; acceptance: all within 3 %).
"""

import argparse
import json
from pathlib import Path

from grainscale.analysis import read_columns, unit_element_metrics
from grainscale.cli import main as grainscale
from grainscale.io.plots import plot_stress_path

HERE = Path(__file__).resolve().parent


def compare(case: Path, out: Path, quiet: bool = False) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    flags = ["--quiet"] if quiet else []
    if grainscale(["run", str(case), "--out", str(out / "multiscale"), *flags]) != 0:
        raise SystemExit("the multiscale run failed")
    if grainscale(["rve", "triaxial", str(case), "--out", str(out / "dem.csv"), *flags]) != 0:
        raise SystemExit("the pure DEM test failed")
    ms = read_columns(out / "multiscale" / "history.csv")
    dem = read_columns(out / "dem.csv")
    metrics = unit_element_metrics(dem, ms)
    plot_stress_path(out / "comparison.png",
                     {"pure DEM (drained triaxial)": dem, "MPM x DEM (8 points)": ms},
                     title="Unit element test: multiscale vs pure DEM (seed Fig. 3)")
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=Path, default=HERE / "case.toml")
    ap.add_argument("--out", type=Path, default=Path("ue_compare"))
    args = ap.parse_args()
    print(json.dumps(compare(args.case, args.out), indent=2))

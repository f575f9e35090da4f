"""The friction angle of an intrusion case's RVE, for the modified Archimedes law.

    python examples/intrusion/friction_angle.py CASE.toml RUN --out phi.json [--from 0.1]

Runs `grainscale rve triaxial CASE.toml` (drained, at the case's [triaxial] confining
pressure and rate) on every packing the run used (RUN/packings/*.h5) and takes the
mobilised friction angle phi = asin((sigma_1 - sigma_3)/(sigma_1 + sigma_3)), with
sigma_3 the mean lateral stress, over the axial strains from `--from` to the end: the
steady (critical-state) part of the test, the analogue of a repose angle, which is the
angle Kang et al.'s law is written for. Small RVEs give noisy paths, so the angle is
the mean over the window and all packings, with a 95 % band from the per-packing means
(Student t); the peak of each path is reported beside it. Writes phi.json
({"phi_deg": ..., ...}, the input of analyse.py --phi-from) and prints it.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from grainscale.io.history import read_history

T95 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306}




def mobilised_angle(h: dict[str, np.ndarray]) -> np.ndarray:
    """phi [deg] along a triaxial path (stresses compression positive)."""
    s1 = h["sigma_zz"]
    s3 = 0.5 * (h["sigma_xx"] + h["sigma_yy"])
    return np.degrees(np.arcsin((s1 - s3) / (s1 + s3)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", type=Path)
    ap.add_argument("run", type=Path, help="output folder of a run of the case")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--from", dest="start", type=float, default=0.1,
                    help="axial strain where the steady window starts")
    args = ap.parse_args()
    packings = sorted((args.run / "packings").glob("*.h5"))
    if not packings:
        raise SystemExit(f"{args.run / 'packings'}: no packings (*.h5); run the case first")
    means, peaks = [], []
    for k, pack in enumerate(packings):
        csv = args.out.with_name(f"{args.out.stem}_triaxial_{k}.csv")
        if not csv.is_file():
            subprocess.run([sys.executable, "-m", "grainscale", "rve", "triaxial",
                            str(args.case), "--packing", str(pack), "--out", str(csv),
                            "--quiet"], check=True)
        h = read_history(csv)
        phi = mobilised_angle(h)
        window = h["axial_strain"] >= args.start
        if window.sum() < 5:
            raise SystemExit(f"{csv}: fewer than 5 rows beyond axial strain {args.start}")
        means.append(float(phi[window].mean()))
        peaks.append(float(phi.max()))
        print(f"{pack.name}: steady phi {means[-1]:.2f} deg (axial strain >= {args.start}), "
              f"peak {peaks[-1]:.2f} deg", flush=True)
    n = len(means)
    band = T95[n - 1] * float(np.std(means, ddof=1)) / math.sqrt(n) if n > 1 else math.nan
    result = {"phi_deg": round(float(np.mean(means)), 2), "phi_band95_deg": round(band, 2),
              "phi_per_packing_deg": [round(m, 2) for m in means],
              "peak_phi_deg": [round(p, 2) for p in peaks],
              "method": f"drained triaxial at the case's [triaxial] confining pressure, mean "
                        f"mobilised angle for axial strain >= {args.start}, all packings",
              "case": str(args.case), "packings": [p.name for p in packings]}
    args.out.write_text(json.dumps(result, indent=1))
    print(json.dumps(result))


if __name__ == "__main__":
    main()

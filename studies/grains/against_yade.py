"""Grain models against YADE 2023.02a: the drained triaxial of an 800-sphere RVE.

    python studies/grains/against_yade.py [--png docs/img/hertz_yade.png]

Runs grainscale's `rve triaxial` of examples/rve/hertz_mindlin.toml (the seed's
800-sphere RVE with Hertz-Mindlin contacts, E = 70 GPa, nu = 0.25, mu = 0.5, damping
0.2; 100 kPa, 0.25 /s to 30 % axial strain, from rest) on its packing stored in
tests/data/triaxial_800_hertz and compares it with YADE's run of the same packing and
test stored there (yade_0.csv: Ip2_FrictMat_FrictMat_MindlinPhys,
Law2_ScGeom_MindlinPhys_Mindlin, the same time step, damping and servo): smoothed peak of
q/p (running mean over 5 rows, 1 % strain), residual (mean over the last 5 % of strain)
and eps_v at 10 and 20 % (studies/rolling/against_yade.py's measures). Prints a table and
one JSON line; draws q/p and eps_v against axial strain.
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

import numpy as np

from grainscale import rve

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "triaxial_800_hertz"
sys.path.insert(0, str(ROOT / "studies" / "rolling"))
from against_yade import figures  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--png", type=Path)
    args = ap.parse_args(argv)
    case = tomllib.loads((ROOT / "examples" / "rve" / "hertz_mindlin.toml").read_text())
    batch = rve.packing(case, [DATA / "packing.txt"])
    rows = rve.rows_of(rve.triaxial(case, batch, progress=False))[1:]
    ours = np.array([[r["axial_strain"], r["q_over_p"], r["volumetric_strain"]]
                     for r in rows])
    yade = np.loadtxt(DATA / "yade_0.csv", delimiter=",", skiprows=1)[1:, :3]  # row 0: no step
    results = {"grainscale": figures(*ours.T), "yade": figures(*yade.T)}
    print(f"{'code':>10} {'peak q/p':>9} {'residual':>9} {'eps_v 10%':>10} {'eps_v 20%':>10}")
    for code, f in results.items():
        print(f"{code:>10} {f['peak']:>9.3f} {f['residual']:>9.3f} {f['eps_v_10']:>10.4f} "
              f"{f['eps_v_20']:>10.4f}")
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
        for curve, label, ls in ((ours, "grainscale", "-"), (yade, "YADE 2023.02a", "--")):
            ax1.plot(curve[:, 0], curve[:, 1], color="C0", ls=ls, label=label)
            ax2.plot(curve[:, 0], curve[:, 2], color="C0", ls=ls)
        ax1.set(xlabel="axial strain", ylabel="q/p")
        ax2.set(xlabel="axial strain", ylabel="eps_v = ln(V/V0)")
        ax1.legend(fontsize=8)
        fig.suptitle("800 spheres, Hertz-Mindlin (E 70 GPa, nu 0.25), 100 kPa, 0.25 /s")
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

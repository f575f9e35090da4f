"""The 800-sphere drained triaxial with rolling resistance against YADE 2023.02a.

    python studies/rolling/against_yade.py [--png docs/img/rolling_yade.png]

Runs grainscale's `rve triaxial` of tests/data/triaxial_800's packing (100 kPa, 0.25 /s
to 30 % axial strain, alpha_r = 1, eta_r = 0.1 and 0.3) and compares it with YADE's
runs of the same test stored there (yade_rolling_1_ETA.csv; YADE's own run without
rolling resistance, yade_0.csv, beside them): smoothed peak of q/p (running mean over 5
rows, 1 % strain), residual (mean over the last 5 % of strain) and eps_v at 10 and 20 %.
Prints a table and one JSON line; draws q/p and eps_v against axial strain.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from grainscale import rve

DATA = Path(__file__).resolve().parents[2] / "tests" / "data" / "triaxial_800"
ETAS = (0.1, 0.3)


def figures(a: np.ndarray, qp: np.ndarray, ev: np.ndarray) -> dict:
    """Peak (smoothed over 5 rows), residual (last 5 % of strain), eps_v at 10 and 20 %."""
    smooth = np.convolve(qp, np.ones(5) / 5, mode="valid")
    last = a > a[-1] - 0.05
    at = {s: float(ev[int(np.argmin(np.abs(a - s)))]) for s in (0.1, 0.2)}
    return {"peak": float(smooth.max()), "residual": float(qp[last].mean()),
            "eps_v_10": at[0.1], "eps_v_20": at[0.2]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--png", type=Path)
    args = ap.parse_args(argv)
    tables = {"rve": {"particles": 800, "preparation": {"pressure": 100e3, "porosity": 0.373}},
              "triaxial": {"confining_pressure": 100e3, "axial_strain": 0.3,
                           "strain_rate": 0.25, "output_interval": 0.002}}
    results, curves = {}, {}
    for eta in ETAS:
        tables["rve"].update(rolling_stiffness=1.0, rolling_friction=eta)
        case = {"rve": dict(tables["rve"]), "triaxial": tables["triaxial"]}
        batch = rve.packing(case, [DATA / "packing.txt"])
        rows = rve.rows_of(rve.triaxial(case, batch, progress=False))[1:]
        ours = np.array([[r["axial_strain"], r["q_over_p"], r["volumetric_strain"]]
                         for r in rows])
        yade = np.loadtxt(DATA / f"yade_rolling_1_{eta}.csv", delimiter=",", skiprows=1)[:, :3]
        curves[eta] = (ours, yade)
        results[eta] = {"grainscale": figures(*ours.T), "yade": figures(*yade.T)}
    plain = np.loadtxt(DATA / "yade_0.csv", delimiter=",", skiprows=1)[:, :3]
    results[0.0] = {"yade": figures(*plain.T)}
    print(f"{'eta_r':>6} {'code':>10} {'peak q/p':>9} {'residual':>9} {'eps_v 10%':>10} "
          f"{'eps_v 20%':>10}")
    for eta, res in sorted(results.items()):
        for code, f in res.items():
            print(f"{eta:>6} {code:>10} {f['peak']:>9.3f} {f['residual']:>9.3f} "
                  f"{f['eps_v_10']:>10.4f} {f['eps_v_20']:>10.4f}")
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
        ax1.plot(plain[:, 0], plain[:, 1], color="0.6", label="YADE, no rolling")
        ax2.plot(plain[:, 0], plain[:, 2], color="0.6")
        for eta, color in zip(ETAS, ("C0", "C3"), strict=True):
            ours, yade = curves[eta]
            ax1.plot(ours[:, 0], ours[:, 1], color=color, label=f"grainscale, eta_r {eta}")
            ax1.plot(yade[:, 0], yade[:, 1], color=color, ls="--", label=f"YADE, eta_r {eta}")
            ax2.plot(ours[:, 0], ours[:, 2], color=color)
            ax2.plot(yade[:, 0], yade[:, 2], color=color, ls="--")
        ax1.set(xlabel="axial strain", ylabel="q/p")
        ax2.set(xlabel="axial strain", ylabel="eps_v = ln(V/V0)")
        ax1.legend(fontsize=8)
        fig.suptitle("800 spheres, 100 kPa, 0.25 /s, alpha_r = 1: grainscale against YADE "
                     "2023.02a")
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
    print(json.dumps({str(k): v for k, v in results.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Grain models against YADE 2023.02a: drained triaxials of 800-sphere RVEs.

    python studies/grains/against_yade.py [--only NAME] [--png FOLDER]

For each case (NAME: hertz, elongated, tetrahedral) runs grainscale's `rve triaxial` of
its example file on its packing stored under tests/data and compares it with YADE's run
of the same packing and test stored there (the script and commands in that folder's
README; 100 kPa, 0.25 /s to 30 % axial strain, from rest, the same time step, damping
and servo):

- hertz: examples/rve/hertz_mindlin.toml, the seed's 800-sphere RVE with Hertz-Mindlin
  contacts (E = 70 GPa, nu = 0.25), tests/data/triaxial_800_hertz;
- elongated: examples/rve/clumps.toml, 400 two-sphere clumps of aspect 1.5,
  tests/data/triaxial_clumps/elongated*;
- tetrahedral: examples/rve/clumps_tetrahedral.toml, 200 four-sphere tetrahedral clumps,
  tests/data/triaxial_clumps/tetrahedral*.

Measures (studies/rolling/against_yade.py's): smoothed peak of q/p (running mean over 5
rows, 1 % strain), residual (mean over the last 5 % of strain), eps_v at 10 and 20 %.
With --realisations N (N > 1) grainscale runs N realisations, the first from rest and
the others with the grains' velocities perturbed by 1e-9 m/s (seeds 0 .. N-2, as the
YADE script's SEED), and every stored YADE realisation of the case (its rows files
yade_NAME*.csv) is read: the table gives each code's mean and standard deviation, since
in a small loose packing one realisation's peak can stray by several per cent. Prints a
table and one JSON line; --png FOLDER draws q/p and eps_v against axial strain (every
realisation) to FOLDER/NAME_yade.png.
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
sys.path.insert(0, str(ROOT / "studies" / "rolling"))
from against_yade import figures  # noqa: E402

DATA = ROOT / "tests" / "data"
CASES = {  # name: (example case, packing, YADE rows, title)
    "hertz": ("hertz_mindlin.toml", "triaxial_800_hertz/packing.txt",
              "triaxial_800_hertz/yade_0.csv",
              "800 spheres, Hertz-Mindlin (E 70 GPa, nu 0.25)"),
    "elongated": ("clumps.toml", "triaxial_clumps/elongated.txt",
                  "triaxial_clumps/yade_elongated.csv",
                  "400 two-sphere clumps, aspect 1.5, linear law"),
    "tetrahedral": ("clumps_tetrahedral.toml", "triaxial_clumps/tetrahedral.txt",
                    "triaxial_clumps/yade_tetrahedral.csv",
                    "200 tetrahedral four-sphere clumps, linear law"),
}


def run(name: str, realisations: int = 1) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(grainscale runs, YADE runs) of case `name`, each an array of rows: axial strain,
    q/p, eps_v from the first step on (module docstring for the realisations)."""
    example, packing, ref, _ = CASES[name]
    case = tomllib.loads((ROOT / "examples" / "rve" / example).read_text())
    ours = []
    for k in range(realisations):
        batch = rve.packing(case, [DATA / packing])
        if k > 0:
            grains = batch.bv if batch.clumped else batch.v
            grains += np.random.default_rng(k - 1).normal(0.0, 1e-9, grains.shape)
        rows = rve.rows_of(rve.triaxial(case, batch, progress=False))[1:]
        ours.append(np.array([[r["axial_strain"], r["q_over_p"], r["volumetric_strain"]]
                              for r in rows]))
    files = [DATA / ref] if realisations == 1 else sorted(
        (DATA / ref).parent.glob((DATA / ref).stem + "*.csv"))
    yade = [np.loadtxt(f, delimiter=",", skiprows=1)[1:, :3] for f in files]  # row 0: no step
    return ours, yade


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=sorted(CASES))
    ap.add_argument("--realisations", type=int, default=1)
    ap.add_argument("--png", type=Path, help="folder of the figures (NAME_yade.png)")
    args = ap.parse_args(argv)
    results = {}
    keys = ("peak", "residual", "eps_v_10", "eps_v_20")
    print(f"{'case':>12} {'code':>10} {'runs':>4} {'peak q/p':>13} {'residual':>13} "
          f"{'eps_v 10%':>15} {'eps_v 20%':>15}")
    for name in [args.only] if args.only else list(CASES):
        ours, yade = run(name, args.realisations)
        results[name] = {}
        for code, runs in (("grainscale", ours), ("yade", yade)):
            f = [figures(*r.T) for r in runs]
            mean = {k: float(np.mean([x[k] for x in f])) for k in keys}
            std = {k: float(np.std([x[k] for x in f], ddof=1)) if len(f) > 1 else 0.0
                   for k in keys}
            results[name][code] = {"runs": len(f), "mean": mean, "std": std}
            cells = " ".join(f"{mean[k]:>7.4f}+-{std[k]:<6.4f}" for k in keys)
            print(f"{name:>12} {code:>10} {len(f):>4} {cells}")
        if args.png:
            draw(ours, yade, CASES[name][3], args.png / f"{name}_yade.png")
    print(json.dumps(results))
    return 0


def draw(ours: list[np.ndarray], yade: list[np.ndarray], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for runs, label, color in ((ours, "grainscale", "C0"), (yade, "YADE 2023.02a", "C3")):
        for k, curve in enumerate(runs):
            kw = {"label": label} if k == 0 else {}
            ax1.plot(curve[:, 0], curve[:, 1], color=color, lw=0.8, alpha=0.8, **kw)
            ax2.plot(curve[:, 0], curve[:, 2], color=color, lw=0.8, alpha=0.8)
    ax1.set(xlabel="axial strain", ylabel="q/p")
    ax2.set(xlabel="axial strain", ylabel="eps_v = ln(V/V0)")
    ax1.legend(fontsize=8)
    fig.suptitle(f"{title}, 100 kPa, 0.25 /s")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    raise SystemExit(main())

"""Friction angles of elongated clumps against their aspect ratio.

    python studies/grains/aspect_ratio.py run ASPECT --out DIR [--packings 8]
        [--spheres 3] [--axes z] [--particles N]
    python studies/grains/aspect_ratio.py table DIR [--png FILE]

`run`: the recipe of examples/rve/clumps.toml (400 grains of member radius 3-7 mm, linear
law, mu 0.5, damping 0.2, consolidated at 100 kPa at the real friction) with grains
`--spheres` equal spheres on a line, `ASPECT` times as long as wide; ASPECT 1 is the same
recipe of plain spheres. `--particles` replaces the 400 grains (a cell must be 8 grain
reaches wide: aspect 2.5 needs about 500). `--packings` packings (seeds 1, 2, ...) are
generated and each is sheared in the recipe's drained triaxial (100 kPa, 0.25 /s to
30 %) along `--axes` by studies/intrusion/friction_angle.py, whose steady angle (mean
mobilised angle beyond 10 % axial strain) and peak angle are reported with a 95 % band
over packings. Writes DIR/aspect_ASPECT/phi.json, the packings next to it (cached: a
stopped run goes on from the last packing written) and the case file it ran.

`table`: the angles of every DIR/aspect_*/phi.json, a line each, and with --png the
steady and peak angles against aspect ratio with their bands.
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "studies" / "intrusion"))
import friction_angle  # noqa: E402

RECIPE = ROOT / "examples" / "rve" / "clumps.toml"


def case_text(aspect: float, spheres: int, particles: int | None = None) -> str:
    """The recipe's TOML with the clump table of this aspect (none at aspect 1)."""
    data = tomllib.loads(RECIPE.read_text())
    if particles is not None:
        data["rve"]["particles"] = particles
    lines = ["[rve]"] + [f"{k} = {v!r}" for k, v in data["rve"].items()
                          if not isinstance(v, dict)]
    if aspect > 1.0:
        lines += ["", "[rve.clump]", 'template = "elongated"', f"aspect = {aspect!r}",
                  f"spheres = {spheres}"]
    for table in ("preparation",):
        lines += ["", f"[rve.{table}]"] + [f"{k} = {v!r}"
                                           for k, v in data["rve"][table].items()]
    lines += ["", "[triaxial]"] + [f"{k} = {v!r}".replace("'", '"')
                                   for k, v in data["triaxial"].items()]
    return "\n".join(lines) + "\n"


def run(aspect: float, out: Path, packings: int, spheres: int, axes: list[str],
        particles: int | None = None) -> int:
    folder = out / f"aspect_{aspect:g}"
    folder.mkdir(parents=True, exist_ok=True)
    case = folder / "case.toml"
    case.write_text(case_text(aspect, spheres, particles))
    return friction_angle.main([str(case), "--realisations", str(packings),
                                "--axes", *axes, "--out", str(folder / "phi.json")])


def table(out: Path, png: Path | None) -> int:
    rows = []
    for f in sorted(out.glob("aspect_*/phi.json")):
        r = json.loads(f.read_text())
        rows.append((float(f.parent.name.split("_", 1)[1]), r))
    if not rows:
        raise SystemExit(f"{out}: no aspect_*/phi.json; run `run ASPECT --out {out}` first")
    rows.sort(key=lambda x: x[0])
    print(f"{'aspect':>6} {'grains':>6} {'packings':>8} {'steady [deg]':>15} "
          f"{'peak [deg]':>15}")
    for a, r in rows:
        grains = tomllib.loads((out / f"aspect_{a:g}" / "case.toml").read_text())["rve"][
            "particles"]
        print(f"{a:>6g} {grains:>6} {len(r['packings']):>8} {r['phi_deg']:>8.2f} +- "
              f"{r['phi_band95_deg']:<4.2f} {r['peak_phi_deg']:>8.2f} +- "
              f"{r['peak_phi_band95_deg']:<4.2f}")
    if png is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5, 4))
        a = [x for x, _ in rows]
        for key, label, marker in (("phi", "steady (axial strain >= 10 %)", "o"),
                                   ("peak_phi", "peak", "s")):
            ax.errorbar(a, [r[f"{key}_deg"] for _, r in rows],
                        yerr=[r[f"{key}_band95_deg"] for _, r in rows],
                        marker=marker, capsize=3, label=label)
        ax.set(xlabel="aspect ratio (length / width)", ylabel="friction angle [deg]",
               title="elongated clumps of 3 spheres, 100 kPa")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(png, dpi=110)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("aspect", type=float)
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--packings", type=int, default=8)
    r.add_argument("--spheres", type=int, default=3)
    r.add_argument("--axes", nargs="+", choices=["x", "y", "z"], default=["z"])
    r.add_argument("--particles", type=int, help="grains (default the recipe's 400)")
    t = sub.add_parser("table")
    t.add_argument("out", type=Path)
    t.add_argument("--png", type=Path)
    args = ap.parse_args(argv)
    if args.command == "run":
        if not 1.0 <= args.aspect <= 4.0:
            ap.error(f"aspect = {args.aspect}: valid range [1, 4] (1: plain spheres)")
        return run(args.aspect, args.out, args.packings, args.spheres, args.axes,
                   args.particles)
    return table(args.out, args.png)


if __name__ == "__main__":
    raise SystemExit(main())

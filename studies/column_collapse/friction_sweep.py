"""Mohr-Coulomb column collapse against the friction angle, in mu_i.toml's geometry.

    python studies/column_collapse/friction_sweep.py --out DIR [--cell 5]
        [--angles 20 22 25 30 35] [--velocity-update apic]

Each run is mu_i.toml's column (frictional floor 0.466, one-sided frictionless back
wall, its velocity update unless --velocity-update names another) with a Mohr-Coulomb
material of that friction angle (psi = 0, c = 0, same density and elastic moduli), at
cells of --cell mm, to 7 tau_c (runs already complete in DIR are reused). Prints a
table and, last, one JSON object {angle: runout}; writes DIR/sweep.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import grainscale as gs

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]  # convergence.py; studies/: variants.py
from convergence import case_at, measures, variant  # noqa: E402
from variants import run_variant  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--cell", type=float, default=5.0, help="cell size in mm")
    ap.add_argument("--angles", type=float, nargs="+", default=[20.0, 22.0, 25.0, 30.0, 35.0])
    ap.add_argument("--velocity-update", default=None, choices=["apic", "flip", "aflip"],
                    help="instead of mu_i.toml's (its flip or relaxation time dropped)")
    args = ap.parse_args()
    rows = {}
    for phi in args.angles:
        out = args.out / (f"mc_{phi:g}deg_{args.cell:g}mm"
                          + variant(2, "friction", 0.5, 7.0, args.velocity_update))
        wall = run_variant(case_at(args.cell * 1e-3, "mohr_coulomb", phi,
                                   update=args.velocity_update), out)
        m = measures(gs.open_result(out / "run").history)
        rows[f"{phi:g}"] = round(m["runout"], 4)
        print(f"phi {phi:4g} deg, {args.cell:g} mm: runout {m['runout']:.3f}, H_f/H_i "
              f"{m['height_ratio']:.3f}, front stops at {m['front_stop_t_over_tc']:.2f} "
              f"tau_c, {wall:.0f} s", flush=True)
    (args.out / "sweep.json").write_text(json.dumps(rows, indent=1))
    print(json.dumps(rows))


if __name__ == "__main__":
    main()

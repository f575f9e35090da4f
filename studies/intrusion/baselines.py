"""Continuum baselines of a multiscale intrusion case: Mohr-Coulomb and mu(I) beds in the
very same geometry.

    python studies/intrusion/baselines.py --phi-from phi.json --out DIR
        [--cases quick.toml quick_cuboid.toml] [--materials mohr_coulomb mu_i]
        [--cell-size H] [--points-per-cell N] [--quarter WIDTH DEPTH]
        [--to-depth D_OVER_R] [--young E] [--contact nodes|penalty] [--friction MU]

For each case (in examples/intrusion/ unless a path is given) and material, the case with
its DEM material replaced by a continuum of friction angle phi (the RVE's, measured by
friction_angle.py), the bed's density and the RVE's measured secant stiffness, run into
DIR/<material>_<case stem>; the probes, the [rve] and [triaxial] tables and the DEM
history columns are dropped. `--cell-size`, `--points-per-cell` and `--quarter` (the
quarter's side and the bed's depth, m) rerun the same cases on another grid or bed, to
tell the discretisation's and the boundaries' share of a slope from the material's;
`--to-depth` drives the intruder deeper than the case does, `--young` sets the
continuum's Young's modulus [Pa] (default 10 MPa, the RVE's secant modulus);
`--contact` and `--friction` replace the intruder's contact (`nodes`: no-slip, a rough
surface; `penalty` with the Coulomb coefficient `--friction`, default 0: smooth), to
tell the surface's share of a slope or of the zone that moves with the intruder.
Then `analyse.py` compares them, e.g.
    python examples/intrusion/analyse.py DIR/mohr_coulomb_quick DIR/mohr_coulomb_quick_cuboid
        --phi-from phi.json
A run already complete in DIR is not repeated. The last printed line is one JSON object
with the runs' folders and wall times.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from reshape import add_args, check_args, reshape, surface, to_depth

import grainscale as gs

STUDIES = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(STUDIES))  # studies/variants.py
from variants import run_variant  # noqa: E402

CASES = STUDIES.parent / "examples" / "intrusion"  # the case files
DENSITY = 1600.0  # kg/m3: grains of 2650 kg/m3 at porosity 0.397 (seed §4.3)
YOUNG = 10e6  # Pa: the RVE's drained secant modulus to ~7e-4 strain at 10 kPa (validation §3)
NU = 0.3


def continuum(material: str, phi: float, young: float = YOUNG) -> dict:
    if material == "mohr_coulomb":
        return {"type": "mohr_coulomb", "density": DENSITY, "youngs_modulus": young,
                "poisson_ratio": NU, "friction_angle": phi, "dilation_angle": 0.0,
                "cohesion": 0.0, "tension_cutoff": 0.0}
    # mu(I) with mu_s = tan phi; quasi-static intrusion keeps I << I_0, so mu ~ mu_s
    mu_s = math.tan(math.radians(phi))
    return {"type": "mu_i", "density": DENSITY, "youngs_modulus": young, "poisson_ratio": NU,
            "mu_s": mu_s, "mu_2": mu_s + 0.26, "I_0": 0.279, "grain_diameter": 0.01,
            "grain_density": 2650.0}


def baseline_case(path: Path, material: str, phi: float, young: float = YOUNG) -> gs.Case:
    """The case file's continuum twin: its DEM material replaced by `continuum(material,
    phi, young)`; the [rve] and element-test tables, the probes, the DEM history columns
    and the checkpoints dropped (gs.Case.continuum_twin)."""
    case = gs.load_case(path)
    return case.continuum_twin(continuum(material, phi, young),
                               title=f"{case.title}: {material} baseline, phi = {phi:g} deg")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--cases", nargs="+", default=["quick.toml", "quick_cuboid.toml"])
    ap.add_argument("--materials", nargs="+", default=["mohr_coulomb", "mu_i"],
                    choices=["mohr_coulomb", "mu_i"])
    add_args(ap)
    ap.add_argument("--young", type=float, default=YOUNG, help="Pa (default %(default)g)")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--phi", type=float, help="friction angle [deg]")
    g.add_argument("--phi-from", type=Path, help="JSON with phi_deg (friction_angle.py)")
    args = ap.parse_args()
    phi = args.phi if args.phi is not None else json.loads(args.phi_from.read_text())["phi_deg"]
    if not 0.0 < phi < 60.0:
        raise SystemExit(f"phi = {phi} deg: valid 0 < phi < 60")
    check_args(args.cell_size, args.points_per_cell, args.quarter, args.contact,
               args.friction)
    if not 1e4 <= args.young <= 1e10:
        raise SystemExit(f"--young {args.young:g}: valid 1e4 to 1e10 Pa")
    width, depth = args.quarter if args.quarter is not None else (None, None)
    cases = {}  # every case built (and checked) before the first run
    for name in args.cases:
        path = Path(name) if Path(name).is_file() else CASES / name
        if not path.is_file():
            raise SystemExit(f"--cases {name}: no such file (here or in {CASES})")
        for material in args.materials:
            case = reshape(baseline_case(path, material, phi, args.young), args.cell_size,
                           args.points_per_cell, width, depth)
            if args.to_depth is not None:
                to_depth(case, args.to_depth)
            if args.contact is not None:
                surface(case, args.contact, args.friction or 0.0)
            cases[(path, material)] = case
    runs = {}
    for (path, material), case in cases.items():
        out = args.out / f"{material}_{path.stem}"
        wall = run_variant(case, out)
        print(f"{material} {path.name}: {out / 'run'} ({wall:.0f} s)", flush=True)
        runs[f"{material}_{path.stem}"] = {"run": str(out / "run"), "wall_s": round(wall)}
    print(json.dumps({"phi_deg": phi, "runs": runs}))


if __name__ == "__main__":
    main()

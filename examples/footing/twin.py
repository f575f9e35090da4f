"""The Mohr-Coulomb twin of footing.toml: the same bed, footing, surcharge and stages,
the RVEs replaced by a Mohr-Coulomb continuum at a friction angle (README.md).

    python examples/footing/twin.py --phi 19.48 26.0 --out footing_mc

Runs footing.toml with `materials.sand` a `mohr_coulomb` material (c = 0, no dilation,
the intrusion twins' elasticity E = 10 MPa, nu = 0.3, docs/validation.md §3.2; the
RVE's bulk density) at each --phi, into OUT/phi_PHI. Weightless, so only the angle sets
the limit load (elasticity sets how soon it is reached).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import grainscale as gs

HERE = Path(__file__).resolve().parent
DENSITY = 2650.0 * (1 - 0.397)  # kg/m3: the RVE's grains at its porosity


def twin(phi: float) -> gs.Case:
    case = gs.load_case(HERE / "footing.toml")
    case.materials = {"sand": {"type": "mohr_coulomb", "density": DENSITY,
                               "youngs_modulus": 10e6, "poisson_ratio": 0.3,
                               "friction_angle": phi}}
    case.output.history = [c for c in case.output.history
                           if c not in ("porosity", "coordination")]  # RVE columns
    case.title = f"strip footing, Mohr-Coulomb twin, phi = {phi:g} deg"
    return case.check()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--phi", type=float, nargs="+", default=[19.48, 26.0],
                    help="friction angles [deg] (default: the RVE's steady and peak)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--threads", type=int)
    args = ap.parse_args()
    for phi in args.phi:
        case = twin(phi)  # invalid angles are refused here, before any run
        gs.run(case, args.out / f"phi_{phi:g}", threads=args.threads)


if __name__ == "__main__":
    main()

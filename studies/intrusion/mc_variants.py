"""The Mohr-Coulomb intrusion example against Kang's law at its own friction angle: how
the slope K_phi moves with the bed's size, the grid and the intruder's contact.

    python studies/intrusion/mc_variants.py --out DIR [--variants base wide penalty
        wide_penalty fine]

Each variant is `mohr_coulomb.toml` (examples/intrusion/: phi = 30 deg, K_theory = 41.9)
with one change, run into DIR/<variant>:
- base: as written (2.5 x 2.5 m quarter = 5 R, 2 m bed = 4 R, 0.125 m cells = 4 over R,
  the no-slip `nodes` contact);
- wide: a 3.75 x 3.75 m quarter (7.5 R) of a 3 m bed (6 R);
- penalty: the `penalty` contact with friction 0.3 (a smooth, frictional, separable
  intruder surface; docs/mpm.md: rigid body);
- wide_penalty: both;
- fine: 0.0833 m cells (6 over R);
- fine_penalty, fine8_penalty: the penalty contact on 0.0833 and 0.0625 m cells (6 and 8
  over R, the seed's resolution).
Then the slopes are fitted by analyse.py's rule (steady window of d/R) and printed
against K_theory; a run complete in DIR is not repeated. The last printed line is one
JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from reshape import reshape

import grainscale as gs

STUDIES = Path(__file__).resolve().parents[1]
CASES = STUDIES.parent / "examples" / "intrusion"  # the case files, and analyse.py
sys.path[:0] = [str(STUDIES), str(CASES)]  # studies/variants.py, examples/intrusion/analyse.py
from analyse import analyse, table  # noqa: E402
from variants import run_variant  # noqa: E402

PHI = 30.0  # deg, mohr_coulomb.toml's friction angle

VARIANTS = {
    "base": {},
    "wide": {"width": 3.75, "depth": 3.0},
    "penalty": {"contact": "penalty", "friction": 0.3},
    "wide_penalty": {"width": 3.75, "depth": 3.0, "contact": "penalty", "friction": 0.3},
    "fine": {"cell": 0.125 / 1.5},
    "fine_penalty": {"cell": 0.125 / 1.5, "contact": "penalty", "friction": 0.3},
    "fine8_penalty": {"cell": 0.0625, "contact": "penalty", "friction": 0.3},
}


def variant_case(width: float = 2.5, depth: float = 2.0, cell: float = 0.125,
                 contact: str | None = None, friction: float = 0.0) -> gs.Case:
    """mohr_coulomb.toml on a width x width quarter of a bed `depth` deep [m], cells of
    `cell` m, and the intruder's contact (default: the file's)."""
    case = reshape(gs.load_case(CASES / "mohr_coulomb.toml"), cell, width=width, depth=depth)
    if contact is not None:
        case.rigid.contact = contact
        case.rigid.friction = friction
    return case


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS)[:5], choices=list(VARIANTS),
                    help="default: the first five (fine_penalty takes ~21 min on one "
                         "thread; fine8_penalty ~6 h, 10 %% of it took 35 min)")
    args = ap.parse_args()
    walls = {}
    for name in args.variants:
        walls[name] = run_variant(variant_case(**VARIANTS[name]), args.out / name)
        print(f"{name}: {walls[name]:.0f} s", flush=True)
    summary = analyse([args.out / v for v in args.variants], PHI,
                      png=args.out / "mc_variants.png")
    print(table(summary))
    print(json.dumps({"K_theory": summary["K_theory"],
                      "K_phi": dict(zip(args.variants, (round(r["K_phi"], 2)
                                                        for r in summary["runs"]), strict=True)),
                      "p_0": dict(zip(args.variants, (round(r["p_0"], 2)
                                                      for r in summary["runs"]), strict=True)),
                      "wall_s": walls}))


if __name__ == "__main__":
    main()

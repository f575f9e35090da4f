"""Does a thin periodic cell make the RVE stronger? Isochoric plane extension of a
packing and of its 2 x 2 x 2 supercell (the same grains, eight times), side by side.

The cell follows F = diag(e^t, 1, e^-t) at a constant rate through the RVE material (the
same path as an MPM point), with no stress control, so p wanders; compare q/p at equal
stretch, the small cell's narrowest width in grain diameters beside it.

    python studies/column_collapse/stretch_rve.py PACKING.h5 [--case quick.toml]
        [--rate 5] [--max-stretch 4.5]

PACKING.h5: a packing of the case, e.g. OUT/packings/sand_0.h5 of a quick-column run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from grainscale import rve
from grainscale.analysis import p_q
from grainscale.blocks import (
    RVEMaterial,
    SimulationError,
    from_packing,
    perpendicular_widths,
    read_rve_state,
)

CASES = Path(__file__).resolve().parents[2] / "examples" / "column_collapse"  # the case files


def stretched(material: RVEMaterial, rate: float, max_stretch: float, d: float = 2e-3):
    """Rows (stretch, narrowest width in diameters, p, q/p) every 0.1 of log-stretch."""
    dH = np.diag([np.expm1(d), 0.0, np.expm1(-d)])[None]
    sig = material.initial_stress()
    diameter = 2 * material.batch.radius[0].max()
    rows = []
    for k in range(1, int(np.log(max_stretch) / d) + 1):
        try:
            material.update(dH, d / rate, sig)
        except SimulationError:
            break  # cell too thin for its spheres
        if k % 50 == 0:
            p, q = p_q(sig)
            w = perpendicular_widths(np.ascontiguousarray(material.batch.h[0])).min()
            rows.append((np.exp(k * d), w / diameter, p[0], q[0] / max(p[0], 1e-12)))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("packing", type=Path)
    ap.add_argument("--case", type=Path, default=CASES / "quick.toml")
    ap.add_argument("--rate", type=float, default=5.0, help="1/s")
    ap.add_argument("--max-stretch", type=float, default=4.5)
    args = ap.parse_args()
    params = rve.load(args.case).rve  # the case's validated RVEParams
    b, _ = read_rve_state(args.packing)
    h, r = b.h[0], b.radius[0]
    x = b.s[0] @ h.T
    shifts = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    big = from_packing(2 * h, np.concatenate([x + s @ h.T for s in shifts]), np.tile(r, 8),
                       params.density)
    runs = {n: stretched(RVEMaterial(n, params, [batch], 1, retile_width=0.0), args.rate,
                         args.max_stretch)
            for n, batch in [(f"{len(r)}", from_packing(h, x, r, params.density)),
                             (f"{8 * len(r)} (2x2x2)", big)]}
    print(f"{'stretch':>7} | " + " | ".join(f"{n:>28}" for n in runs))
    print(f"{'':>7} | " + " | ".join(f"{'width [d]':>9} {'p [Pa]':>8} {'q/p':>9}"
                                     for _ in runs))
    for i in range(max(len(v) for v in runs.values())):
        cells = []
        for v in runs.values():
            cells.append(f"{v[i][1]:9.2f} {v[i][2]:8.0f} {v[i][3]:9.3f}" if i < len(v)
                         else f"{'(too thin)':>28}")
        stretch = next(v[i][0] for v in runs.values() if i < len(v))
        print(f"{stretch:7.2f} | " + " | ".join(cells))


if __name__ == "__main__":
    main()

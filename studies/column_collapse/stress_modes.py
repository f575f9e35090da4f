"""How the weight of a column at rest is shared between its points: layer means
against the lithostatic stress, and the median stress of each sub-cell position.

    python studies/column_collapse/stress_modes.py RUN [--frames 1 -1] [--behind 0.05]
    python studies/column_collapse/stress_modes.py DIR --geostatic {rve,mohr-coulomb}
        [--shape GIMP|linear] [--library N] [--points-per-cell N] [--frames -1]

For the points initially behind x = --behind (the part of the column that stays at
rest), per frame: the vertical stress sigma_zz (compression positive) of each 1-cell
layer, its mean against rho_bulk g (top - z) (the weight above: the layer means must
carry it) and its 10/50/90th percentiles; and the median sigma_zz of the points by
their initial sub-cell position (x, z parity of their position in half cells: with
2 x 2 x 2 points a cell, which of the cell's points it was). A smooth field has equal
medians; a field whose cells carry the weight on some of their points only (an
intra-cell stress mode: the cell's nodal forces do not see how its points share the
stress) has medians apart by the layer's stress.

--geostatic first runs quick.toml's geostatic stage (to t = 0) into DIR, with its RVEs
(~2 min on one core) or with a Mohr-Coulomb continuum (phi 22 deg, E = 19 MPa, about
the RVE's P-wave modulus, nu 0.3, 1500 kg/m3; ~1 min) on the same grid and points, with
GIMP or linear shape functions (--shape), the RVEs copies of --library packings
(quick.toml: 2, assigned at random; 1: every point a copy of the same packing), with
--points-per-cell N^3 points a cell (quick.toml: 2).
"""

from __future__ import annotations

import argparse
import glob
from pathlib import Path

import numpy as np

import grainscale as gs
from grainscale.analysis import read_frame

QUICK = Path(__file__).resolve().parents[2] / "examples" / "column_collapse" / "quick.toml"


def geostatic(out: Path, material: str, shape: str, library: int | None = None,
              points_per_cell: int | None = None) -> None:
    """quick.toml's geostatic stage with its RVEs (from `library` packings if given) or
    a Mohr-Coulomb continuum (module docstring)."""
    c = gs.load_case(QUICK)
    if library is not None:
        c.materials["sand"].library = library
    if points_per_cell is not None:
        c.bodies[0].points_per_cell = points_per_cell
    if material == "mohr-coulomb":
        c.materials = {"sand": {"type": "mohr_coulomb", "density": 1500.0,
                                "youngs_modulus": 19e6, "poisson_ratio": 0.3,
                                "friction_angle": 22.0}}
        c.output.history = ["time", "kinetic_energy"]
        c.output.column = None
    c.solver.shape = shape
    c.output.frame_interval = 0.01
    c.output.checkpoint_every = 0
    c.time.end = 0.0
    gs.run(c.check(), out, progress=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--frames", type=int, nargs="+", default=[1, -1],
                    help="frame indices (Python's: -1 the last)")
    ap.add_argument("--behind", type=float, default=0.05, help="m: points initially behind")
    ap.add_argument("--geostatic", choices=["rve", "mohr-coulomb"],
                    help="run quick.toml's geostatic stage into RUN first")
    ap.add_argument("--shape", choices=["GIMP", "linear"], default="GIMP",
                    help="shape functions of that run")
    ap.add_argument("--library", type=int, help="packings of that run's RVEs (default "
                    "quick.toml's 2)")
    ap.add_argument("--points-per-cell", type=int, help="n of that run's n^3 points a cell "
                    "(default quick.toml's 2)")
    args = ap.parse_args()
    if args.geostatic:
        geostatic(args.run, args.geostatic, args.shape, args.library, args.points_per_cell)
    case = gs.open_result(args.run).case
    h = case.grid.cell_size if np.isscalar(case.grid.cell_size) else case.grid.cell_size[0]
    n = next(b.points_per_cell for b in case.bodies)
    g = float(np.linalg.norm(case.solver.gravity))
    frames = sorted(glob.glob(str(args.run / "frames" / "frame_*.vtu")))
    _, first = read_frame(frames[0])
    x0 = first["position"]
    sel = x0[:, 0] < args.behind
    sub = np.floor(x0 / (h / n)).astype(int) % n  # the point's place within its cell
    for k in args.frames:
        _, d = read_frame(frames[k])
        x, szz = d["position"], -d["stress"].reshape(-1, 3, 3)[:, 2, 2]
        rho = None
        if "porosity" in d:
            rho = case.rve.density * (1 - float(np.median(d["porosity"][sel])))
        elif all(m.type != "dem" for m in case.materials.values()):
            rho = next(iter(case.materials.values())).density
        print(f"{Path(frames[k]).name}: points initially behind x = {args.behind} m")
        top = float((x[sel, 2] + 0.5 * h / n).max())
        for z in np.arange(0.0, top, h):
            lay = sel & (x[:, 2] >= z) & (x[:, 2] < z + h)
            if not lay.any():
                continue
            lith = f"{rho * g * (top - z - 0.5 * h):7.1f}" if rho else "    -"
            q = np.percentile(szz[lay], [10, 50, 90])
            print(f"  z {z:.3f}-{z + h:.3f} m: {lay.sum():3d} points, mean {szz[lay].mean():7.1f} "
                  f"Pa (weight above {lith}), 10/50/90 % {q[0]:7.1f} {q[1]:7.1f} {q[2]:7.1f}")
        print("  median sigma_zz by sub-cell (x, z):", ", ".join(
            f"({i}, {j}) {np.median(szz[sel & (sub[:, 0] == i) & (sub[:, 2] == j)]):.1f}"
            for i in range(n) for j in range(n)))


if __name__ == "__main__":
    main()

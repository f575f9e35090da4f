"""The MPM step on a graded grid: per-axis stencils against one width for every axis.

`examples/intrusion/seed_quick.toml`'s graded grid and bodies (0.0625 m cells near the
intruder, up to 0.48 m away from it; one point a cell) with its DEM material replaced by
a Mohr-Coulomb twin (so the step is the MPM's alone), timed over the same steps two
ways in one run: the stencil sized per axis from where the points are (the solver's
`rectilinear.stencil`), and one width for all three axes from the widest domain over
the smallest cell (floor(2 l_max / h_min) + 3), as a single global stencil would be.
Both give the same nodal values (the extra nodes carry zero weight); the printed
figures are seconds per MPM step, nodes per point and transfer, and their ratio. The
last line printed is one JSON object.

    python benchmarks/graded_stencil.py [--steps 20] [--threads 1]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numba
import numpy as np

import grainscale as gs
from grainscale.mpm import rectilinear
from grainscale.mpm.setup import build_state
from grainscale.mpm.step import step

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dem_update_cost import cpu_model  # noqa: E402

CASE = Path(__file__).resolve().parents[1] / "examples" / "intrusion" / "seed_quick.toml"
TWIN = {"type": "mohr_coulomb", "density": 1600.0, "youngs_modulus": 10e6,
        "poisson_ratio": 0.3, "friction_angle": 20.07, "dilation_angle": 0.0,
        "cohesion": 0.0, "tension_cutoff": 0.0}


def global_width(x, lp, axes, gimp=True) -> np.ndarray:
    """One width for every axis: the widest domain over the smallest cell of any axis."""
    if not gimp:
        return np.full(3, 2, dtype=np.int64)
    n = max(math.floor(2.0 * float(lp[:, a].max()) / float(np.diff(axes[a]).min())) + 3
            for a in range(3))
    return np.full(3, n, dtype=np.int64)


def timed(steps: int, threads: int, width=None) -> dict:
    """Seconds per MPM step of the twin (after 2 warm-up steps), and its stencil."""
    case = gs.load_case(CASE).continuum_twin(TWIN, title="seed_quick twin (benchmark)")
    s = build_state(case, CASE.parent, n_threads=threads)
    original = rectilinear.stencil
    if width is not None:
        rectilinear.stencil = width
    try:
        for _ in range(2):
            step(s, s.stable_dt())
        t0 = time.perf_counter()
        for _ in range(steps):
            step(s, s.stable_dt())
        wall = (time.perf_counter() - t0) / steps
    finally:
        rectilinear.stencil = original
    return {"s_per_step": wall, "stencil": s.ns.tolist(), "nodes_per_point": int(s.ns.prod()),
            "points": s.points.n, "kinetic_energy": float(
                0.5 * s.points.m @ (s.points.v ** 2).sum(axis=1))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20, help="timed MPM steps per variant")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    numba.set_num_threads(args.threads)
    per_axis = timed(args.steps, args.threads)
    single = timed(args.steps, args.threads, global_width)
    ratio = single["s_per_step"] / per_axis["s_per_step"]
    for name, r in (("per-axis stencil", per_axis), ("one global width", single)):
        print(f"{name:18s}: {r['s_per_step'] * 1e3:8.2f} ms per MPM step, stencil "
              f"{r['stencil']} ({r['nodes_per_point']} nodes a point), {r['points']} points")
    print(f"{cpu_model()}, {args.threads} thread(s): speed-up {ratio:.2f}x; kinetic energies "
          f"{per_axis['kinetic_energy']:.9e} and {single['kinetic_energy']:.9e} (the same "
          "physics)")
    print(json.dumps({"cpu": cpu_model(),
                      "threads": args.threads, "steps": args.steps, "per_axis": per_axis,
                      "global": single, "speedup": ratio}))


if __name__ == "__main__":
    main()

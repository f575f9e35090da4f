"""MPM throughput: material-point steps per second (a whole USF step per point).

An elastic block under gravity with GIMP, 2 x 2 x 2 points per cell, sized to 1e4, 1e5
and 1e6 points; each size timed with one thread and with all threads after a warm-up
(compilation excluded). The last line printed is one JSON object.

    PYTHONPATH=src python benchmarks/mpm_throughput.py [--sizes 1e4 1e5 1e6] [--steps 10]
"""

from __future__ import annotations

import argparse
import json
import time

import numba
import numpy as np

from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.materials import LinearElastic
from grainscale.mpm.points import fill_box, make_points
from grainscale.mpm.step import MPMState, step


def build(n_points: float, n_threads: int) -> MPMState:
    """A cubic block of about n_points points (8 per cell) in a grid one cell larger."""
    cells = max(2, round((n_points / 8) ** (1 / 3)))
    h = 0.01
    grid = Grid.make([0, 0, 0], h, [cells + 2, cells + 2, cells + 2])
    x, vol = fill_box(grid, [h, h, 0.0], [(cells + 1) * h, (cells + 1) * h, cells * h], 2)
    pts = make_points(x, vol, 2000.0, 0)
    mat = LinearElastic("e", pts.n, density=2000.0, youngs_modulus=1e7, poisson_ratio=0.3)
    s = MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None],
                 gravity=np.array([0.0, 0.0, -9.81]), n_threads=n_threads)
    s.constraints = [boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None)]
    return s


def measure(n_points: float, n_threads: int, steps: int) -> tuple[int, float]:
    numba.set_num_threads(n_threads)
    s = build(n_points, n_threads)
    for _ in range(2):  # warm-up (and compilation on the first call)
        step(s, s.stable_dt())
    t0 = time.perf_counter()
    for _ in range(steps):
        step(s, s.stable_dt())
    wall = time.perf_counter() - t0
    return s.points.n, s.points.n * steps / wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[1e4, 1e5, 1e6])
    ap.add_argument("--steps", type=int, default=10, help="timed steps per size")
    args = ap.parse_args()
    all_threads = numba.config.NUMBA_NUM_THREADS
    results = []
    for n in args.sizes:
        steps = max(3, int(args.steps * 1e5 / max(n, 1e5)))  # shorter for the big ones
        P, r1 = measure(n, 1, steps)
        _, rn = measure(n, all_threads, steps)
        results.append({"points": P, "steps": steps, "point_steps_per_s_1thread": r1,
                        f"point_steps_per_s_{all_threads}threads": rn})
        print(f"{P:>9d} points: {r1:10.3e} point-steps/s (1 thread), "
              f"{rn:10.3e} ({all_threads} threads)", flush=True)
    numba.set_num_threads(all_threads)
    head = max(results, key=lambda r: r["points"])
    print(json.dumps({"benchmark": "mpm_throughput", "shape": "GIMP", "scheme": "USF",
                      "threads_all": all_threads,
                      "point_steps_per_s_1thread": head["point_steps_per_s_1thread"],
                      "point_steps_per_s_all_threads":
                          head[f"point_steps_per_s_{all_threads}threads"],
                      "points": head["points"], "sizes": results}))


if __name__ == "__main__":
    main()

"""Cost of a coupled update of quasi-static RVEs against the DEM steps it takes.

    python benchmarks/dem_update_cost.py [--case examples/intrusion/quick.toml]
        [--rves 64 2048] [--steps 1 2 4 8 16 32]

A quasi-static RVE takes ceil(max|dH| / strain_per_substep) DEM steps per MPM step
(docs/coupling.md), so in an intrusion most RVEs, far from the intruder, take one or two
while a few under it take hundreds. This times `engine.advance` on a batch of the
case's RVE recipe (two packings, copies of each) over a small random increment applied
in n steps, for each n, on one thread, best of 3; a straight-line fit of the time per
RVE, a + b n, splits it into a fixed cost per call a and a cost per step b. Two batch
sizes tell what the fixed part is: a batch whose state fits in the caches against one
that does not (each RVE's state is then read from memory once per call).
Prints one line per batch and n, then one JSON object with the fits.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from grainscale.config.case import STRAIN_PER_SUBSTEP, load_rve_case
from grainscale.coupling.materials import cached_packing
from grainscale.dem import engine
from grainscale.dem.generate import contact_params
from grainscale.dem.state import concatenate

ROOT = Path(__file__).resolve().parents[1]


def cpu_model() -> str:
    """The CPU's model name (Linux), else what platform knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def timings(base, cp, safety: float, n_rves: int, steps: list[int],
            strain: float) -> dict[int, float]:
    """Best-of-3 seconds per RVE of one `engine.advance` call taking n steps, per n."""
    batch = concatenate([base[k % len(base)] for k in range(n_rves)])
    engine.refresh(batch, cp)
    dt = engine.critical_dt(batch, cp, safety)
    rng = np.random.default_rng(0)

    def call(n: int) -> float:
        dH = strain * n * rng.standard_normal((n_rves, 3, 3))
        ctrl = engine.increment_control(batch, dH, n, dt)
        t0 = time.perf_counter()
        engine.advance(batch, n, dt, cp, ctrl)
        return time.perf_counter() - t0

    call(1)  # compile, and bring the batch into its steady contact state
    best = {n: np.inf for n in steps}
    for _ in range(3):
        for n in steps:
            best[n] = min(best[n], call(n) / n_rves)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=Path, default=ROOT / "examples/intrusion/quick.toml")
    ap.add_argument("--rves", type=int, nargs="+", default=[64, 2048])
    ap.add_argument("--steps", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32])
    args = ap.parse_args()
    if min(args.rves) < 1 or min(args.steps) < 1 or len(set(args.steps)) < 2:
        raise SystemExit("--rves and --steps: positive, and at least two different --steps")
    numba.set_num_threads(1)
    case = load_rve_case(args.case)
    cp = contact_params(case.rve)
    with tempfile.TemporaryDirectory() as tmp:
        base = [cached_packing(case.rve, k, Path(tmp) / f"p{k}.h5", progress=False)
                for k in range(2)]
    # components of ~0.3 strain_per_substep (the default) a step: the largest of nine
    # stays near the increment a quasi-static RVE takes per DEM step
    strain = 0.3 * STRAIN_PER_SUBSTEP
    npart = base[0].n_particles
    state_bytes = sum(v.nbytes for v in vars(base[0]).values() if isinstance(v, np.ndarray))
    fits = {}
    print(f"{cpu_model()}, one thread; state "
          f"{state_bytes / 1e3:.0f} kB per RVE", flush=True)
    for n_rves in args.rves:
        best = timings(base, cp, case.rve.numerics.timestep_safety, n_rves, args.steps,
                       strain)
        for n, t in best.items():
            print(f"{n_rves} RVEs x {npart} spheres, {n:3d} steps a call: {t * 1e6:8.2f} us "
                  f"per RVE, {t / (n * npart) * 1e9:6.1f} ns per particle-step", flush=True)
        ns = np.array(sorted(best), float)
        b, a = np.polyfit(ns, np.array([best[int(n)] for n in ns]), 1)
        fits[n_rves] = {"fixed_us_per_rve_call": round(float(a) * 1e6, 2),
                        "us_per_rve_step": round(float(b) * 1e6, 2),
                        "ns_per_particle_step": round(float(b) / npart * 1e9, 1),
                        "fixed_in_steps": round(float(a / b), 2),
                        "batch_MB": round(n_rves * state_bytes / 1e6, 1)}
        print(f"{n_rves} RVEs: {fits[n_rves]}", flush=True)
    print(json.dumps({"case": str(args.case), "particles": npart,
                      "state_bytes_per_rve": state_bytes, "cpu": cpu_model(), "threads": 1,
                      "fits": fits}))


if __name__ == "__main__":
    main()

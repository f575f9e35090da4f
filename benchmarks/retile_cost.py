"""What retiling a few RVEs costs in a large batch: whole-group copies against moving
only the RVEs concerned.

A batch of R RVEs of N spheres (copies of one generated packing, the state of a coupled
run's group) from which one RVE at a time is doubled (dem/retile.py), `--events` times,
as a coupled run doubles its thinnest cells: each event takes the doubled RVE out of the
N-sphere group and adds its double to the 2N-sphere group. Two ways, timed in one run:
- "copy": the group rebuilt without it (RVEBatch.take of the others) and the 2N group
  rebuilt with it (concatenate), two copies of both groups per event;
- "in place" (the solver's, coupling/rve_material.py): state.remove_rves moves the last
  RVE into the slot, state.extend writes the double into the 2N group's spare rows.
Both end with the same RVEs (checked). Prints milliseconds per event and their ratio,
the last line one JSON object.

    python benchmarks/retile_cost.py [--rves 3072] [--particles 150] [--events 20]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import fields
from pathlib import Path

import numpy as np

from grainscale.config.rve import RVEParams
from grainscale.dem import retile
from grainscale.dem.generate import generate
from grainscale.dem.state import RVEBatch, concatenate, extend, remove_rves

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dem_update_cost import cpu_model  # noqa: E402


def copying(group: RVEBatch, events: int) -> tuple[float, RVEBatch, RVEBatch]:
    """The copy-based way: seconds per event, and the two groups at the end."""
    doubled = None
    t0 = time.perf_counter()
    for _ in range(events):
        r = int(np.argmin(group.s[:, 0, 0]))  # the same RVE whatever the order
        d = retile.double_cell(group, r, 0)
        group = group.take(np.flatnonzero(np.arange(group.n_rve) != r))
        doubled = d if doubled is None else concatenate([doubled, d])
    return (time.perf_counter() - t0) / events, group, doubled


def in_place(group: RVEBatch, events: int) -> tuple[float, RVEBatch, RVEBatch]:
    """The solver's way: seconds per event, and the two groups at the end."""
    doubled, storage = None, None
    t0 = time.perf_counter()
    for _ in range(events):
        r = int(np.argmin(group.s[:, 0, 0]))
        d = retile.double_cell(group, r, 0)
        group, _ = remove_rves(group, [r])
        if doubled is None:
            doubled = d
        else:
            doubled, storage = extend(doubled, [d], storage)
    return (time.perf_counter() - t0) / events, group, doubled


def same_rves(a: RVEBatch, b: RVEBatch) -> bool:
    """The same RVEs, in any order (compared by their cells and positions)."""
    if a.n_rve != b.n_rve:
        return False
    key = lambda x: np.lexsort(x.s.reshape(x.n_rve, -1).T)  # noqa: E731
    ia, ib = key(a), key(b)
    return all(np.array_equal(getattr(a, f.name)[ia], getattr(b, f.name)[ib])
               for f in fields(RVEBatch) if f.name not in ("force", "torque", "x", "link"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rves", type=int, default=3072)
    ap.add_argument("--particles", type=int, default=150)
    ap.add_argument("--events", type=int, default=20)
    args = ap.parse_args()
    if args.rves <= args.events or args.events < 1:
        raise SystemExit(f"--rves {args.rves}, --events {args.events}: valid "
                         "rves > events >= 1")
    pack = generate(RVEParams(particles=args.particles))
    group = concatenate([pack] * args.rves)
    group.s += np.linspace(0.0, 1e-6, args.rves)[:, None, None]  # distinguishable RVEs
    t_copy, g1, d1 = copying(group.copy(), args.events)
    t_place, g2, d2 = in_place(group.copy(), args.events)
    assert same_rves(g1, g2) and same_rves(d1, d2)
    mb = sum(getattr(group, f.name).nbytes for f in fields(RVEBatch)) / 1e6
    print(f"{cpu_model()}: {args.rves} RVEs of {args.particles} spheres ({mb:.0f} MB), "
          f"one doubled per event: copy {t_copy * 1e3:.1f} ms, in place "
          f"{t_place * 1e3:.2f} ms per event ({t_copy / t_place:.0f}x)")
    print(json.dumps({"cpu": cpu_model(), "rves": args.rves, "particles": args.particles,
                      "events": args.events, "group_mb": mb, "copy_ms": t_copy * 1e3,
                      "in_place_ms": t_place * 1e3, "ratio": t_copy / t_place}))


if __name__ == "__main__":
    main()

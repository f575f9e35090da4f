"""Ripple of a rigid body's reaction: a strip punch pushed into a bed, both contact laws.

    python studies/intrusion/ripple.py [--material elastic mohr_coulomb]
        [--contact nodes penalty] [--cell 0.05] [--depth 0.2] [--png ripple.png]

Plane strain: a slice two cells thick between frictionless rollers, a 1 m x 0.6 m bed
(E = 10 MPa, nu = 0.3, rho = 1600 kg/m3; Mohr-Coulomb phi = 30 deg, psi = 0, c = 0, or
linear elastic) on a fixed base under gravity, geostatic stage of 0.3 s with local
damping; a rigid strip of half-width 0.15 m (symmetry plane x = 0) resting on the
surface is pushed down at 0.1 m/s (0.1 s ramp) to `--depth`. The reaction is recorded at
every step; the ripple is its deviation from a quadratic fit in depth beyond one cell,
as rms and largest value in % of the mean. Prints one line per run and, last, one JSON
object with every figure.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from grainscale.blocks import (
    BOX,
    Grid,
    LinearElastic,
    MohrCoulomb,
    MPMState,
    RigidBody,
    boundary,
    fill_box,
    make_points,
    step,
)

WIDTH, BED, HALF = 1.0, 0.6, 0.15  # m: bed width and height, strip half-width
RHO, E, NU = 1600.0, 1e7, 0.3
SPEED, RAMP = 0.1, 0.1  # m/s, s


def punch(material: str, contact: str, h: float, depth: float) -> tuple[np.ndarray, float]:
    """(depth [m], resistance [N]) at every step after the start, and the wall time."""
    grid = Grid.make([0, 0, 0], h, [round(WIDTH / h), 2, round((BED + 0.3) / h)])
    x, vol = fill_box(grid, [0, 0, 0], [WIDTH, 2 * h, BED], 2)
    pts = make_points(x, vol, RHO, 0)
    if material == "mohr_coulomb":
        mat = MohrCoulomb("bed", pts.n, density=RHO, youngs_modulus=E, poisson_ratio=NU,
                          friction_angle=30.0, dilation_angle=0.0, cohesion=0.0,
                          tension_cutoff=0.0)
    else:
        mat = LinearElastic("bed", pts.n, density=RHO, youngs_modulus=E, poisson_ratio=NU)
    s = MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None],
                 gravity=np.array([0.0, 0.0, -9.81]), damping=0.7, damping_end=0.0)
    s.time = -0.3
    s.constraints = [boundary.constraint(boundary.face_nodes(grid, f), "roller",
                                         boundary.FACES[f][0])
                     for f in ("x-", "x+", "y-", "y+")]
    s.constraints.append(boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None))
    xr, volr = fill_box(grid, [0, 0, BED], [HALF, 2 * h, BED + 0.2], 2)
    s.rigid = RigidBody(x=xr, lp=0.5 * np.cbrt(volr), velocity=np.array([0, 0, -SPEED]),
                        ramp_time=RAMP, start_time=0.0, kind=BOX,
                        geom=np.array([-HALF, -1.0, BED, HALF, 1.0, BED + 0.2, 0.0, 0.0]),
                        contact=contact)
    rows = []
    end = 0.5 * RAMP + depth / SPEED
    t0 = time.perf_counter()
    while s.time < end - 1e-12:
        step(s, min(s.stable_dt(), end - s.time))
        if s.time > 0.0:
            rows.append((-s.rigid.displacement[2], s.rigid.force[2]))
    return np.array(rows), time.perf_counter() - t0


def ripple(rec: np.ndarray, h: float) -> dict:
    d, f = rec[:, 0], rec[:, 1]
    sel = d > h
    fit = np.polyfit(d[sel], f[sel], 2)
    r = (f[sel] - np.polyval(fit, d[sel])) / f[sel].mean()
    return {"mean_force": float(f[sel].mean()), "rms_percent": float(100 * r.std()),
            "max_percent": float(100 * np.abs(r).max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--material", nargs="+", default=["elastic", "mohr_coulomb"],
                    choices=["elastic", "mohr_coulomb"])
    ap.add_argument("--contact", nargs="+", default=["nodes", "penalty"],
                    choices=["nodes", "penalty"])
    ap.add_argument("--cell", type=float, default=0.05, help="cell size [m]")
    ap.add_argument("--depth", type=float, default=0.2, help="final depth [m]")
    ap.add_argument("--png", default=None, help="plot the reactions against depth")
    args = ap.parse_args()
    results, curves = [], {}
    for material in args.material:
        for contact in args.contact:
            rec, wall = punch(material, contact, args.cell, args.depth)
            r = {"material": material, "contact": contact, "steps": len(rec),
                 "wall_s": round(wall, 1), **ripple(rec, args.cell)}
            results.append(r)
            curves[(material, contact)] = rec
            print(f"{material:13s} {contact:8s} mean {r['mean_force']:9.1f} N  ripple rms "
                  f"{r['rms_percent']:.2f} %  max {r['max_percent']:.1f} %  ({wall:.0f} s)",
                  flush=True)
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4))
        for (material, contact), rec in curves.items():
            ax.plot(rec[:, 0], rec[:, 1] / 1e3, lw=0.8, label=f"{material}, {contact}")
        ax.set(xlabel="depth (m)", ylabel="reaction (kN per slice)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(args.png, dpi=120)
    print(json.dumps({"cell": args.cell, "depth": args.depth, "runs": results}))


if __name__ == "__main__":
    main()

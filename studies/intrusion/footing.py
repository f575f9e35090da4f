"""The Mohr-Coulomb continuum of the intrusion twins against an exact limit load: a
strip footing on a weightless bed under a surcharge, Prandtl's N_q.

    python studies/intrusion/footing.py [--phi 20] [--cells-per-width 8 16]
        [--points-per-cell 2] [--settlement 0.1] [--friction 0] [--png footing.png]

The slope K_phi of the intrusion (docs/validation.md §3) is the resistance that the
weight of the soil beside the intruder gives it. The classical exact solution of that
part of bearing capacity is Prandtl's (1921) and Reissner's (1924): a strip footing of
width B on a weightless Mohr-Coulomb bed (phi, c = 0) under a surcharge q_0 beside it;
the limit pressure is q_u = N_q q_0, exact for an associated material, rough or smooth
footing alike, with

    N_q(phi) = exp(pi tan phi) tan^2(pi/4 + phi/2).

The twins' material does not dilate (psi = 0). For a non-associated material
Radenkovic's theorems bound the limit load between the associated ones at phi and at
Davis's reduced angle phi*, tan phi* = cos(psi) cos(phi) tan(phi) / (1 - sin psi sin phi)
(= sin phi at psi = 0): N_q(phi*) <= N_q <= N_q(phi); 5.73-6.40 at 20 deg, 12.6-18.4 at
30 deg.

The case: plane strain, a slice one cell thick between frictionless rollers; half the
footing (b = B/2 = 0.5 m) on the symmetry plane x = 0, rigid, `--friction` its Coulomb
coefficient (penalty contact, docs/mpm.md, as the intrusion's); a bed wider and deeper
than Prandtl's mechanism by 30 %, on a fixed base, rollers on the far side; the twins'
elasticity (E = 10 MPa, nu = 0.3, rho = 1600 kg/m3); surcharge q_0 = 10 kPa (the
intrusion bed's mean stress) on the surface beside the footing, ramped in over 0.05 s
with local damping until t = 0; then the footing is pushed down at 0.1 m/s (0.05 s
ramp; rho v^2 / q_0 = 2e-3, quasi-static) to `--settlement` B. The footing pressure q is
its reaction over its base in the slice (b times the slice's thickness); N_q = q / q_0,
read as the mean over the last half of the settlement (the plateau of the weightless
bed) and as the maximum.
Prints one line per run and, last, one JSON object with every figure. A run that fails
(points thrown out of the grid: one-point beds on 32 cells over B do so beyond ~0.18 B)
is reported with the settlement it reached, and the others go on.

At 20 deg the pressure levels off from 0.03 B; at 30 deg it still rises at 0.1 B, so
that angle needs a larger `--settlement` (docs/validation.md §3).
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from grainscale.blocks import (
    BOX,
    Grid,
    MohrCoulomb,
    MPMState,
    RigidBody,
    SimulationError,
    boundary,
    fill_box,
    make_points,
    step,
)

HALF = 0.5  # m: half-width b of the footing (B = 1 m)
RHO, E, NU = 1600.0, 10e6, 0.3  # the intrusion twins' bed (baselines.py)
SURCHARGE = 10e3  # Pa
SPEED, RAMP, LOAD_RAMP, SETTLE_TIME = 0.1, 0.05, 0.05, 0.2  # m/s, s, s, s


def prandtl_nq(phi: float) -> float:
    """N_q = exp(pi tan phi) tan^2(pi/4 + phi/2), phi in degrees (Prandtl-Reissner)."""
    p = math.radians(phi)
    return math.exp(math.pi * math.tan(p)) * math.tan(math.pi / 4 + p / 2) ** 2


def davis_angle(phi: float, psi: float = 0.0) -> float:
    """Davis's reduced friction angle [deg]: tan phi* = cos psi cos phi tan phi /
    (1 - sin psi sin phi), the associated material whose limit load bounds a
    non-associated one's from below (Radenkovic)."""
    p, s = math.radians(phi), math.radians(psi)
    return math.degrees(math.atan(math.cos(s) * math.sin(p) / (1.0 - math.sin(s) * math.sin(p))))


def mechanism(phi: float) -> tuple[float, float]:
    """(reach from the footing's axis, depth) [m] of Prandtl's mechanism under a footing
    of half-width HALF: the active wedge, the log-spiral fan from r_0 = b / cos(pi/4 +
    phi/2) to r_1 = r_0 exp((pi/2) tan phi), the passive wedge of surface length
    2 r_1 cos(pi/4 - phi/2); r_1 bounds the depth."""
    p = math.radians(phi)
    r1 = HALF / math.cos(math.pi / 4 + p / 2) * math.exp(0.5 * math.pi * math.tan(p))
    return HALF + 2.0 * r1 * math.cos(math.pi / 4 - p / 2), r1


def footing(phi: float, cells_per_width: int, settlement: float, friction: float = 0.0,
            points_per_cell: int = 2) -> dict:
    """Push the footing to `settlement` B; its pressure against settlement, N_q."""
    h = 2.0 * HALF / cells_per_width
    reach, depth = mechanism(phi)
    nx, nz = math.ceil(1.3 * reach / h), math.ceil(1.3 * depth / h)
    width, bed = nx * h, nz * h
    grid = Grid.make([0, 0, 0], h, [nx, 1, nz + math.ceil(HALF / h)])  # room for the heave
    x, vol = fill_box(grid, [0, 0, 0], [width, h, bed], points_per_cell)
    pts = make_points(x, vol, RHO, 0)
    mat = MohrCoulomb("bed", pts.n, density=RHO, youngs_modulus=E, poisson_ratio=NU,
                      friction_angle=phi, dilation_angle=0.0, cohesion=0.0,
                      tension_cutoff=0.0)
    s = MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None],
                 damping=0.7, damping_end=0.0)
    s.time = -SETTLE_TIME
    s.constraints = [boundary.constraint(boundary.face_nodes(grid, f), "roller",
                                         boundary.FACES[f][0])
                     for f in ("x-", "x+", "y-", "y+")]
    s.constraints.append(boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None))
    # the surface beside the footing: the top layer of points (centres h/2n below it)
    s.tractions = [boundary.make_traction(x, vol, [HALF, -1.0, bed - h / points_per_cell],
                                          [width, 1.0, bed], [0.0, 0.0, -SURCHARGE], "z+",
                                          ramp_time=LOAD_RAMP, start_time=-SETTLE_TIME)]
    xr, volr = fill_box(grid, [0, 0, bed], [HALF, h, bed + 2 * h], 2)
    s.rigid = RigidBody(x=xr, lp=0.5 * np.cbrt(volr), velocity=np.array([0, 0, -SPEED]),
                        ramp_time=RAMP, start_time=0.0, kind=BOX,
                        geom=np.array([-HALF, -1.0, bed, HALF, 1.0, bed + 2 * h, 0.0, 0.0]),
                        contact="penalty", friction=friction)
    end = 0.5 * RAMP + settlement * 2.0 * HALF / SPEED
    rows = []
    failure = None
    t0 = time.perf_counter()
    try:
        while s.time < end - 1e-12:
            step(s, min(s.stable_dt(), end - s.time))
            if s.time > 0.0:
                rows.append((-s.rigid.displacement[2], s.rigid.force[2] / (HALF * h)))
    except SimulationError as err:  # the curve so far is still worth its plot
        failure = f"{err}"
    rec = np.array(rows).reshape(-1, 2)
    s_over_b, nq = rec[:, 0] / (2.0 * HALF), rec[:, 1] / SURCHARGE
    plateau = s_over_b >= 0.5 * settlement
    return {"phi": phi, "cells_per_width": cells_per_width, "points_per_cell": points_per_cell,
            "cell": h, "points": pts.n, "bed": [width, bed], "steps": len(rec),
            "wall_s": round(time.perf_counter() - t0, 1),
            "N_q_plateau": float(nq[plateau].mean()) if plateau.any() else math.nan,
            "N_q_max": float(nq.max()) if len(nq) else math.nan,
            "failed_at_settlement": None if failure is None
            else float(s_over_b[-1]) if len(rec) else 0.0, "failure": failure, "curve": rec}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--phi", type=float, nargs="+", default=[20.0], help="deg")
    ap.add_argument("--cells-per-width", type=int, nargs="+", default=[8, 16],
                    help="cells across the footing's width B")
    ap.add_argument("--points-per-cell", type=int, default=2, help="n: n^3 points a cell")
    ap.add_argument("--settlement", type=float, default=0.1, help="final settlement / B")
    ap.add_argument("--friction", type=float, default=0.0, help="footing's Coulomb coefficient")
    ap.add_argument("--png", default=None, help="plot N_q against settlement")
    args = ap.parse_args()
    for phi in args.phi:
        if not 5.0 <= phi <= 45.0:
            raise SystemExit(f"--phi {phi}: valid 5 to 45 deg")
    for n in args.cells_per_width:
        if not 2 <= n <= 128:
            raise SystemExit(f"--cells-per-width {n}: valid 2 to 128")
    if not 1 <= args.points_per_cell <= 4:
        raise SystemExit(f"--points-per-cell {args.points_per_cell}: valid 1 to 4")
    if not 0.0 < args.settlement <= 0.5:
        raise SystemExit(f"--settlement {args.settlement}: valid (0, 0.5] (of B)")
    if args.friction < 0.0:
        raise SystemExit(f"--friction {args.friction}: must be >= 0")
    results = []
    for phi in args.phi:
        lo, hi = prandtl_nq(davis_angle(phi)), prandtl_nq(phi)
        for n in args.cells_per_width:
            r = footing(phi, n, args.settlement, args.friction, args.points_per_cell)
            r.update(N_q_associated=hi, N_q_davis=lo)
            results.append(r)
            failed = ("" if r["failure"] is None else
                      f"; FAILED at {r['failed_at_settlement']:.3f} B: {r['failure']}")
            print(f"phi {phi:g} deg, {n} cells over B: N_q {r['N_q_plateau']:.3f} (max "
                  f"{r['N_q_max']:.3f}); Prandtl {hi:.3f}, Davis {lo:.3f}, ratio "
                  f"{r['N_q_plateau'] / hi:.3f} ({r['points']} points, {r['wall_s']} s)"
                  f"{failed}", flush=True)
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, len(args.phi), figsize=(5 * len(args.phi), 4), squeeze=False)
        for ax, phi in zip(axes[0], args.phi, strict=True):
            for r in (r for r in results if r["phi"] == phi):
                ax.plot(r["curve"][:, 0] / (2.0 * HALF), r["curve"][:, 1] / SURCHARGE, lw=0.8,
                        label=f"{r['cells_per_width']} cells over B")
            ax.axhspan(prandtl_nq(davis_angle(phi)), prandtl_nq(phi), color="0.85",
                       label="Radenkovic bounds (psi = 0)")
            ax.set(xlabel="settlement / B", ylabel="q / q_0", title=f"phi = {phi:g} deg")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(args.png, dpi=120)
    for r in results:
        r.pop("curve")
    print(json.dumps({"settlement": args.settlement, "friction": args.friction,
                      "surcharge_Pa": SURCHARGE, "runs": results}))


if __name__ == "__main__":
    main()

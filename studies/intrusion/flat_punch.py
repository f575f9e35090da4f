"""A rigid flat circular punch on an elastic half-space, with the penalty contact:
its stiffness against Boussinesq's K = 2 a E / (1 - nu^2).

    python studies/intrusion/flat_punch.py [--sizes 6 9 12] [--cells-per-radius 3]

Quarter model (symmetry rollers at x = 0 and y = 0): a frictionless rigid cylinder of
radius a = 0.25 m on a cube of side L (rollers on the far sides, fixed base), linear
elastic (E = 1 MPa, nu = 0.3), one point a cell, pressed 1 mm/s with a 0.5 s ramp and
light local damping for 40 wave transits. The soil's stiffness is the measured one with
the contact springs taken out of the series, K = 4 F / (d - F / (N k_p)) (N points in
contact, k_p their spring). Two corrections turn the layer into the half-space:
- the finite cube: K(L) = K_inf + c / L to first order (the displacement a point load
  makes at distance L decays as 1/L), so K_inf is extrapolated from two or more sizes;
- the discretised punch: its N points cover N h_p^2 (h_p the point spacing), the area
  of a disc of radius a_eff = h_p sqrt(4 N / pi), which replaces a in Boussinesq's K.
Prints each size, then one JSON object with K_inf / K_Boussinesq(a_eff).
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from grainscale.blocks import (
    CYLINDER,
    Grid,
    LinearElastic,
    MPMState,
    RigidBody,
    boundary,
    fill_box,
    make_points,
    step,
)

RADIUS, E, NU, RHO = 0.25, 1e6, 0.3, 1000.0


def punch(size: float, cells_per_radius: int) -> dict:
    """Press the punch on a cube of side size * a; the soil's stiffness (full circle)."""
    h = RADIUS / cells_per_radius
    side = size * RADIUS
    n = round(side / h)
    if abs(n * h - side) > 1e-9 * side:  # the cube's far faces must lie on node planes
        raise ValueError(f"size = {size}: size x cells_per_radius ({cells_per_radius}) "
                         f"must be a whole number of cells")
    grid = Grid.make([0, 0, 0], h, [n, n, n + 2])
    x, vol = fill_box(grid, [0, 0, 0], [side, side, side], 1)
    pts = make_points(x, vol, RHO, 0)
    mat = LinearElastic("m", pts.n, density=RHO, youngs_modulus=E, poisson_ratio=NU)
    s = MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None], damping=0.3)
    s.constraints = [boundary.constraint(boundary.face_nodes(grid, f), "roller",
                                         boundary.FACES[f][0])
                     for f in ("x-", "x+", "y-", "y+")]
    s.constraints.append(boundary.constraint(boundary.face_nodes(grid, "z-"), "fixed", None))
    xr, volr = fill_box(grid, [0, 0, side], [RADIUS, RADIUS, side + h], 2)
    s.rigid = RigidBody(x=xr, lp=0.5 * np.cbrt(volr), velocity=np.array([0.0, 0.0, -1e-3]),
                        ramp_time=0.5, kind=CYLINDER,
                        geom=np.array([0.0, 0.0, side, 0.0, 0.0, 1.0, RADIUS, h]),
                        contact="penalty")
    wave = math.sqrt(E * (1 - NU) / ((1 + NU) * (1 - 2 * NU)) / RHO)
    end = 0.5 + 40 * side / wave
    t0 = time.perf_counter()
    while s.time < end - 1e-12:
        step(s, min(s.stable_dt(), end - s.time))
    d, force = -s.rigid.displacement[2], s.rigid.force[2]
    k_p = pts.m[0] * (s.rigid.penalty * s.rigid.wave_speed_ref / (2 * pts.lp[0, 2])) ** 2
    contact = s.rigid.in_contact
    stiffness = 4.0 * force / (d - force / (contact * k_p))
    return {"size": size, "points": pts.n, "in_contact": contact, "spacing": h,
            "stiffness": stiffness, "wall_s": round(time.perf_counter() - t0, 1)}


def extrapolate(rows: list[dict]) -> float:
    """K_inf of K(L) = K_inf + c / L, least squares over the sizes."""
    inv = np.array([1.0 / r["size"] for r in rows])
    k = np.array([r["stiffness"] for r in rows])
    return float(np.polyfit(inv, k, 1)[1])


def boussinesq(radius: float) -> float:
    return 2.0 * radius * E / (1.0 - NU ** 2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[6.0, 9.0, 12.0],
                    help="cube sides in punch radii")
    ap.add_argument("--cells-per-radius", type=int, default=3)
    args = ap.parse_args()
    rows = []
    for size in args.sizes:
        r = punch(size, args.cells_per_radius)
        rows.append(r)
        print(f"L = {size:g} a: K = {r['stiffness']:.4g} N/m, K / K_B(a) = "
              f"{r['stiffness'] / boussinesq(RADIUS):.4f} ({r['points']} points, "
              f"{r['wall_s']} s)", flush=True)
    a_eff = rows[0]["spacing"] * math.sqrt(4.0 * rows[0]["in_contact"] / math.pi)
    k_inf = extrapolate(rows)
    print(json.dumps({"K_inf_over_boussinesq_a_eff": k_inf / boussinesq(a_eff),
                      "K_inf_over_boussinesq_a": k_inf / boussinesq(RADIUS),
                      "a_eff_over_a": a_eff / RADIUS, "runs": rows}))


if __name__ == "__main__":
    main()

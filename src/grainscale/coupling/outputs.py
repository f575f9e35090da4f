"""What a run writes about its points: history rows and VTK fields.

Under MPI every rank holds only its own points, so outputs first gather the points (and
the materials' per-point fields) to rank 0 in global point order; every sum then runs
over the same numbers in the same order as in a serial run, which keeps history.csv
identical whatever the number of ranks.
"""

from __future__ import annotations

import math

import numpy as np

from grainscale.analysis import deposit_profile, front_at_thickness
from grainscale.config.case import HISTORY_COST, HISTORY_DEM, Case
from grainscale.coupling.rve_material import RVEMaterial
from grainscale.mpm.points import Points
from grainscale.mpm.setup import AXES
from grainscale.mpm.step import MPMState, kinetic_energy
from grainscale.stress import p_q


def material_fields(s: MPMState) -> dict[str, np.ndarray]:
    """The materials' own per-point fields on this rank's points (NaN where a field
    does not apply)."""
    out: dict[str, np.ndarray] = {}
    n = s.points.n
    for mat, ids in zip(s.materials, s.mat_points, strict=True):
        for k, a in mat.point_fields().items():
            full = out.setdefault(k, np.full((n, *a.shape[1:]), np.nan))
            full[slice(None) if ids is None else ids] = a
    return out


def gather(s: MPMState) -> tuple[Points, dict[str, np.ndarray]] | None:
    """All points and material fields in global point order, on rank 0 (None elsewhere)."""
    local = material_fields(s)
    parts = s.comm.gather((s.point_ids, s.points.arrays(), local))
    if parts is None:
        return None
    if len(parts) == 1:
        return s.points, local
    ids = np.concatenate([p[0] for p in parts])
    order = np.argsort(ids)

    def merged(key: str, source: int) -> np.ndarray:
        chunks = []
        for p in parts:
            a = p[source].get(key)
            if a is None:  # a rank without points of that material
                ref = next(q[source][key] for q in parts if key in q[source])
                a = np.full((len(p[0]), *ref.shape[1:]), np.nan)
            chunks.append(a)
        return np.ascontiguousarray(np.concatenate(chunks)[order])

    pts = Points(**{k: merged(k, 1) for k in parts[0][1]})
    keys = dict.fromkeys(k for p in parts for k in p[2])
    return pts, {k: merged(k, 2) for k in keys}


def history_values(case: Case, s: MPMState, pts: Points,
                   fields: dict[str, np.ndarray]) -> dict[str, float]:
    """Every history quantity available for this case; pts and fields hold all points
    (gather())."""
    out = {"step": s.step, "time": s.time, "dt": s.last_dt,
           "kinetic_energy": kinetic_energy(pts)}
    # the body as one element: volume-averaged stress, mean strains (seed §4.1)
    vol = pts.vol.sum()
    sigma = np.einsum("p,pab->ab", pts.vol, pts.stress) / vol
    p, q = p_q(sigma[None])
    a = AXES[case.output.axial_axis]
    out.update(p=float(p[0]), q=float(q[0]), q_over_p=float(q[0] / p[0]) if p[0] > 0 else 0.0,
               axial_strain=float(1.0 - np.average(pts.F[:, a, a], weights=pts.vol0)),
               volumetric_strain=float(np.log(vol / pts.vol0.sum())))
    dem = [i for i, m in enumerate(s.materials) if isinstance(m, RVEMaterial)]
    if dem:
        # sum_p V_p f_p / sum_p V_p over the points of every DEM material, with the
        # current volumes, as the stress average: a plain point mean would describe the
        # fine near field of a graded grid only (its points differ up to 56x in volume).
        # For porosity it is the material's void fraction. numpy's pairwise sums in
        # global point order (no BLAS dot, whose blocking may follow the thread count).
        on_rve = np.isin(pts.mat, dem)
        w = pts.vol[on_rve]
        for key in HISTORY_DEM:
            if key in fields:
                out[key] = float((w * fields[key][on_rve]).sum() / w.sum())
        for key, field in zip(HISTORY_COST, ("rve_dem_steps", "rve_updates"), strict=True):
            if field in fields:  # per RVE, whatever its volume: the cost
                out[key] = float(fields[field][on_rve].sum() / on_rve.sum())
    col = case.output.column
    if col is not None:
        fa, ua = AXES[col.flow_axis], AXES[col.up_axis]
        edge = pts.x[:, fa] + pts.lp[:, fa]  # particle-domain edge: the initial runout is 0
        front = float(np.quantile(edge, col.front_quantile)) if col.front_quantile < 1 \
            else float(edge.max())
        height = float((pts.x[:, ua] + pts.lp[:, ua]).max()) - col.base
        g = float(np.linalg.norm(case.solver.gravity))
        out.update(front=front, column_height=height,
                   runout_ratio=(front - col.wall - col.length) / col.length,
                   height_ratio=height / col.height,
                   t_over_tc=s.time / math.sqrt(col.height / g) if g > 0 else math.nan)
        if col.min_thickness > 0.0:
            # bins one point spacing (2 l_p) wide
            edges, thick = deposit_profile(pts.x[:, fa], pts.x[:, ua], pts.lp[:, ua],
                                           2.0 * float(np.median(pts.lp[:, fa])), col.base)
            front = front_at_thickness(edges, thick, col.min_thickness)
            out.update(front_thick=front,
                       runout_ratio_thick=(front - col.wall - col.length) / col.length)
    if s.rigid is not None:
        f = s.rigid.force
        v = s.rigid.velocity
        n = v / np.linalg.norm(v) if np.any(v) else np.zeros(3)
        depth = float(np.dot(s.rigid.displacement, n))
        force = -float(np.dot(f, n))  # resistance to the motion
        out.update(rigid_fx=f[0], rigid_fy=f[1], rigid_fz=f[2], rigid_depth=depth,
                   depth=depth, force=force)
        # seed §4.3: d/R and p_u/(rho g R), p_u = force / S (the modelled section), rho
        # the initial bulk density of the material
        g = float(np.linalg.norm(case.solver.gravity))
        rho = float(pts.m.sum() / pts.vol0.sum()) if pts.n else math.nan
        R = s.rigid.radius
        out.update(depth_over_R=depth / R,
                   force_normalized=force / s.rigid.area / (rho * g * R) if g > 0 else math.nan,
                   bearing_pressure=force / s.rigid.area)  # over the section S in the grid
        per = np.flatnonzero(s.grid.periodic)
        if len(per) == 1:  # plane strain: the force on the model's thickness
            lo, hi = s.grid.period_box()
            out["force_per_length"] = force / float(hi[per[0]] - lo[per[0]])
    return out


def point_fields(pts: Points, fields: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-point VTK output: position, velocity, displacement, stress, p, q,
    eps_v = ln(V/V0), material index, and the materials' own fields."""
    p, q = p_q(pts.stress)
    return {"position": pts.x, "velocity": pts.v, "displacement": pts.x - pts.x0,
            "stress": pts.stress, "p": p, "q": q, "eps_v": np.log(pts.vol / pts.vol0),
            "material": pts.mat, **fields}

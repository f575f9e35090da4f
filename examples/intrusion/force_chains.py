"""Force chains of the probe RVEs below and beside an intruder (seed Fig. 16).

    python examples/intrusion/force_chains.py OUT [--probes below edge]
        [--depths 0 0.5 1.0] [--png OUT/force_chains.png]

Reads a multiscale run's probe series (probe_NAME_{contacts,spheres,cell}.pvd, written
at every frame: docs/coupling.md "Probe RVEs") and prints, for every frame of each probe,
what the RVE's contact network carries: the intrusion's d/R (from history.csv), where
the probe's point is (its depth below the intruder's base, from frames.pvd), the RVE's
pressure p and q/p (Love-Weber, compression positive), the median pressure of the
points next to it (its face neighbours on the grid: one RVE is one sample of a field
that scatters from point to point, docs/validation.md §3.1), its porosity, the coordination
number Z = 2 N_c / N_p (contacts with a positive normal force), the mean normal force,
the share of contacts in the strong network (normal force above the mean) and the
vertical fabric of that network, a_z = <n_z^2> - (<n_x^2> + <n_y^2>) / 2 over its
branch directions n (0 for an isotropic network, 1 for chains all along z). p is also
summed from the contacts themselves, (1/V) sum d (x) f, as a check on the files (the
RVE's p adds the kinetic stress of its grains' fluctuating motion, nil at rest).

The picture has a row per probe and a column per requested d/R (the frame nearest
each): the RVE's contacts seen along y, each a line from centre to centre with a width
and colour set by its normal force on one scale per probe, so a compaction front that
reaches the probe shows as thicker, redder chains. The seed's Fig. 16 shows the same for
three RVEs under the intruder's axis. The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

import grainscale as gs  # noqa: E402
from grainscale import analysis  # noqa: E402


def cell_volume(cell) -> float:
    """Volume [m^3] of the periodic cell, a parallelepiped written as one hexahedron in
    VTK order (points 1, 3 and 4 are the ends of its edges from point 0)."""
    x = np.asarray(cell.points, float)
    return float(abs(np.linalg.det(np.stack([x[1] - x[0], x[3] - x[0], x[4] - x[0]]))))


def network(contacts, spheres, cell) -> dict:
    """Measures of one RVE snapshot (io/rve_vtk.py files read with meshio): Z, mean
    normal force [N], strong share, a_z of the strong network, p and q/p [Pa] from the
    cell's stress, p summed from the contacts [Pa], porosity."""
    ends = np.asarray(contacts.points, float)[contacts.cells_dict["line"]]
    d = ends[:, 1] - ends[:, 0]                               # branch vectors [m]
    fn = np.asarray(contacts.cell_data["normal_force"][0], float)
    f = np.asarray(contacts.cell_data["force_vector"][0], float)
    sigma = np.einsum("ci,cj->ij", d, f) / cell_volume(cell)  # Love-Weber, tension +
    on = fn > 0.0
    strong = on & (fn > fn[on].mean()) if on.any() else on
    n = d[strong] / np.linalg.norm(d[strong], axis=1)[:, None]
    a_z = float(np.mean(n[:, 2] ** 2) - 0.5 * np.mean(n[:, 0] ** 2 + n[:, 1] ** 2)) \
        if strong.any() else 0.0
    data = cell.cell_data
    p = float(np.asarray(data["p"][0]).ravel()[0])
    q = float(np.asarray(data["q"][0]).ravel()[0])
    return {"Z": 2.0 * int(on.sum()) / len(spheres.points),
            "mean_normal_force": float(fn[on].mean()) if on.any() else 0.0,
            "strong_share": float(strong.sum() / max(int(on.sum()), 1)),
            "a_z_strong": a_z, "p": p, "q_over_p": q / p if p > 0 else float("nan"),
            "p_contacts": float(-np.trace(sigma) / 3.0),
            "porosity": float(np.asarray(data["porosity"][0]).ravel()[0])}


def point_context(result: gs.Result, case: gs.Case, point_position, times,
                  depths) -> np.ndarray:
    """(n, 2): at each probe frame, the depth [m] of the probe's point below the
    intruder's base, and the median pressure [Pa] of its face neighbours by initial
    position (analysis.neighbour_median): the field the probe's RVE samples. The point
    is the frame's one whose initial position (position - displacement) is the probe's.
    NaN where a frame is missing."""
    by_time = {round(t, 9): mesh for t, mesh in result.frames()}
    base0 = case.rigid.center[2] if case.rigid.shape == "cylinder" else case.rigid.lo[2]
    found = np.full((len(times), 2), np.nan)
    for k, (t, depth) in enumerate(zip(times, depths, strict=True)):
        mesh = by_time.get(round(t, 9))
        if mesh is None:
            continue
        x = np.asarray(mesh.points, float)
        x0 = x - np.asarray(mesh.point_data["displacement"], float)
        i = int(np.argmin(np.linalg.norm(x0 - np.asarray(point_position), axis=1)))
        p = np.asarray(mesh.point_data["p"], float).ravel()
        found[k] = (base0 - depth) - x[i, 2], analysis.neighbour_median(x0, p, [i])[0]
    return found


def draw(ax, contacts, scale: float) -> None:
    """The contacts seen along y: width and colour by normal force over `scale` [N]."""
    ends = np.asarray(contacts.points, float)[contacts.cells_dict["line"]]
    fn = np.asarray(contacts.cell_data["normal_force"][0], float)
    on = fn > 0.0
    order = np.argsort(fn[on])  # the strongest drawn last, on top
    lines = LineCollection(ends[on][order][:, :, [0, 2]], cmap="inferno_r",
                           linewidths=0.3 + 4.0 * fn[on][order] / scale)
    lines.set_array(fn[on][order] / scale)
    lines.set_clim(0.0, 1.0)
    ax.add_collection(lines)
    ax.autoscale()
    ax.set(aspect="equal", xticks=[], yticks=[])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--probes", nargs="+", default=None,
                    help="probe names (default: every probe of probes.json)")
    ap.add_argument("--depths", type=float, nargs="+", default=[0.0, 0.5, 1.0], help="d/R")
    ap.add_argument("--png", type=Path, default=None)
    args = ap.parse_args(argv)
    try:
        result = gs.open_result(args.out)
        hist, case = result.history, result.case
        record = json.loads((args.out / "probes.json").read_text())["probes"]
    except (ValueError, gs.ConfigError, OSError) as err:
        raise SystemExit(str(err)) from None
    if case.rigid is None:
        raise SystemExit(f"{args.out}: the case has no [rigid] intruder")
    known = {p["name"]: p for p in record}
    names = args.probes or list(known)
    for name in names:
        if name not in known:
            raise SystemExit(f"--probes {name}: not a probe of {args.out} (valid: {list(known)})")
    report = {}
    fig, axes = plt.subplots(len(names), len(args.depths), squeeze=False,
                             figsize=(2.6 * len(args.depths) + 0.6, 2.9 * len(names)),
                             constrained_layout=True)
    for row, name in enumerate(names):
        series = {kind: result.probe(name, kind) for kind in ("contacts", "spheres", "cell")}
        times = np.array([t for t, _ in series["contacts"]])
        d_over_r = np.interp(times, hist["time"], hist["depth_over_R"])
        depth = np.interp(times, hist["time"], hist["depth"])
        context = point_context(result, case, known[name]["point_position"], times, depth)
        rows = []
        print(f"probe {name!r} (point {known[name]['point']}, initially at "
              f"{known[name]['point_position']} m)")
        print("    t (s)   d/R  below base (m)  p (kPa)  p nearby (kPa)  q/p  porosity"
              "    Z  <f_n> (N) strong   a_z  p of contacts (kPa)")
        for k, t in enumerate(times):
            m = network(series["contacts"][k][1], series["spheres"][k][1], series["cell"][k][1])
            m |= {"time": float(t), "depth_over_R": float(d_over_r[k]),
                  "below_base": float(context[k, 0]), "p_neighbours": float(context[k, 1])}
            rows.append(m)
            print(f"  {t:7.3f} {d_over_r[k]:5.2f} {context[k, 0]:12.3f} {m['p'] / 1e3:10.2f}"
                  f" {context[k, 1] / 1e3:12.2f} {m['q_over_p']:7.2f} {m['porosity']:7.3f}"
                  f" {m['Z']:6.2f}"
                  f" {m['mean_normal_force']:9.3f} {m['strong_share']:6.2f}"
                  f" {m['a_z_strong']:5.2f} {m['p_contacts'] / 1e3:9.2f}")
        # the latest of equally near frames: d/R 0 is the geostatic stage's end
        chosen = [len(times) - 1 - int(np.argmin(np.abs(d_over_r - target)[::-1]))
                  for target in args.depths]
        scale = max(float(np.asarray(series["contacts"][k][1].cell_data["normal_force"][0])
                          .max(initial=0.0)) for k in chosen) or 1.0
        for ax, k in zip(axes[row], chosen, strict=True):
            draw(ax, series["contacts"][k][1], scale)
            ax.set_title(f"{name}, d/R {d_over_r[k]:.2f}\np {rows[k]['p'] / 1e3:.1f} kPa, "
                         f"Z {rows[k]['Z']:.2f}", fontsize=9)
        axes[row][0].set_ylabel(f"darkest, widest: {scale:.1f} N", fontsize=8)
        report[name] = {"frames": rows, "drawn": [rows[k]["time"] for k in chosen],
                        "max_normal_force_drawn": scale}
    png = args.png or args.out / "force_chains.png"
    fig.savefig(png, dpi=100)
    print(json.dumps({"png": str(png), "probes": report}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

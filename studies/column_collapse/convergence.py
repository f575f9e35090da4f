"""Grid convergence of the continuum column collapse (mu(I) and Mohr-Coulomb).

    python studies/column_collapse/convergence.py --out DIR [--cells 10 5 2.5 1.25]
        [--materials mu_i mohr_coulomb] [--friction-angle 22] [--points-per-cell 2]
        [--floor friction|fixed|roller|penalty] [--cfl 0.5] [--t-end 7]
        [--velocity-update apic|flip|aflip] [--flip F | --relaxation-time TAU]
        [--separation reset|recompact] [--channel W_MM --wall-friction MU_W]

Runs `examples/column_collapse/mu_i.toml` at each cell size (mm), and the same geometry with
a Mohr-Coulomb material of the given friction angle (psi = 0, no cohesion, the same
density and elastic moduli), to 7 tau_c. The slice stays one cell thick. The options
vary the points per cell, the floor's discretisation and the time step (run folders
get a suffix such as _n4_penalty_cfl0.25). A run whose
history already reaches the end is not repeated, so the study can be extended or
resumed. Writes DIR/results.json, DIR/convergence.png (runout against t / tau_c for every
run beside Lube et al. 2005, 1.2 a, and Lajeunesse et al. 2005, 1.8 a; final runout
against cell size) and prints a table; the last line is one JSON object.

Front-stop time: the first t / tau_c at which the front is within 0.01 L_i of its final
position. The final deposit (last frame): its thickness along the channel, and the
runout of the part at least 2 and 3 bead diameters thick (the experiment's 1.15 mm beads;
`front` itself is the outermost point, however thin the layer it ends in), and of the
point behind which 95 % and 99 % of the mass lies (`runout_mass95`, `runout_mass99`).

`--channel W_MM` replaces the slice by half of a channel W_MM wide (the symmetry plane
y = 0 frictionless, a Coulomb wall of `--wall-friction` at y = W/2): the experiments'
channels have walls whose friction the slice leaves out. Such runs also report the
deposit in the layer of points along the wall (`wall_runout`, `wall_runout_3d`,
`wall_runout_mass99`), which is where a profile photographed through the wall lies.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import grainscale as gs  # noqa: E402
from grainscale.analysis import deposit_profile, front_at_thickness  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # studies/: variants.py
from variants import run_variant  # noqa: E402

CASES = Path(__file__).resolve().parents[2] / "examples" / "column_collapse"  # the case files
ASPECT = 0.6
LENGTH = 0.1  # m, L_i
BEAD = 1.15e-3  # m, the diameter of Lajeunesse et al.'s glass beads
X_EXTENT, Z_EXTENT = 0.32, 0.07  # m, the grid of mu_i.toml


def case_at(h: float, material: str, friction_angle: float, points_per_cell: int = 2,
            floor: str = "friction", cfl: float = 0.5, t_end: float = 7.0,
            update: str | None = None, flip: float | None = None,
            relaxation_time: float | None = None, separation: str | None = None,
            nonlocal_amplitude: float = 0.48, fluidity_time: float = 1e-4,
            channel: float | None = None, wall_friction: float = 0.0) -> gs.Case:
    """mu_i.toml with cells of h metres (and a slice one cell thick), its Mohr-Coulomb
    twin, or its nonlocal twin (`nonlocal_mu_i`, the same beads with amplitude A and
    fluidity time t_0; docs/mpm.md: nonlocal mu(I)); n x n x n points a cell; the floor
    as in mu_i.toml (`friction`, Coulomb 0.466
    on the grid nodes), no-slip (`fixed`), frictionless (`roller`: the mass slides on
    and leaves the grid, compare at early times), or a rigid box under z = 0 with the penalty
    contact and the same friction (`penalty`, docs/mpm.md: rigid body; the grid then
    reaches two cells below the floor); runs end at t_end tau_c; `update`, `flip` and
    `relaxation_time` replace mu_i.toml's solver.velocity_update, solver.flip and
    solver.velocity_relaxation_time [s] when `update` is given (docs/mpm.md: velocity
    update); `separation` replaces the mu(I) material's (docs/mpm.md: mu(I) rheology);
    `channel` [m] makes the slice half of a channel that wide, its wall at y = channel/2
    with Coulomb friction `wall_friction` (frictionless at 0), whole cells wide.
    The validated gs.Case (ConfigError names a bad value)."""
    if floor not in ("friction", "fixed", "roller", "penalty"):
        raise ValueError(f"floor = {floor!r}: one of friction, fixed, roller, penalty")
    half = channel_cells(h, channel, wall_friction) if channel is not None else None
    case = gs.load_case(CASES / "mu_i.toml")
    case.grid.cell_size = h
    case.grid.cells = [round(X_EXTENT / h), 2 if half is None else half, round(Z_EXTENT / h)]
    case.bodies[0].hi = [case.bodies[0].hi[0], h if channel is None else channel / 2,
                         case.bodies[0].hi[2]]
    case.bodies[0].points_per_cell = points_per_cell
    case.solver.cfl = cfl
    if t_end != 7.0:  # (mu_i.toml's own end is 7 tau_c)
        case.time.end = t_end * math.sqrt(0.06 / 9.81)  # its H_i and g
    case.title = f"column collapse, {material}, {h * 1e3:g} mm cells" + (
        f", channel {channel * 1e3:g} mm wide, wall friction {wall_friction:g}"
        if channel is not None else "")

    def tables(t: dict) -> None:  # what replaces or removes keys and whole tables
        solver = t["solver"]
        if update is not None:
            solver["velocity_update"] = update
            solver.pop("flip", None)
            solver.pop("velocity_relaxation_time", None)
            if flip is not None:
                solver["flip"] = flip
            if relaxation_time is not None:
                solver["velocity_relaxation_time"] = relaxation_time
        if material == "nonlocal_mu_i":
            t["materials"]["beads"].update(type="nonlocal_mu_i",
                                           nonlocal_amplitude=nonlocal_amplitude,
                                           fluidity_time=fluidity_time)
        if separation is not None and material in ("mu_i", "nonlocal_mu_i"):
            t["materials"]["beads"]["separation"] = separation
        for bc in t["boundaries"]:
            if "box" in bc:
                bc["box"]["hi"][1] = h
                if bc.get("normal") == "y":
                    bc["box"]["lo"][1] = h
        if channel is not None:
            t["boundaries"] = [bc for bc in t["boundaries"] if bc.get("normal") != "y"]
            for bc in t["boundaries"]:
                if "box" in bc:
                    bc["box"]["hi"][1] = channel / 2
            t["boundaries"].append(
                {"type": "friction", "face": "y+", "friction": wall_friction}
                if wall_friction > 0 else {"type": "roller", "face": "y+"})
        floor_bc = t["boundaries"][0]
        assert floor_bc.get("face") == "z-" and floor_bc["type"] == "friction"
        if floor in ("fixed", "roller"):
            t["boundaries"][0] = {"type": floor, "face": "z-"}
        elif floor == "penalty":
            del t["boundaries"][0]
            t["grid"]["origin"][2] = -2 * h
            t["grid"]["cells"][2] += 2
            t["rigid"] = {"shape": "box", "lo": [-h, -h, -2 * h],
                          "hi": [X_EXTENT + h, 2 * h, 0.0], "velocity": [0.0, 0.0, 0.0],
                          "contact": "penalty", "clip_to_grid": True,
                          "friction": floor_bc["friction"]}
        if material == "mohr_coulomb":
            mu = t["materials"]["beads"]
            t["materials"]["beads"] = {
                "type": "mohr_coulomb", "density": mu["density"],
                "youngs_modulus": mu["youngs_modulus"], "poisson_ratio": mu["poisson_ratio"],
                "friction_angle": friction_angle, "dilation_angle": 0.0}

    return case.edited(tables)


def channel_cells(h: float, channel: float, wall_friction: float) -> int:
    """Cells across half of a channel `channel` m wide on cells of h m; ValueError naming
    the option where half the channel is not a whole number of cells or the wall's
    friction is negative."""
    half = round(channel / 2 / h)
    if half < 1 or abs(half * h - channel / 2) > 1e-9 * channel:
        raise ValueError(f"--channel {channel * 1e3:g} mm: half of it must be a whole "
                         f"number (>= 1) of {h * 1e3:g} mm cells")
    if wall_friction < 0.0:
        raise ValueError(f"--wall-friction {wall_friction}: valid >= 0")
    return half


def variant(points_per_cell: int, floor: str, cfl: float, t_end: float,
            update: str | None = None, flip: float | None = None,
            relaxation_time: float | None = None, separation: str | None = None,
            channel: float | None = None, wall_friction: float = 0.0) -> str:
    """Suffix of a run folder for the non-default options ('' for mu_i.toml's)."""
    return ((f"_n{points_per_cell}" if points_per_cell != 2 else "")
            + (f"_{separation}" if separation is not None else "")
            + (f"_{update}" if update is not None else "")
            + (f"{flip:g}" if flip is not None else "")
            + (f"_tau{relaxation_time * 1e3:g}ms" if relaxation_time is not None else "")
            + (f"_{floor}" if floor != "friction" else "")
            + (f"_cfl{cfl:g}" if cfl != 0.5 else "")
            + (f"_t{t_end:g}" if t_end != 7.0 else "")
            + (f"_W{channel * 1e3:g}mm_muw{wall_friction:g}" if channel is not None else ""))


def measures(h: dict[str, np.ndarray]) -> dict[str, float]:
    after = h["t_over_tc"] >= 0
    t, r = h["t_over_tc"][after], h["runout_ratio"][after]
    final = float(r[-1])
    stop = float(t[np.argmax(r >= final - 0.01)])
    ke = h["kinetic_energy"][after]
    return {"runout": final, "height_ratio": float(h["height_ratio"][after][-1]),
            "front_stop_t_over_tc": stop, "t_over_tc_end": float(t[-1]),
            "kinetic_energy_end_over_peak": float(ke[-1] / ke.max()) if ke.max() > 0 else 0.0}


def last_points(run: Path) -> np.ndarray:
    """Point positions of the run's last frame [m], (n, 3)."""
    return gs.open_result(run).frames()[-1][1].points


def point_spacing(case: gs.Case) -> float:
    """Distance between neighbouring points of the column's body [m]: cell / n."""
    return case.grid.cell_size / case.bodies[0].points_per_cell


def deposit(run: Path, case: gs.Case) -> tuple[np.ndarray, np.ndarray]:
    """Thickness of the last frame's deposit along x (bins one point spacing wide, point
    domains of half-width cell / (2 n)): bin boundaries and thicknesses [m]."""
    x, spacing = last_points(run), point_spacing(case)
    return deposit_profile(x[:, 0], x[:, 2], spacing / 2, spacing)


def mass_runouts(run: Path) -> dict[str, float]:
    """Runout ratio of the point behind which 95 % and 99 % of the mass of the last frame
    lies (points of equal mass, as every body here is one uniform box): a measure of where
    the deposit's mass went that a few points leading the front do not move."""
    q = np.quantile(last_points(run)[:, 0], [0.95, 0.99])
    return {"runout_mass95": float((q[0] - LENGTH) / LENGTH),
            "runout_mass99": float((q[1] - LENGTH) / LENGTH)}


def wall_runouts(run: Path, case: gs.Case) -> dict[str, float]:
    """Front, 3-bead deposit and 99 % mass runouts of the layer of points along a channel's
    wall (centres within one point spacing of it): the deposit a photograph through the
    wall shows."""
    x, spacing = last_points(run), point_spacing(case)
    wall = x[x[:, 1] > case.bodies[0].hi[1] - spacing]
    edges, thick = deposit_profile(wall[:, 0], wall[:, 2], spacing / 2, spacing)
    return {"wall_runout": float((wall[:, 0].max() + spacing / 2 - LENGTH) / LENGTH),
            "wall_runout_3d": (front_at_thickness(edges, thick, 3 * BEAD) - LENGTH) / LENGTH,
            "wall_runout_mass99": float((np.quantile(wall[:, 0], 0.99) - LENGTH) / LENGTH)}


def thick_runouts(edges: np.ndarray, thick: np.ndarray) -> dict[str, float]:
    """Runout ratio of the deposit where it is at least 2 and 3 bead diameters thick."""
    return {f"runout_{k}d": (front_at_thickness(edges, thick, k * BEAD) - LENGTH) / LENGTH
            for k in (2, 3)}


def experiment_bands(ax) -> None:
    """The published final runouts at a = 0.6 as horizontal lines: Lube et al. 2005
    (1.2 a) and Lajeunesse et al. 2005 (1.8 a)."""
    for frac, who, colour in ((1.2, "Lube et al. 2005", "tab:blue"),
                              (1.8, "Lajeunesse et al. 2005", "tab:red")):
        ax.axhline(frac * ASPECT, color=colour, ls=":", lw=1,
                   label=f"{who}: {frac}a = {frac * ASPECT:.2f}")


def plot(results: list[dict], histories: dict, deposits: dict, png: Path) -> None:
    fig, (ax, bx, cx) = plt.subplots(1, 3, figsize=(16, 4.2))
    styles = {"mu_i": "-", "mohr_coulomb": "--", "nonlocal_mu_i": ":"}
    sizes = sorted({r["cell_mm"] for r in results}, reverse=True)
    colours = dict(zip(sizes, plt.cm.viridis(np.linspace(0.0, 0.85, len(sizes))), strict=True))
    for r in results:
        h = histories[(r["material"], r["cell_mm"])]
        after = h["t_over_tc"] >= 0
        ax.plot(h["t_over_tc"][after], h["runout_ratio"][after], styles[r["material"]],
                color=colours[r["cell_mm"]], label=f"{r['label']}, {r['cell_mm']:g} mm")
        if r["cell_mm"] not in sizes[-2:]:  # profiles of the two finest grids only
            continue
        edges, thick = deposits[(r["material"], r["cell_mm"])]
        cx.stairs(thick * 1e3, edges / LENGTH, ls=styles[r["material"]],
                  color=colours[r["cell_mm"]], lw=1, label=f"{r['label']}, {r['cell_mm']:g} mm")
    for b in (ax, bx):
        experiment_bands(b)
    ax.set_xlabel("t / tau_c")
    ax.set_ylabel("(L - L_i) / L_i")
    ax.set_xlim(0, 7)
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7, loc="lower right")
    for mat in dict.fromkeys(r["material"] for r in results):
        rows = sorted((r for r in results if r["material"] == mat), key=lambda r: r["cell_mm"])
        bx.plot([r["cell_mm"] for r in rows], [r["runout"] for r in rows],
                styles[mat] + "o", color="k", label=f"{rows[0]['label']}: front")
        bx.plot([r["cell_mm"] for r in rows], [r["runout_3d"] for r in rows],
                styles[mat] + "s", color="tab:green", mfc="none",
                label=f"{rows[0]['label']}: deposit >= 3 beads thick")
        bx.plot([r["cell_mm"] for r in rows], [r["runout_mass99"] for r in rows],
                styles[mat] + "^", color="tab:purple", mfc="none",
                label=f"{rows[0]['label']}: 99 % of the mass")
    bx.set_xscale("log")
    bx.set_xticks(sizes, [f"{mm:g}" for mm in sizes])
    bx.minorticks_off()
    bx.set_xlabel("cell size (mm)")
    bx.set_ylabel("final runout (L_f - L_i) / L_i at 7 tau_c")
    bx.set_ylim(bottom=0)
    bx.legend(fontsize=7)
    for k in (2, 3):
        cx.axhline(k * BEAD * 1e3, color="0.6", lw=0.8, ls=":")
    cx.set_xlim(1.0, None)
    cx.set_ylim(0, 20)
    cx.set_xlabel("x / L_i (the column's face was at 1)")
    cx.set_ylabel("final deposit thickness (mm); dotted: 2 and 3 beads")
    cx.legend(fontsize=7)
    fig.suptitle(f"column collapse a = {ASPECT}: grid convergence")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--cells", type=float, nargs="+", default=[10.0, 5.0, 2.5, 1.25],
                    help="cell sizes in mm")
    ap.add_argument("--materials", nargs="+", default=["mu_i", "mohr_coulomb"],
                    choices=["mu_i", "mohr_coulomb", "nonlocal_mu_i"])
    ap.add_argument("--nonlocal-amplitude", type=float, default=0.48,
                    help="A of nonlocal_mu_i (Henann & Kamrin's glass beads: 0.48)")
    ap.add_argument("--fluidity-time", type=float, default=1e-4,
                    help="t_0 [s] of nonlocal_mu_i")
    ap.add_argument("--friction-angle", type=float, default=22.0,
                    help="Mohr-Coulomb friction angle (deg)")
    ap.add_argument("--points-per-cell", type=int, default=2, help="n: n^3 points a cell")
    ap.add_argument("--floor", default="friction",
                    choices=["friction", "fixed", "roller", "penalty"])
    ap.add_argument("--cfl", type=float, default=0.5)
    ap.add_argument("--t-end", type=float, default=7.0, help="end of the runs, in tau_c")
    ap.add_argument("--velocity-update", default=None, choices=["apic", "flip", "aflip"],
                    help="instead of mu_i.toml's (aflip, relaxation time 0.01 s)")
    ap.add_argument("--flip", type=float, default=None,
                    help="FLIP share of --velocity-update flip or aflip")
    ap.add_argument("--relaxation-time", type=float, default=None,
                    help="solver.velocity_relaxation_time [s] of flip or aflip")
    ap.add_argument("--separation", default=None, choices=["reset", "recompact"],
                    help="the mu(I) material's separation, instead of mu_i.toml's")
    ap.add_argument("--channel", type=float, default=None, metavar="W_MM",
                    help="half of a channel W_MM wide instead of the slice")
    ap.add_argument("--wall-friction", type=float, default=0.0,
                    help="Coulomb friction of the channel's wall (with --channel)")
    args = ap.parse_args()
    channel = args.channel * 1e-3 if args.channel is not None else None
    if channel is None and args.wall_friction:
        raise SystemExit("--wall-friction needs --channel (the slice's walls are frictionless)")
    for mm in args.cells if channel is not None else ():
        try:  # before the first run
            channel_cells(mm * 1e-3, channel, args.wall_friction)
        except ValueError as err:
            raise SystemExit(str(err)) from None
    results, histories, deposits = [], {}, {}
    for mat in args.materials:
        label = {"mu_i": "mu(I)", "nonlocal_mu_i": "nonlocal mu(I)"}.get(
            mat, f"Mohr-Coulomb {args.friction_angle:g} deg")
        for mm in sorted(args.cells, reverse=True):
            separation = args.separation if mat != "mohr_coulomb" else None
            suffix = variant(args.points_per_cell, args.floor, args.cfl, args.t_end,
                             args.velocity_update, args.flip, args.relaxation_time,
                             separation, channel, args.wall_friction)
            out = args.out / f"{mat}_{mm:g}mm{suffix}"
            case = case_at(mm * 1e-3, mat, args.friction_angle, args.points_per_cell,
                           args.floor, args.cfl, args.t_end, args.velocity_update, args.flip,
                           args.relaxation_time, separation, args.nonlocal_amplitude,
                           args.fluidity_time, channel, args.wall_friction)
            wall = run_variant(case, out)
            h = gs.open_result(out / "run").history
            histories[(mat, mm)] = h
            deposits[(mat, mm)] = deposit(out / "run", case)
            row = {"material": mat, "label": label, "cell_mm": mm, "wall_s": round(wall, 1),
                   **measures(h), **thick_runouts(*deposits[(mat, mm)]),
                   **mass_runouts(out / "run"),
                   **(wall_runouts(out / "run", case) if channel is not None else {})}
            results.append(row)
            print(f"{label:24s} {mm:5g} mm: runout {row['runout']:.3f} (deposit >= 2 / 3 "
                  f"beads thick: {row['runout_2d']:.3f} / {row['runout_3d']:.3f}; 99 % of "
                  f"the mass: {row['runout_mass99']:.3f}), H_f/H_i "
                  f"{row['height_ratio']:.3f}, front stops at "
                  f"{row['front_stop_t_over_tc']:.2f} tau_c, KE end/peak "
                  f"{row['kinetic_energy_end_over_peak']:.3f}, {wall:.0f} s"
                  + (f"; along the wall: front {row['wall_runout']:.3f}, >= 3 beads "
                     f"{row['wall_runout_3d']:.3f}, 99 % of its mass "
                     f"{row['wall_runout_mass99']:.3f}" if channel is not None else ""),
                  flush=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=1))
    plot(results, histories, deposits, args.out / "convergence.png")
    summary = {}
    for mat in args.materials:
        rows = sorted((r for r in results if r["material"] == mat), key=lambda r: r["cell_mm"])
        for key in ("runout", "runout_2d", "runout_3d", "runout_mass99"):
            summary[f"{mat}_{key}"] = {f"{r['cell_mm']:g}mm": round(r[key], 4) for r in rows}
        if len(rows) >= 2:
            summary[f"{mat}_finest_change"] = round(abs(rows[0]["runout"] / rows[1]["runout"]
                                                        - 1.0), 4)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()

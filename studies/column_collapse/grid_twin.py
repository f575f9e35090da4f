"""What the column's grid costs: the continuum twin of a multiscale column case, carrying
its RVE's own measured mu(I), on the case's cells and on finer ones, with each transfer.

    python studies/column_collapse/grid_twin.py --out DIR
        [--case examples/column_collapse/representative.toml] [--cells 10 5 2.5]
        [--velocity-update aflip apic] [--pressures 200 800]
        [--inertial 0.01 0.03 0.1 0.2 0.4 0.8] [--points-per-cell N]
        [--multiscale RUN ... [--labels NAME ...]]

(a) The case's RVE's mu(I) as cross_scale.py measures it (grainscale.rve.flow on the
    case's [rve], DIR/flow.csv, flow.png, flow.mu_i.toml; reused where DIR holds it).
(b) The case's continuum twin (Case.continuum_twin with that law) on cells of each size
    in mm: the same extent, n^3 points a cell as the case, the slice one cell thick (as
    fine.toml is quick.toml on 5 mm cells), with the case's own transfer (`aflip`, its
    relaxation time) and with APIC (`apic`, no relaxation), into DIR/<transfer>_<mm>mm
    (with --points-per-cell N: N^3 points a cell instead of the case's, into
    DIR/<transfer>_<mm>mm_<N>ppc). A run already finished there is not repeated.
Where the multiscale case can only be afforded on its own grid, the twin's change from
that grid to the finer ones is what the reduction costs in a column carrying the same
grains' law. --multiscale adds finished runs of the case (on its grid) to the table and
the figure. Writes DIR/grid_twin.png (runout against t / tau_c; the final deposit's
front, 95 % and 99 % of the mass against cell size) and DIR/results.json; prints a table;
the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import NullFormatter  # noqa: E402

import grainscale as gs  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]
from convergence import experiment_bands, mass_runouts, measures  # noqa: E402
from cross_scale import measure_flow  # noqa: E402
from measurement import runout_at  # noqa: E402
from sleeping import with_apic, with_points_per_cell  # noqa: E402
from variants import run_variant  # noqa: E402

CASES = HERE.parents[1] / "examples" / "column_collapse"
TAU_C = (1, 2, 3, 4, 5, 6, 7)


def on_cells(case: gs.Case, h: float) -> gs.Case:
    """The column case on cells of h metres: the grid's extent kept, the slice (the body's
    and the walls' y extent, one cell of the case's grid) one cell of h thick."""
    h0, width = case.grid.cell_size, case.bodies[0].hi[1]
    extent = [n * h0 for n in case.grid.cells]
    cells = [round(e / h) for e in extent]
    if any(abs(n * h - e) > 1e-9 for n, e in zip(cells, extent, strict=True)):
        raise SystemExit(f"--cells {h * 1e3:g}: the grid's extent {extent} m is not a whole "
                         f"number of {h * 1e3:g} mm cells")

    def tables(t: dict) -> None:
        t["grid"]["cell_size"] = h
        t["grid"]["cells"] = [cells[0], 2, cells[2]]
        for body in t["bodies"]:
            body["hi"][1] = h
        for bc in t["boundaries"]:
            for corner in bc.get("box", {}).values():
                if abs(corner[1] - width) < 1e-12:
                    corner[1] = h

    return case.edited(tables)


def with_transfer(case_path: Path, transfer: str) -> gs.Case:
    """The case with `transfer`: its own, or APIC substituted."""
    case = gs.load_case(case_path)
    if transfer == "apic":
        with_apic(case)
    elif transfer != case.solver.velocity_update:
        raise SystemExit(f"--velocity-update {transfer}: the case has "
                         f"{case.solver.velocity_update!r}; only 'apic' is substituted")
    return case


def twin(case_path: Path, material: dict, h: float, transfer: str,
         points_per_cell: int | None = None) -> gs.Case:
    """(b): the continuum twin of the case on cells of h metres with `transfer` (and
    points_per_cell^3 points a cell where given)."""
    case = with_transfer(case_path, transfer)
    title = f"column collapse, mu(I) of {case_path.name}'s RVE, {h * 1e3:g} mm, {transfer}"
    case = on_cells(case.continuum_twin(material, title), h)
    return case if points_per_cell is None else with_points_per_cell(case, points_per_cell)


def row(run: Path) -> dict:
    """The final measures of a column run and its runout at whole tau_c."""
    h = gs.open_result(run).history
    return {**measures(h), **mass_runouts(run), "runout_at_tau_c": runout_at(h, TAU_C)}


def plot(rows: list[dict], histories: dict, png: Path) -> None:
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.4))
    colours = {"aflip": "tab:red", "apic": "tab:blue"}
    dark = {"aflip": "darkred", "apic": "navy"}  # the multiscale runs (others: black)
    cells = sorted({r["cell_mm"] for r in rows if r["kind"] == "continuum"}, reverse=True)
    styles = dict(zip(cells, ("-", "--", ":", "-."), strict=False))
    runs_of: dict[str, int] = {}
    for r in rows:
        h = histories[r["label"]]
        after = h["t_over_tc"] >= 0
        if r["kind"] == "continuum":
            ls, lw, colour = styles.get(r["cell_mm"], "-"), 1.2, colours[r["transfer"]]
        else:  # thick, one style per multiscale run of a transfer
            k = runs_of[r["transfer"]] = runs_of.get(r["transfer"], -1) + 1
            ls = ("-", "--", "-.", ":")[k % 4]
            lw, colour = 2.4, dark.get(r["transfer"], "k")
        ax.plot(h["t_over_tc"][after], h["runout_ratio"][after], ls, lw=lw, color=colour,
                label=r["label"])
    experiment_bands(ax)
    ax.set(xlabel="t / tau_c", ylabel="(L - L_i) / L_i", xlim=(0, 7))
    ax.set_ylim(bottom=0)
    for transfer in ("aflip", "apic"):
        rs = sorted((r for r in rows if r["kind"] == "continuum" and r["transfer"] == transfer),
                    key=lambda r: r["cell_mm"])
        if not rs:
            continue
        mm = [r["cell_mm"] for r in rs]
        for key, marker, what in (("runout", "o", "front"), ("runout_mass99", "s", "99 %"),
                                  ("runout_mass95", "^", "95 % of the mass")):
            bx.plot(mm, [r[key] for r in rs], marker=marker, color=colours[transfer],
                    label=f"continuum, {transfer}: {what}")
    bx.set(xscale="log", xlabel="cell size [mm]", ylabel="final runout ratio")
    bx.set_xticks(cells, [f"{c:g}" for c in cells])
    bx.xaxis.set_minor_formatter(NullFormatter())
    bx.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    bx.grid(alpha=0.3)
    ax.legend(fontsize=7)
    bx.legend(fontsize=7, ncol=2, loc="lower center")
    fig.suptitle("column collapse a = 0.6: the continuum with the RVE's mu(I) on finer grids")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--case", type=Path, default=CASES / "representative.toml")
    ap.add_argument("--cells", type=float, nargs="+", default=[10.0, 5.0, 2.5],
                    help="cell sizes in mm")
    ap.add_argument("--velocity-update", nargs="+", default=["aflip", "apic"],
                    choices=["aflip", "apic"])
    ap.add_argument("--pressures", type=float, nargs="+", default=[200.0, 800.0],
                    help="normal stresses of the flow measurement [Pa]")
    ap.add_argument("--inertial", type=float, nargs="+",
                    default=[0.01, 0.03, 0.1, 0.2, 0.4, 0.8],
                    help="inertial numbers of the flow measurement")
    ap.add_argument("--points-per-cell", type=int, default=None,
                    help="n of the twins' n^3 points a cell (default: the case's)")
    ap.add_argument("--multiscale", type=Path, nargs="*", default=[],
                    help="finished runs of the case on its own grid")
    ap.add_argument("--labels", nargs="*", default=None,
                    help="one name per --multiscale run (default: its folder's)")
    args = ap.parse_args()
    if not args.case.is_file():
        raise SystemExit(f"--case {args.case}: no such file")
    for mm in args.cells:  # every grid, transfer and run checked before the first run
        for transfer in args.velocity_update:
            on_cells(with_transfer(args.case, transfer), mm * 1e-3)
    names = args.labels if args.labels is not None else [r.name for r in args.multiscale]
    if len(names) != len(args.multiscale):
        raise SystemExit(f"--labels: {len(names)} names for {len(args.multiscale)} runs")
    for run in args.multiscale:
        if not (run / "history.csv").is_file():
            raise SystemExit(f"--multiscale {run}: no history.csv")
    args.out.mkdir(parents=True, exist_ok=True)
    material = measure_flow(args.case, args.out, 1, args.pressures, args.inertial)
    print(f"mu(I) of the RVE: mu_s {material['mu_s']}, mu_2 {material['mu_2']}, "
          f"I_0 {material['I_0']}", flush=True)
    rows, histories = [], {}
    for transfer in args.velocity_update:
        for mm in sorted(args.cells, reverse=True):
            n = args.points_per_cell
            out = args.out / (f"{transfer}_{mm:g}mm" + (f"_{n}ppc" if n is not None else ""))
            wall = run_variant(twin(args.case, material, mm * 1e-3, transfer, n), out)
            label = f"continuum, {transfer}, {mm:g} mm" + (f", {n}^3 a cell" if n else "")
            rows.append({"kind": "continuum", "transfer": transfer, "cell_mm": mm,
                         "label": label, "wall_s": round(wall, 1), **row(out / "run")})
            histories[label] = gs.open_result(out / "run").history
    for run, name in zip(args.multiscale, names, strict=True):
        result = gs.open_result(run)
        mm = result.case.grid.cell_size * 1e3
        label = f"multiscale {name}, {result.case.solver.velocity_update}, {mm:g} mm"
        rows.append({"kind": "multiscale", "transfer": result.case.solver.velocity_update,
                     "cell_mm": mm, "label": label, **row(run)})
        histories[label] = result.history
    print(f"{'run':46s} {'front':>6s} {'99 %':>6s} {'95 %':>6s} {'H_f/H_i':>7s} "
          f"{'KE end':>7s}  runout at 1-7 tau_c")
    for r in rows:
        print(f"{r['label']:46s} {r['runout']:6.3f} {r['runout_mass99']:6.3f} "
              f"{r['runout_mass95']:6.3f} {r['height_ratio']:7.3f} "
              f"{r['kinetic_energy_end_over_peak']:7.4f}  "
              + " ".join("-" if v is None else f"{v:.3f}" for v in r["runout_at_tau_c"].values()))
    coarse = max(args.cells)
    change = {}
    for transfer in args.velocity_update:
        by = {r["cell_mm"]: r for r in rows
              if r["kind"] == "continuum" and r["transfer"] == transfer}
        for mm in sorted(args.cells, reverse=True)[1:]:
            change[f"{transfer}_{coarse:g}mm_against_{mm:g}mm"] = {  # what the coarse costs
                k: round(by[coarse][k] / by[mm][k] - 1.0, 4)
                for k in ("runout", "runout_mass99", "runout_mass95")}
    (args.out / "results.json").write_text(json.dumps({"material": material, "rows": rows,
                                                       "change": change}, indent=1))
    plot(rows, histories, args.out / "grid_twin.png")
    print(json.dumps({"mu_s": material["mu_s"], "change": change}))


if __name__ == "__main__":
    main()

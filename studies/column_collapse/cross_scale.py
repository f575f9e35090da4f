"""Cross-scale consistency in flow: the multiscale column against a continuum carrying its
RVE's own measured mu(I).

    python studies/column_collapse/cross_scale.py --out DIR [--case quick.toml]
        [--tiles 1] [--pressures 200 800] [--inertial 0.003 ... 0.8] [--multiscale RUN]
        [--separation reset|recompact]

(a) grainscale.rve.flow (`grainscale rve flow`) on the RVE of the case (default
    `quick.toml`; same grains, contact law and restitution) at the column's pressure
    range, fitting mu(I) in the shear-cell measure (DIR/flow.csv, DIR/flow.png,
    DIR/flow.mu_i.toml);
(b) the mu(I) continuum with those parameters in the case's geometry: same grid,
    points, boundaries, velocity update, geostatic stage and output (DIR/continuum);
(c) the multiscale case itself (DIR/multiscale; or an existing finished run of it given
    by --multiscale);
(d) the glass-bead mu(I) baseline of `mu_i.toml` (Jop's parameters) in the same geometry
    (DIR/baseline), for reference.
Writes DIR/cross_scale.png (runout and kinetic energy against t / tau_c, every run) and
DIR/results.json; the last printed line is one JSON object with `multiscale_runout`,
`continuum_runout` and `baseline_runout` (values at 7 tau_c), the relative difference
of the first two, and where 95 % and 99 % of the mass of each of them ended
(`multiscale_runout_mass95`, ...; convergence.py's measure). A step already done in
DIR (flow.csv, a finished run) is not repeated.
`--case examples/column_collapse/fine.toml --multiscale RUN` compares a finished run of
the 5 mm column.
`--separation recompact` gives both continua that key (docs/mpm.md: mu(I) rheology;
their folders, figure and results become DIR/continuum_recompact,
DIR/baseline_recompact, DIR/cross_scale_recompact.png and DIR/results_recompact.json).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import grainscale as gs  # noqa: E402
from grainscale import analysis, rve  # noqa: E402

HERE = Path(__file__).resolve().parent
CASES = Path(__file__).resolve().parents[2] / "examples" / "column_collapse"  # the case files
sys.path[:0] = [str(HERE), str(HERE.parent)]  # convergence.py; studies/: variants.py
from convergence import experiment_bands, mass_runouts, measures  # noqa: E402
from variants import run_variant  # noqa: E402


def measure_flow(case: Path, out: Path, tiles: int, pressures: list[float],
                 inertial: list[float]) -> dict:
    """(a): the fitted [materials.sand] table of the case's RVE (grainscale.rve.flow, as
    `grainscale rve flow` runs it: DIR/flow.csv, DIR/flow.png, DIR/flow.mu_i.toml)."""
    table = out / "flow.mu_i.toml"
    if not table.is_file():
        def say(row: dict) -> None:
            print(f"P = {row['pressure_target']:.4g} Pa, rate {row['shear_rate']:.4g}/s: "
                  f"I = {row['I']:.4g}, mu = {row['mu']:.4f} +- {row['mu_err']:.4f}, mu_p = "
                  f"{row['mu_p']:.4f} +- {row['mu_p_err']:.4f}, porosity "
                  f"{row['porosity']:.4f}", flush=True)

        res = rve.flow(case, tiles=tiles, pressures=pressures, inertial=inertial,
                       material="sand", on_point=say, progress=False)
        analysis.write_columns(out / "flow.csv", res["table"])
        analysis.plot_flow(out / "flow.png", res["table"], res["fits"],
                           title=f"rve flow: {case.name}, {tiles}^3 tiles")
        if res["material"] is None:  # measured, but the points did not determine a law
            raise SystemExit(f"no mu(I) fit in {out / 'flow.csv'}: {res['fit_error']} "
                             "(--inertial needs at least 3 rates)")
        table.write_text(res["material"])
    return tomllib.loads(table.read_text())["materials"]["sand"]


def continuum_case(path: Path, material: dict, title: str) -> gs.Case:
    """(b), (d): the case with its DEM material replaced by a mu(I) continuum."""
    return gs.load_case(path).continuum_twin(material, f"column collapse, a = 0.6, {title}")


def run_multiscale(path: Path, out: Path, given: Path | None) -> Path:
    """(c): the run directory of the multiscale column."""
    case = gs.load_case(path)
    if given is not None:
        ran = gs.open_result(given)
        end = case.time.end
        if ran.history["time"][-1] < end - 1e-9:
            raise SystemExit(f"--multiscale {given}: the run has not reached t = {end} s")
        if (given / "case.resolved.toml").is_file():
            grid = ran.case.grid
            if (grid.cell_size, grid.cells) != (case.grid.cell_size, case.grid.cells):
                raise SystemExit(f"--multiscale {given}: its grid is not {path.name}'s "
                                 f"({[grid.cell_size, list(grid.cells)]} against "
                                 f"{[case.grid.cell_size, list(case.grid.cells)]})")
        return given
    run_variant(case, out / "multiscale")
    return out / "multiscale" / "run"


def plot(hs: dict, png: Path, name: str) -> None:
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    styles = (("-", "k"), ("--", "k"), ("-.", "tab:grey"))
    for (label, h), (style, colour) in zip(hs.items(), styles, strict=True):
        after = h["t_over_tc"] >= 0
        t = h["t_over_tc"][after]
        ax.plot(t, h["runout_ratio"][after], style, color=colour, label=label)
        ke = h["kinetic_energy"][after]
        bx.plot(t, ke / max(ke.max(), 1e-300), style, color=colour, label=label)
    experiment_bands(ax)
    ax.set(xlabel="t / tau_c", ylabel="(L - L_i) / L_i", xlim=(0, 7))
    ax.set_ylim(bottom=0)
    bx.set(xlabel="t / tau_c", ylabel="kinetic energy / peak", xlim=(0, 7), yscale="log")
    for b in (ax, bx):
        b.grid(alpha=0.3)
        b.legend(fontsize=8)
    fig.suptitle(f"column collapse a = 0.6 ({name}): multiscale vs its RVE's mu(I)")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--case", type=Path, default=CASES / "quick.toml",
                    help="the multiscale column case (default examples/column_collapse/quick.toml)")
    ap.add_argument("--tiles", type=int, default=1, help="supercell of the flow measurement")
    ap.add_argument("--pressures", type=float, nargs="+", default=[200.0, 800.0],
                    help="normal stresses of the flow measurement [Pa] (the column's range)")
    ap.add_argument("--inertial", type=float, nargs="+",
                    default=[0.003, 0.01, 0.03, 0.1, 0.2, 0.4, 0.8])
    ap.add_argument("--multiscale", type=Path, default=None,
                    help="a finished run of the case to use instead of running it")
    ap.add_argument("--separation", default=None, choices=["reset", "recompact"],
                    help="the continua's mu(I) separation (default: the material's own)")
    args = ap.parse_args()
    if not args.case.is_file():
        raise SystemExit(f"--case {args.case}: no such file")
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    material = measure_flow(args.case, args.out, args.tiles, args.pressures, args.inertial)
    print(f"(a) fitted mu(I): mu_s {material['mu_s']}, mu_2 {material['mu_2']}, "
          f"I_0 {material['I_0']} ({time.perf_counter() - t0:.0f} s)", flush=True)
    sep = {"separation": args.separation} if args.separation else {}
    suffix = f"_{args.separation}" if args.separation else ""
    wall_c = run_variant(continuum_case(args.case, material | sep, "mu(I) fitted to its RVE"),
                     args.out / f"continuum{suffix}")
    print(f"(b) continuum run: {wall_c:.0f} s", flush=True)
    ms = run_multiscale(args.case, args.out, args.multiscale)
    beads = gs.load_case(CASES / "mu_i.toml").materials["beads"].model_dump(
        mode="json", exclude_unset=True)
    wall_b = run_variant(continuum_case(args.case, beads | sep, "glass-bead mu(I) of mu_i.toml"),
                     args.out / f"baseline{suffix}")
    print(f"(d) glass-bead baseline run: {wall_b:.0f} s", flush=True)
    hs = {f"multiscale ({args.case.name})": gs.open_result(ms).history,
          "mu(I) continuum, fitted to the RVE":
              gs.open_result(args.out / f"continuum{suffix}" / "run").history,
          "glass-bead mu(I) (mu_i.toml)":
              gs.open_result(args.out / f"baseline{suffix}" / "run").history}
    plot(hs, args.out / f"cross_scale{suffix}.png", args.case.name)
    m_ms, m_c, m_b = (measures(h) for h in hs.values())
    mass_ms, mass_c = (mass_runouts(r) for r in (ms, args.out / f"continuum{suffix}" / "run"))
    result = {"case": args.case.name,
              "multiscale_runout": round(m_ms["runout"], 4),
              "continuum_runout": round(m_c["runout"], 4),
              "baseline_runout": round(m_b["runout"], 4),
              "relative_difference": round(m_ms["runout"] / m_c["runout"] - 1.0, 4),
              **{f"{who}_{k}": round(v, 4) for who, m in (("multiscale", mass_ms),
                                                          ("continuum", mass_c))
                 for k, v in m.items()},
              "multiscale_height_ratio": round(m_ms["height_ratio"], 4),
              "continuum_height_ratio": round(m_c["height_ratio"], 4),
              "multiscale_ke_end_over_peak": round(m_ms["kinetic_energy_end_over_peak"], 4),
              "continuum_ke_end_over_peak": round(m_c["kinetic_energy_end_over_peak"], 4),
              "mu_s": material["mu_s"], "mu_2": material["mu_2"], "I_0": material["I_0"],
              "tiles": args.tiles, "wall_s": round(time.perf_counter() - t0)}
    (args.out / f"results{suffix}.json").write_text(json.dumps(result, indent=1))
    print(json.dumps(result))

if __name__ == "__main__":
    main()

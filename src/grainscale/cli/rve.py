"""`grainscale rve ...`: generation and element tests from the command line, on the
functions of grainscale.rve (docs/api.md)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from grainscale import __version__, rve
from grainscale.config.base import ConfigError
from grainscale.config.case import load_rve_case
from grainscale.config.rve import RVECase
from grainscale.dem import element_tests
from grainscale.dem import flow as dem_flow
from grainscale.dem.generate import contact_params
from grainscale.dem.state import RVEBatch
from grainscale.io.plots import plot_flow, plot_stress_path
from grainscale.io.rve_vtk import write_rve_vtk


def prepared(case: RVECase, packing: Path | None, quiet: bool) -> RVEBatch:
    """The starting RVE: read from `packing`, or generated from the [rve] table."""
    if packing is not None:
        return rve.packing(case, packing)
    return rve.generate(case, progress=not quiet)


def write_rows(path: Path, rows: list[dict[str, float]], title: str) -> None:
    """CSV with a commented header (test, version, conventions), written atomically."""
    cols = list(rows[0])
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as f:
        f.write(f"# grainscale {__version__}: {title}\n")
        f.write(f"# {element_tests.COLUMN_DOC}\n")
        f.write(",".join(cols) + "\n")
        for r in rows:
            f.write(",".join(repr(float(r[c])) for c in cols) + "\n")
    tmp.replace(path)


def _check_out(path: Path, suffixes: tuple[str, ...], key: str) -> None:
    if path.suffix not in suffixes:
        raise ConfigError(f"{key} = {str(path)!r}: must end in one of {', '.join(suffixes)}")
    if not path.parent.exists():
        raise ConfigError(f"{key} = {str(path)!r}: folder {str(path.parent)!r} does not exist")


def dispatch(args: argparse.Namespace) -> int:
    case = load_rve_case(args.params)
    if args.rve_command == "generate":
        _check_out(args.out, (".txt", ".h5"), "--out")
        t0 = time.perf_counter()
        batch = prepared(case, None, args.quiet)
        rve.save(case, batch, args.out)
        if args.vtk is not None:
            write_rve_vtk(args.vtk, batch, contact_params(case.rve))
        row = element_tests.state_row(batch)
        print(f"wrote {args.out}: porosity {row['porosity']:.4f}, p = {row['p']:.5g} Pa, "
              f"coordination {row['coordination']:.2f} ({time.perf_counter() - t0:.1f} s)")
        return 0

    _check_out(args.out, (".csv",), "--out")
    if args.plot is not None:
        _check_out(args.plot, (".png",), "--plot")
    if args.packing is not None and not args.packing.is_file():
        raise ConfigError(f"--packing = {str(args.packing)!r}: file does not exist")
    if args.rve_command == "flow":
        return run_flow(case, args)
    table = args.rve_command
    if table not in case.model_fields_set:  # the file has no table for this test
        defaults = getattr(case, table).model_dump()
        print(f"grainscale: {args.params} has no [{table}] table: the defaults "
              + ", ".join(f"{k} = {v!r}" for k, v in defaults.items())
              + " (docs/case-files.md)", file=sys.stderr)
    batch = prepared(case, args.packing, args.quiet)
    run, x = {"triaxial": (rve.triaxial, "axial_strain"),
              "undrained": (rve.undrained, "axial_strain"),
              "isotropic": (rve.isotropic, "volumetric_strain"),
              "shear": (rve.shear, "shear_strain")}[args.rve_command]
    rows = rve.rows_of(run(case, batch, progress=not args.quiet))  # the API's curve, as rows
    write_rows(args.out, rows, f"rve {args.rve_command} of {args.params}")
    if args.plot is not None:
        cols = {c: [r[c] for r in rows] for c in rows[0]}
        plot_stress_path(args.plot, {"DEM": cols}, x=x if x != "volumetric_strain" else "p",
                         title=f"rve {args.rve_command}")
    print(f"wrote {args.out} ({len(rows)} rows)")
    return 0


# the CLI's spelling of grainscale.rve.flow's arguments, for its error messages
FLOW_OPTIONS = {"pressures": "--pressure", "inertial": "--inertial", "rates": "--rates",
                "strain": "--strain", "steady_from": "--steady-from", "tiles": "--tiles",
                "allow_damping": "--allow-damping", "material": "--material"}


def run_flow(case: RVECase, args: argparse.Namespace) -> int:
    """`grainscale rve flow`: rve.flow, its steady table as CSV, the mu(I) fit printed
    and written as a mu_i material table."""
    def say(row: dict) -> None:
        print(f"P = {row['pressure_target']:.4g} Pa, rate {row['shear_rate']:.4g}/s: "
              f"I = {row['I']:.4g}, mu = {row['mu']:.4f} +- {row['mu_err']:.4f}, mu_p = "
              f"{row['mu_p']:.4f} +- {row['mu_p_err']:.4f}, porosity {row['porosity']:.4f}",
              flush=True)

    # generation only after every argument is checked (rve.flow checks before it starts)
    start = rve.packing(case, args.packing) if args.packing is not None else None
    res = rve.flow(case, start, inertial=args.inertial, rates=args.rates,
                   pressures=args.pressure, strain=args.strain,
                   steady_from=args.steady_from, tiles=args.tiles,
                   allow_damping=args.allow_damping, material=args.material,
                   on_point=say, progress=not args.quiet, names=FLOW_OPTIONS,
                   source=str(args.params))
    col, fits = res["table"], res["fits"]
    rows = [dict(zip(col, vals, strict=True)) for vals in zip(*col.values(), strict=True)]
    _write_flow(args.out, rows, f"rve flow of {args.params} ({args.tiles}^3 tiles, "
                f"d = {res['diameter']:.6g} m, rho_s = {case.rve.density:.6g} kg/m3, strain "
                f"{args.strain}, steady from {args.steady_from})")
    print(f"wrote {args.out} ({len(rows)} rows)")
    if res["fit_error"] is not None:
        print(f"no mu(I) fit: {res['fit_error']}")
    for m, f in fits.items():
        bound = f"; {f['warning']}" if f["warning"] else ""
        print(f"fit of {m}({'I' if m == 'mu' else 'I_p'}): mu_s = {f['mu_s']:.4f} +- "
              f"{f['mu_s_err']:.2g}, mu_2 = {f['mu_2']:.4f} +- {f['mu_2_err']:.2g}, "
              f"I_0 = {f['I_0']:.4g} (ln I_0 +- {f['ln_I_0_err']:.2g}; standard errors; "
              f"rms {f['rms']:.3g} bands{bound})")
    if res["material"] is not None:
        path = args.out.with_suffix(".mu_i.toml")
        path.write_text(res["material"])
        print(f"wrote {path}:\n{res['material']}")
    if args.plot is not None:
        plot_flow(args.plot, col, fits, title=f"rve flow: {args.params.name}, "
                  f"{args.tiles}^3 x {case.rve.particles} grains")
    return 0


def _write_flow(path: Path, rows: list[dict], title: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as f:
        f.write(f"# grainscale {__version__}: {title}\n# {dem_flow.COLUMN_DOC}\n")
        f.write(",".join(dem_flow.COLUMNS) + "\n")
        for r in rows:
            f.write(",".join(repr(int(r[c])) if c in ("tiles", "particles")
                             else repr(float(r[c])) for c in dem_flow.COLUMNS) + "\n")
    tmp.replace(path)

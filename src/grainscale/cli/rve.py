"""`grainscale rve ...`: generation and element tests from the command line."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from grainscale import __version__, rve
from grainscale.config.base import ConfigError
from grainscale.config.case import load_rve_case
from grainscale.config.rve import RVECase
from grainscale.dem import element_tests, flow
from grainscale.dem.generate import contact_params
from grainscale.dem.state import RVEBatch
from grainscale.io.packing import write_packing
from grainscale.io.plots import plot_flow, plot_stress_path
from grainscale.io.progress import Progress
from grainscale.io.rve_h5 import write_rve_state
from grainscale.io.rve_vtk import write_rve_vtk


def prepared(case: RVECase, packing: Path | None, quiet: bool) -> RVEBatch:
    """The starting RVE: read from `packing`, or generated from the [rve] table."""
    if packing is not None:
        return rve.packing(case, packing)
    say = None if quiet else (lambda text: print(f"generate: {text}", file=sys.stderr))
    return rve.generate(case, progress=say)


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
        if args.out.suffix == ".h5":
            write_rve_state(args.out, batch, case.rve.model_dump(mode="json"))
        else:
            write_packing(args.out, batch.h[0], batch.s[0] @ batch.h[0].T, batch.radius[0])
        if args.vtk is not None:
            write_rve_vtk(args.vtk, batch, case.rve.young_modulus,
                          gamma=contact_params(case.rve).gamma, friction=case.rve.friction)
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
    batch = prepared(case, args.packing, args.quiet)
    test, run, x = {
        "triaxial": (case.triaxial, rve.triaxial, "axial_strain"),
        "undrained": (case.undrained, rve.undrained, "axial_strain"),
        "isotropic": (case.isotropic, rve.isotropic, "volumetric_strain"),
        "shear": (case.shear, rve.shear, "shear_strain"),
    }[args.rve_command]
    total = {"triaxial": getattr(test, "axial_strain", None),
             "undrained": getattr(test, "axial_strain", None),
             "shear": getattr(test, "shear_strain", None)}.get(args.rve_command)
    bar = tqdm(total=total, disable=args.quiet, unit="", file=sys.stderr,
               desc=f"rve {args.rve_command}",
               bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} strain "
                          "[{elapsed}<{remaining}] {postfix}" if total else None)

    def on_row(row: dict[str, float]) -> None:
        if total:
            bar.update(min(row[x], total) - bar.n)
        else:
            bar.update(1)
        bar.set_postfix_str(f"t={row['time']:.4g}s p={row['p']:.4g} q/p={row['q_over_p']:.3f}")

    rows = rve.rows_of(run(case, batch, on_row=on_row))  # the API's curve, as rows
    bar.close()
    write_rows(args.out, rows, f"rve {args.rve_command} of {args.params}")
    if args.plot is not None:
        cols = {c: [r[c] for r in rows] for c in rows[0]}
        plot_stress_path(args.plot, {"DEM": cols}, x=x if x != "volumetric_strain" else "p",
                         title=f"rve {args.rve_command}")
    print(f"wrote {args.out} ({len(rows)} rows)")
    return 0


def _check_flow_args(case: RVECase, args: argparse.Namespace) -> None:
    """Every bad option of `rve flow` named with its value and valid range."""
    def positive(key: str, values) -> None:
        for v in values:
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{key} = {v!r}: must be a finite number > 0")

    positive("--pressure", args.pressure or [case.rve.preparation.pressure])
    positive("--rates" if args.rates else "--inertial", args.rates or args.inertial)
    if not 0 < args.strain <= 20:
        raise ConfigError(f"--strain = {args.strain!r}: valid range (0, 20]")
    if not 0 <= args.steady_from <= args.strain - flow.MIN_WINDOW:
        raise ConfigError(
            f"--steady-from = {args.steady_from!r}: valid range [0, --strain - "
            f"{flow.MIN_WINDOW}] = [0, {args.strain - flow.MIN_WINDOW:.3g}] (the steady "
            "window needs enough samples for a confidence band)")
    if args.tiles**3 * case.rve.particles > 10_000_000:
        raise ConfigError(f"--tiles = {args.tiles}: {args.tiles}^3 x {case.rve.particles} "
                          "particles exceeds 10,000,000")
    if case.rve.damping > 0 and not args.allow_damping:
        raise ConfigError(
            f"rve.damping = {case.rve.damping!r}: local damping acts as a viscosity and "
            "changes the measured mu(I); set it to 0 (valid range for a flow "
            "measurement: 0), or pass --allow-damping to measure it anyway")
    if not args.material.isidentifier():
        raise ConfigError(f"--material = {args.material!r}: must be a TOML bare key "
                          "(letters, digits, underscores)")


def run_flow(case: RVECase, args: argparse.Namespace) -> int:
    """`grainscale rve flow`: steady simple shear at each (pressure, rate), the steady
    table as CSV, the mu(I) fit printed and written as a mu_i material table."""
    _check_flow_args(case, args)
    params = case.rve
    pressures = args.pressure or [params.preparation.pressure]
    start = prepared(case, args.packing, args.quiet)
    d = flow.mean_diameter(start)
    # affine (Voigt) P-wave modulus of the packing's contacts -> E at nu = 0.3: an upper
    # bound, used only for the continuum's elastic predictor and time step
    young = float(np.diagonal(start.stiffness[0]).mean()) * 1.3 * 0.4 / 0.7
    batch = flow.tile(start, args.tiles, seed=params.seed)
    cases = [(p, float(g)) for p in pressures
             for g in (args.rates if args.rates else flow.rate_for(args.inertial, d,
                                                                   params.density, p))]
    dt = element_tests.timestep(batch, params)
    durations = []  # simulated time of each run, as simple_shear rounds it to whole steps
    for p, g in cases:
        steps, n_rows = element_tests.shear_schedule(flow.shear_test(p, g, args.strain), dt)
        durations.append(n_rows * steps * dt)
    bar = Progress(0.0, sum(durations), 0.0, 0, enabled=not args.quiet)
    rows = []
    for (p, g), done in zip(cases, np.cumsum([0.0, *durations[:-1]]), strict=True):
        def on_row(row, done=done):
            t = done + row["time"]
            bar.update(t - bar.time, round(t / dt))

        row, _ = flow.steady_shear(batch, params, p, g, args.strain, args.steady_from, on_row)
        row["tiles"] = args.tiles
        rows.append({c: row[c] for c in flow.COLUMNS})
        print(f"P = {p:.4g} Pa, rate {g:.4g}/s: I = {row['I']:.4g}, mu = {row['mu']:.4f} "
              f"+- {row['mu_err']:.4f}, mu_p = {row['mu_p']:.4f} +- {row['mu_p_err']:.4f}, "
              f"porosity {row['porosity']:.4f}", flush=True)
    bar.close()
    _write_flow(args.out, rows, f"rve flow of {args.params} ({args.tiles}^3 tiles, "
                f"d = {d:.6g} m, rho_s = {params.density:.6g} kg/m3, strain {args.strain}, "
                f"steady from {args.steady_from})")
    print(f"wrote {args.out} ({len(rows)} rows)")
    col = {c: np.array([r[c] for r in rows]) for c in flow.COLUMNS}
    fits = {}
    try:
        for m, i in (("mu", "I"), ("mu_p", "I_p")):
            fits[m] = flow.fit_mu_i(col[i], col[m], col[f"{m}_err"])
    except ValueError as err:
        print(f"no mu(I) fit: {err}")
    for m, f in fits.items():
        bound = f"; {f['warning']}" if f["warning"] else ""
        print(f"fit of {m}({'I' if m == 'mu' else 'I_p'}): mu_s = {f['mu_s']:.4f} +- "
              f"{f['mu_s_err']:.2g}, mu_2 = {f['mu_2']:.4f} +- {f['mu_2_err']:.2g}, "
              f"I_0 = {f['I_0']:.4g} (ln I_0 +- {f['ln_I_0_err']:.2g}; standard errors; "
              f"rms {f['rms']:.3g} bands{bound})")
    if fits:
        slowest = int(np.argmin(col["I"]))
        table = flow.mu_i_table(args.material, fits["mu"], params, d,
                                float(col["porosity"][slowest]), young, str(args.params))
        path = args.out.with_suffix(".mu_i.toml")
        path.write_text(table)
        print(f"wrote {path}:\n{table}")
    if args.plot is not None:
        plot_flow(args.plot, col, fits, title=f"rve flow: {args.params.name}, "
                  f"{args.tiles}^3 x {params.particles} grains")
    return 0


def _write_flow(path: Path, rows: list[dict], title: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as f:
        f.write(f"# grainscale {__version__}: {title}\n# {flow.COLUMN_DOC}\n")
        f.write(",".join(flow.COLUMNS) + "\n")
        for r in rows:
            f.write(",".join(repr(r[c]) if isinstance(r[c], int) else repr(float(r[c]))
                             for c in flow.COLUMNS) + "\n")
    tmp.replace(path)

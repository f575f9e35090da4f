"""`grainscale rve ...`: generation and element tests from the command line."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from tqdm import tqdm

from grainscale import __version__
from grainscale.config.base import ConfigError
from grainscale.config.rve import RVECase, RVEParams, load_rve_case
from grainscale.dem import element_tests, engine
from grainscale.dem.generate import contact_params, generate
from grainscale.dem.state import RVEBatch, from_packing
from grainscale.io.packing import read_packing, write_packing
from grainscale.io.plots import plot_stress_path
from grainscale.io.rve_h5 import read_rve_state, write_rve_state
from grainscale.io.rve_vtk import write_rve_vtk


def load_packing(path: Path, params: RVEParams) -> RVEBatch:
    """A batch of one RVE from a .txt packing (at rest) or a .h5 full state."""
    if path.suffix == ".h5":
        batch, _ = read_rve_state(path)
        return batch.take([0])
    h, centres, radii = read_packing(path)
    return from_packing(h, centres, radii, params.density)


def prepared(case: RVECase, packing: Path | None, quiet: bool) -> RVEBatch:
    """The starting RVE: read from `packing`, or generated from the [rve] table."""
    if packing is not None:
        batch = load_packing(packing, case.rve)
    else:
        say = None if quiet else (lambda text: print(f"generate: {text}", file=sys.stderr))
        batch = generate(case.rve, progress=say)
    engine.refresh(batch, contact_params(case.rve))
    return batch


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
            write_rve_vtk(args.vtk, batch, case.rve.young_modulus)
        row = element_tests.state_row(batch)
        print(f"wrote {args.out}: porosity {row['porosity']:.4f}, p = {row['p']:.5g} Pa, "
              f"coordination {row['coordination']:.2f} ({time.perf_counter() - t0:.1f} s)")
        return 0

    _check_out(args.out, (".csv",), "--out")
    if args.plot is not None:
        _check_out(args.plot, (".png",), "--plot")
    if args.packing is not None and not args.packing.is_file():
        raise ConfigError(f"--packing = {str(args.packing)!r}: file does not exist")
    batch = prepared(case, args.packing, args.quiet)
    test, run, x = {
        "triaxial": (case.triaxial, element_tests.triaxial, "axial_strain"),
        "undrained": (case.undrained, element_tests.undrained, "axial_strain"),
        "isotropic": (case.isotropic, element_tests.isotropic, "volumetric_strain"),
        "shear": (case.shear, element_tests.simple_shear, "shear_strain"),
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

    rows = run(batch, case.rve, test, on_row=on_row)
    bar.close()
    write_rows(args.out, rows, f"rve {args.rve_command} of {args.params}")
    if args.plot is not None:
        cols = {c: [r[c] for r in rows] for c in rows[0]}
        plot_stress_path(args.plot, {"DEM": cols}, x=x if x != "volumetric_strain" else "p",
                         title=f"rve {args.rve_command}")
    print(f"wrote {args.out} ({len(rows)} rows)")
    return 0

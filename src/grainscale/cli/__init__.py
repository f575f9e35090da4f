"""The `grainscale` command: one entry point, one sub-command per job.

Each sub-command parses its arguments here and hands them to the module that does the
work; errors in the input end the command with a clear message and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from grainscale import __version__
from grainscale.config import ConfigError


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="grainscale",
        description="3D hierarchical multiscale MPM x DEM simulator for granular media",
    )
    parser.add_argument("--version", action="version", version=f"grainscale {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="run the demonstration case and write its plots")
    demo.add_argument("--out", type=Path, default=Path("grainscale-demo"),
                      help="output folder (default: ./grainscale-demo)")
    demo.add_argument("--case-only", action="store_true",
                      help="write the demo's case file, OUT/case.toml, and stop")

    run = sub.add_parser("run", help="run an MPM (or MPM x DEM) case file")
    run.add_argument("case", type=Path, help="case file (TOML)")
    run.add_argument("--out", type=Path, required=True, help="output folder")
    run.add_argument("--max-steps", type=_positive_int, default=None,
                     help="end the run at this step, counted from time.start like time.end "
                          "(a final history row is still written); the same command with "
                          "--resume after a stop ends at the same step")
    run.add_argument("--steps-this-run", type=_positive_int, default=None,
                     help="take at most this many steps in this invocation (a per-job "
                          "budget; continue later with --resume)")
    run.add_argument("--checkpoint-every", type=_positive_int, default=None,
                     help="write a checkpoint every N steps (overrides the case file)")
    run.add_argument("--resume", action="store_true",
                     help="continue from the newest valid checkpoint in --out (one whose "
                          "checksums fail is skipped for the previous one, with a "
                          "warning); refused if a physics key of the case changed since")
    run.add_argument("--allow-changed", nargs="+", default=None, metavar="KEY",
                     help="with --resume: case keys (dotted, e.g. solver.gravity, or a "
                          "table such as materials.soil) that may differ from the "
                          "checkpoint's (time.end, title, solver.threads and "
                          "output.frames, frame_interval and checkpoint_every may change "
                          "without it; output.history never: docs/case-files.md)")
    run.add_argument("--threads", type=_positive_int, default=None,
                     help="numba threads per process (overrides solver.threads)")
    run.add_argument("--device", choices=("cpu", "cuda"), default=None,
                     help="where the DEM RVEs of 'dem' materials are stepped (overrides "
                          "solver.device): cpu, or cuda (one NVIDIA GPU per process; needs "
                          "the `cuda` extra)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")

    check = sub.add_parser("check", help="what a run of a case would be, without running it")
    check.add_argument("case", type=Path, help="case file (TOML)")
    check.add_argument("--threads", type=_positive_int, default=None,
                       help="numba threads for the timed DEM steps (default: as a run)")
    check.add_argument("--dem-steps", type=float, default=None,
                       help="assumed DEM steps per RVE and MPM step of quasi-static RVEs "
                            "(default 4.6)")
    check.add_argument("--resolved", type=Path, default=None,
                       help="also write the resolved case (every default filled in, as a "
                            "run's case.resolved.toml) to this file; - for the terminal")

    rve = sub.add_parser("rve", help="pure DEM work on one periodic RVE")
    rsub = rve.add_subparsers(dest="rve_command", required=True)
    gen = rsub.add_parser("generate", help="generate a packing from the [rve] table")
    gen.add_argument("params", type=Path, help="TOML file with an [rve] table")
    gen.add_argument("--out", type=Path, required=True,
                     help="packing file: .txt (exchange format) or .h5 (full state)")
    gen.add_argument("--vtk", type=Path, default=None,
                     help="also write a ParaView snapshot (spheres + force network) here")
    gen.add_argument("--quiet", action="store_true", help="no progress bar")
    for name, help_ in [
        ("triaxial", "drained triaxial compression (lateral stress servo-held)"),
        ("isotropic", "isotropic compression to [isotropic].pressure_final"),
        ("undrained", "constant-volume triaxial compression"),
        ("shear", "simple shear at constant normal stress"),
    ]:
        p = rsub.add_parser(name, help=help_)
        p.add_argument("params", type=Path, help="TOML file with [rve] and test tables")
        p.add_argument("--packing", type=Path, default=None,
                       help="start from this packing (.txt or .h5) instead of generating one")
        p.add_argument("--out", type=Path, required=True, help="CSV file of the stress path")
        p.add_argument("--plot", type=Path, default=None, help="PNG plot of the stress path")
        p.add_argument("--quiet", action="store_true", help="no progress bar")

    flow = rsub.add_parser(
        "flow", help="steady simple shear at several rates: the RVE's mu(I) and its fit",
        description="Steady simple shear of the RVE at constant normal stress, one run per "
        "(pressure, rate): time-averaged I, mu = tau/sigma_n and porosity with 95 %% bands "
        "(CSV), and a fit of mu(I) written as a [materials.X] type = \"mu_i\" table "
        "(docs/dem.md: flow rule).")
    flow.add_argument("params", type=Path, help="TOML file with an [rve] table")
    flow.add_argument("--pressure", type=float, nargs="+", default=None, metavar="P",
                      help="normal stress(es) sigma_n [Pa] (default: rve.preparation.pressure)")
    rates = flow.add_mutually_exclusive_group(required=True)
    rates.add_argument("--rates", type=float, nargs="+", metavar="GDOT",
                       help="shear rates [1/s]")
    rates.add_argument("--inertial", type=float, nargs="+", metavar="I",
                       help="target inertial numbers instead (rate = I sqrt(P/rho_s)/d)")
    flow.add_argument("--strain", type=float, default=3.0,
                      help="shear strain of each run (default 3)")
    flow.add_argument("--steady-from", type=float, default=1.0,
                      help="average over shear strain >= this (default 1)")
    flow.add_argument("--tiles", type=_positive_int, default=1,
                      help="shear an n x n x n supercell of the packing (RVE-size effect)")
    flow.add_argument("--packing", type=Path, default=None,
                      help="start from this packing (.txt or .h5) instead of generating one")
    flow.add_argument("--material", default="rve_fit",
                      help="name of the fitted [materials.NAME] table (default rve_fit)")
    flow.add_argument("--allow-damping", action="store_true",
                      help="accept [rve] damping > 0 (it acts as a viscosity and biases mu)")
    flow.add_argument("--out", type=Path, required=True,
                      help="CSV of the steady values (the fitted table goes to OUT.mu_i.toml)")
    flow.add_argument("--plot", type=Path, default=None, help="PNG plot of mu(I) and porosity")
    flow.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    root = True  # under MPI only rank 0 reports input errors (every rank finds them)
    try:
        if args.command == "demo":
            from grainscale.cli.demo import run_demo

            return run_demo(args.out, case_only=args.case_only)
        if args.command == "run":
            from grainscale.coupling.driver import run_case
            from grainscale.distributed.comm import world

            comm = world()
            root = comm.root
            return run_case(args.case, args.out, max_steps=args.max_steps,
                            steps_this_run=args.steps_this_run,
                            checkpoint_every=args.checkpoint_every, resume=args.resume,
                            allow_changed=args.allow_changed,
                            progress=not args.quiet, threads=args.threads,
                            device=args.device, comm=comm)
        if args.command == "check":
            import json

            import numba

            from grainscale.config.case import load_case
            from grainscale.coupling.dry_run import check, format_check

            if args.threads:
                numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
            case = load_case(args.case)
            report = check(case, args.dem_steps)
            if args.resolved is not None:
                from grainscale.config.base import resolved_toml

                text = resolved_toml(case.check())
                if str(args.resolved) == "-":
                    print(text)
                else:
                    args.resolved.write_text(text)
            print(format_check(report))
            print(json.dumps(report))
            return 0
        if args.command == "rve":
            from grainscale.cli import rve

            return rve.dispatch(args)
    except ConfigError as err:
        if root:
            print(f"grainscale: error: {err}", file=sys.stderr)
        return 2
    except FileNotFoundError as err:
        if root:
            print(f"grainscale: error: file not found: {err.filename or err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # a second Ctrl-C (the first stops at the next step)
        if root:
            print("grainscale: interrupted at once; the last checkpoint written is intact: "
                  "continue with --resume", file=sys.stderr)
        return 130
    return 1

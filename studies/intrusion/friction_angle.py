"""The friction angle of an intrusion case's RVE, for the modified Archimedes law.

    python studies/intrusion/friction_angle.py CASE.toml RUN --out phi.json
    python studies/intrusion/friction_angle.py CASE.toml --realisations 16 --out phi.json
        [--strain-rate RATE] [--damping ALPHA] [--rolling ALPHA_R ETA_R]

Drained triaxial compression of RVE packings (the case's [triaxial] table: confining
pressure, rate, axial strain), one batch per loading axis (`--axes`, default x y z: the
three axes of one packing sample its fabric three ways). The mobilised angle
phi = asin((sigma_1 - sigma_3)/(sigma_1 + sigma_3)), sigma_1 the axial and sigma_3 the
mean lateral stress, is averaged over axial strains from `--from` to the end: the steady
(critical-state) part of the test, the analogue of a repose angle, which is the angle
Kang et al.'s law is written for. The peak of each path is reported beside it.
`--strain-rate` replaces the table's rate [1/s]; the result gives the strain per DEM step
it makes (rate x the DEM step), comparable with a quasi-static coupled run's
`strain_per_substep` (docs/coupling.md), which loads its RVEs at that strain per step.
`--damping` replaces the local damping of the test (the packings keep the recipe's).
`--rolling` replaces the recipe's rolling resistance ([rve] rolling_stiffness and
rolling_friction): the packings are then generated and tested with it (--realisations).

Which packings:
- RUN: the ones the run used (RUN/packings/*.h5). A geostatic library's packings
  (NAME_pL_k.h5) are each tested at their own level's pressure (from
  RUN/case.resolved.toml), and the angle is also given per level.
- `--realisations N`: N packings generated from the case's [rve] table with seeds
  rve.seed, rve.seed + 1, ... (the first `library` of them are the packings a run
  without a geostatic library uses), cached next to --out: the angle of the RVE recipe,
  not of the few packings one run draws.

A packing's sample is its mean over the axes; phi is the mean over packings with a 95 %
band from their spread (Student t), the half-width of the interval in which the recipe's
mean angle lies. Writes phi.json ({"phi_deg": ..., "phi_band95_deg": ..., ...}, the
input of analyse.py --phi-from) and prints it; with packings at one pressure it also holds
each packing's path (mobilised angle and volumetric strain against axial strain, averaged
over the axes, on 41 strains: `paths`), which loading_table.py compares between loadings.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import tomllib
from pathlib import Path

import numpy as np

from grainscale import rve
from grainscale.analysis import t95

AXES = {"x": 0, "y": 1, "z": 2}
def mobilised_angle(rows: list[dict[str, float]], axis: str) -> np.ndarray:
    """phi [deg] along a triaxial path along `axis` (stresses compression positive)."""
    names = ("sigma_xx", "sigma_yy", "sigma_zz")
    a = AXES[axis]
    s1 = np.array([r[names[a]] for r in rows])
    s3 = 0.5 * sum(np.array([r[names[k]] for r in rows]) for k in range(3) if k != a)
    return np.degrees(np.arcsin((s1 - s3) / (s1 + s3)))


def run_packings(run: Path) -> list[tuple[Path, float | None]]:
    """(packing, its geostatic level's pressure or None) for every packing of a run."""
    packings = sorted((run / "packings").glob("*.h5"))
    if not packings:
        raise SystemExit(f"{run / 'packings'}: no packings (*.h5); run the case first")
    resolved = run / "case.resolved.toml"
    materials = tomllib.loads(resolved.read_text())["materials"] if resolved.is_file() else {}
    out = []
    for p in packings:
        m = re.fullmatch(r"(.+)_p(\d+)_\d+", p.stem)
        if m is None:
            out.append((p, None))
            continue
        levels = materials.get(m.group(1), {}).get("geostatic_pressures")
        if not levels:
            raise SystemExit(f"{p}: a geostatic packing, but {resolved} gives no "
                             f"materials.{m.group(1)}.geostatic_pressures")
        out.append((p, float(levels[int(m.group(2))])))
    return out


def realisations(case, n: int, folder: Path) -> list[Path]:
    """n packings of the case's [rve] recipe with seeds seed .. seed + n - 1 (the first
    ones are a run's library), cached in folder."""
    paths = [folder / f"packing_{k}.h5" for k in range(n)]
    for k, path in enumerate(paths):
        rve.generate(case, seed=case.rve.seed + k, path=path)
    return paths


def steady_angles(paths: list[Path], case, test, axes: list[str], start: float):
    """Steady and peak angles [deg], arrays (packings, axes), of the packings tested
    together as one batch per axis, with the [triaxial] table `test` (its confining
    pressure) and the case's [rve] contact law."""
    batch = rve.packing(case, paths)
    strain_per_step = test.strain_rate * rve.timestep(case, batch)
    steady = np.empty((len(paths), len(axes)))
    peak = np.empty_like(steady)
    tested = []  # (packing, axial strain, phi, eps_v) of every path
    for j, axis in enumerate(axes):
        along = case.model_copy(update={"triaxial": test.model_copy(update={"axis": axis})})
        curves = rve.triaxial(along, batch, progress=False, per_rve=True)
        for i, curve in enumerate(curves):
            rows = rve.rows_of(curve)
            phi = mobilised_angle(rows, axis)
            strain = np.array([r["axial_strain"] for r in rows])
            tested.append((i, strain, phi, np.array([r["volumetric_strain"] for r in rows])))
            window = strain >= start
            if window.sum() < 5:
                raise SystemExit(f"fewer than 5 rows beyond axial strain {start}: "
                                 f"raise [triaxial] axial_strain or lower --from")
            steady[i, j] = phi[window].mean()
            peak[i, j] = phi.max()
    return steady, peak, strain_per_step, mean_paths(len(paths), tested)


def mean_paths(n: int, tested, points: int = 41) -> dict:
    """Each of the n packings' mobilised angle and volumetric strain, averaged over its
    axes, on a common axial-strain grid from 0 to the shortest path's end (linear
    interpolation); tested: (packing, axial strain, phi, eps_v) of every path."""
    end = min(float(x[-1]) for _, x, _, _ in tested)
    grid = np.linspace(0.0, end, points)
    out = {"axial_strain": grid, "phi_deg": np.zeros((n, points)),
           "volumetric_strain": np.zeros((n, points))}
    count = np.zeros(n)
    for i, x, phi, ev in tested:
        out["phi_deg"][i] += np.interp(grid, x, phi)
        out["volumetric_strain"][i] += np.interp(grid, x, ev)
        count[i] += 1
    out["phi_deg"] /= count[:, None]
    out["volumetric_strain"] /= count[:, None]
    return out


def summary(samples: np.ndarray) -> tuple[float, float]:
    """Mean and 95 % half-band (Student t over the samples; NaN for one sample)."""
    n = len(samples)
    if n < 2:
        return float(samples.mean()), math.nan
    return float(samples.mean()), t95(n - 1) * float(samples.std(ddof=1)) / math.sqrt(n)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", type=Path)
    ap.add_argument("run", type=Path, nargs="?", help="output folder of a run of the case")
    ap.add_argument("--realisations", type=int, metavar="N",
                    help="test N packings generated from the case's [rve] table instead")
    ap.add_argument("--axes", nargs="+", choices=list(AXES), default=["x", "y", "z"])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--from", dest="start", type=float, default=0.1,
                    help="axial strain where the steady window starts")
    ap.add_argument("--strain-rate", type=float, metavar="RATE",
                    help="1/s, instead of the [triaxial] table's")
    ap.add_argument("--damping", type=float, metavar="ALPHA",
                    help="local damping during the test, instead of [rve] damping (the "
                         "packings are still prepared with the recipe's)")
    ap.add_argument("--rolling", type=float, nargs=2, metavar=("ALPHA_R", "ETA_R"),
                    help="rolling resistance of the recipe ([rve] rolling_stiffness, "
                         "rolling_friction), with --realisations")
    args = ap.parse_args(argv)
    if args.rolling is not None and args.realisations is None:
        ap.error("--rolling makes a new recipe: give --realisations N with it")
    if (args.run is None) == (args.realisations is None):
        ap.error("give either RUN or --realisations N")
    if args.realisations is not None and args.realisations < 1:
        ap.error(f"--realisations = {args.realisations}: must be at least 1")
    case = rve.load(args.case)
    if case.triaxial is None:
        raise SystemExit(f"{args.case}: no [triaxial] table (confining pressure, rate, strain)")
    if args.strain_rate is not None:
        if not 0.0 < args.strain_rate <= 100.0:
            ap.error(f"--strain-rate {args.strain_rate}: valid 0 < rate <= 100 1/s")
        case.triaxial.strain_rate = args.strain_rate
    if args.damping is not None and not 0.0 <= args.damping < 1.0:
        ap.error(f"--damping {args.damping}: valid 0 <= alpha < 1")
    if args.rolling is not None:
        try:
            rolled = type(case.rve).model_validate(
                {**case.rve.model_dump(), "rolling_stiffness": args.rolling[0],
                 "rolling_friction": args.rolling[1]})
        except ValueError as err:  # pydantic's ValidationError: the first message
            ap.error(f"--rolling {args.rolling[0]} {args.rolling[1]}: "
                     f"{err.errors()[0]['msg']}")
        case = case.model_copy(update={"rve": rolled})
    if args.realisations is not None:
        folder = args.out.with_name(f"{args.out.stem}_packings")
        tested = [(p, None) for p in realisations(case, args.realisations, folder)]
        what = f"{args.realisations} packings of the [rve] recipe (seeds {case.rve.seed}..)"
    else:
        tested = run_packings(args.run)
        what = f"the {len(tested)} packings of {args.run}"
    if args.damping is not None:  # the test's damping; the packings keep the recipe's
        case = case.model_copy(update={"rve": case.rve.model_copy(
            update={"damping": args.damping})})
    by_pressure: dict[float, list[int]] = {}
    for i, (_, level) in enumerate(tested):
        by_pressure.setdefault(level or case.triaxial.confining_pressure, []).append(i)
    steady = np.empty((len(tested), len(args.axes)))
    peak = np.empty_like(steady)
    paths = {}
    for pressure, idx in sorted(by_pressure.items()):
        print(f"triaxial at {pressure:g} Pa: {len(idx)} packing(s) x axes {args.axes}",
              file=sys.stderr, flush=True)
        test = case.triaxial.model_copy(update={"confining_pressure": pressure})
        steady[idx], peak[idx], strain_per_step, paths[pressure] = steady_angles(
            [tested[i][0] for i in idx], case, test, args.axes, args.start)
    phi, band = summary(steady.mean(axis=1))
    peak_mean, peak_band = summary(peak.mean(axis=1))
    result = {
        "phi_deg": round(phi, 2), "phi_band95_deg": round(band, 2),
        "peak_phi_deg": round(peak_mean, 2), "peak_phi_band95_deg": round(peak_band, 2),
        "phi_per_axis_deg": {a: round(float(steady[:, j].mean()), 2)
                             for j, a in enumerate(args.axes)},
        "phi_per_packing_deg": [round(float(m), 2) for m in steady.mean(axis=1)],
        "peak_phi_per_packing_deg": [round(float(m), 2) for m in peak.mean(axis=1)],
        "method": f"drained triaxial along {' '.join(args.axes)}, mean mobilised angle for "
                  f"axial strain >= {args.start}; {what}",
        "strain_rate": case.triaxial.strain_rate, "damping": case.rve.damping,
        "rolling_stiffness": case.rve.rolling_stiffness,
        "rolling_friction": case.rve.rolling_friction,
        "strain_per_dem_step": float(f"{strain_per_step:.3g}"),
        "case": str(args.case), "packings": [p.name for p, _ in tested]}
    if len(by_pressure) == 1:  # the paths, for comparing loadings (loading_table.py)
        (p,) = paths.values()
        result["paths"] = {"axial_strain": [round(float(x), 6) for x in p["axial_strain"]],
                           "phi_deg_per_packing": np.round(p["phi_deg"], 4).tolist(),
                           "volumetric_strain_per_packing":
                               np.round(p["volumetric_strain"], 7).tolist()}
    if len(by_pressure) > 1:
        result["phi_per_level_deg"] = {
            f"{p:g}": [round(v, 2) for v in summary(steady[idx].mean(axis=1))]
            for p, idx in sorted(by_pressure.items())}
    args.out.write_text(json.dumps(result, indent=1))
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())

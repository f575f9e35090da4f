"""K_phi against the friction angle: the no-slip intrusion (examples/intrusion/noslip.toml)
at several RVE friction angles, set by the rolling resistance (seed Eq. 27-29, Fig. 14).

    python studies/intrusion/kphi_angles.py run ETA_R --out DIR [--shape cuboid |
        --case examples/intrusion/noslip_fine.toml] [--library N] [--threads N]
    python studies/intrusion/kphi_angles.py collect DIR --name NAME (--eta-r ETA_R |
        --twin-phi PHI) [--partial] [--data studies/intrusion/data/noslip]
    python studies/intrusion/kphi_angles.py table [--data studies/intrusion/data/noslip]
        [--png docs/img/kphi_angles.png] [--min-window 0.8]

`run`: noslip.toml (or noslip_cuboid.toml) with [rve] rolling_stiffness = 1 and
rolling_friction = ETA_R (0: no rolling resistance, the plain RVE), run into DIR, resumed
from its newest checkpoint where DIR holds one (a stopped run goes on where it stopped).
`--case` runs another no-slip case (noslip_fine.toml: 6 cells over R, a 3 m quarter,
to d/R 3). `--library N` draws the bed from packings 0 .. N-1 of the recipe (the case's 2 by
default): with 8 they are exactly the packings whose angles PHI_FILES quote, so the bed
is made of the material whose angle is measured.
The angle each ETA_R gives is measured on the same [rve] table (noslip.toml's [rve] and
[triaxial] are quick.toml's) by
    python studies/intrusion/friction_angle.py examples/intrusion/quick.toml \
        --realisations 8 [--rolling 1 ETA_R] --out phi.json
whose results are studies/rolling/data/q_e0.json and q_a1_e<ETA_R>.json (PHI_FILES).
The continuum twins are baselines.py's Mohr-Coulomb beds of the same case:
    python studies/intrusion/baselines.py --cases noslip.toml --materials mohr_coulomb \
        --phi PHI --out DIR

`collect`: the small files of a finished run (history.csv, case.resolved.toml, cost.json)
copied to DATA/NAME with meta.json (ETA_R or the twin's PHI; with --partial, a run
stopped before its end, and the d/R it reached), and, for a multiscale run,
the zone carried with the intruder at d/R 1, 1.5 and 2 (examples/intrusion/stagnant.py
--field velocity, its default --carried share) in stagnant.json: what `table` reads, so
the table and figure are rebuilt from the repository after the run folders are gone.

`table`: for each collected run, K_phi and p_0 by analyse.py's rule (the window start by
the linearity test and slope stability; the standard error and the uncertainty with the
model error, K_phi_u), over the rule's window and over each of WINDOWS (d/R 0-2 and
1-2), against Kang's law at the steady and peak angles of the bed's own packings (the
first `library` of the recipe's, from the per-packing angles of PHI_FILES, with their
95 % band); the twins at their angle. A multiscale K_phi follows an angle definition
when it lies within 25 % of the law at that angle; the verdict is "undecided" when
K_phi +- K_phi_u straddles an edge of that band. A slope is "steady" when the rule's
window is at least --min-window long and linear. Cuboid / cylinder (same eta_r and
library) and multiscale / twin (the twin at the recipe's angle) ratios are taken over the
common span of their windows. Writes the figure (left:
p_u/(rho g R) against d/R of every run with its fit; right: K_phi against phi, the
multiscale points at their steady angle, filled, and at their peak angle, open, with
their bands; the twins; Kang's law over 15-45 deg; the seed's point) and prints the
table; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import grainscale as gs  # noqa: E402
from grainscale.analysis import k_phi  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CASES = ROOT / "examples" / "intrusion"
sys.path.insert(0, str(CASES))
from analyse import InputError, analyse, load_run  # noqa: E402

sys.path.insert(0, str(HERE))
from friction_angle import summary as angle_summary  # noqa: E402

SHAPES = {"cylinder": CASES / "noslip.toml", "cuboid": CASES / "noslip_cuboid.toml"}
DATA = HERE / "data" / "noslip"
ALPHA_R = 1.0  # rolling stiffness: sets the DEM step, not the angle (docs/validation.md §3)
PHI_FILES = {0.0: "q_e0.json", 0.05: "q_a1_e0.05.json", 0.1: "q_a1_e0.1.json",
             0.15: "q_a1_e0.15.json", 0.2: "q_a1_e0.2.json", 0.3: "q_a1_e0.3.json"}
SEED_POINT = (26.8, 1.5, 23.0)  # seed §4.3: repose angle +- its spread [deg], K_phi
FOLLOWS = 0.25  # a K_phi "follows" an angle definition within this share of the law
WINDOWS = ((0.0, 2.0), (1.0, 2.0))  # d/R: fixed windows every verdict is also stated on
CARRIED_AT = (1.0, 1.5, 2.0)  # d/R of the carried-depth frames


def phi_file(eta_r: float) -> Path:
    """The measured friction angle (friction_angle.py's JSON) of the RVE with eta_r."""
    name = PHI_FILES.get(round(eta_r, 6))
    if name is None:
        raise SystemExit(f"--eta-r {eta_r}: no measured angle; valid {sorted(PHI_FILES)} "
                         "(measure another with friction_angle.py --rolling 1 ETA_R)")
    return ROOT / "studies" / "rolling" / "data" / name


def angle_case(eta_r: float, shape: str = "cylinder", library: int | None = None,
               path: Path | None = None) -> gs.Case:
    """noslip.toml (or noslip_cuboid.toml, or the case at `path`) with rolling resistance
    eta_r at alpha_r = 1 (none at eta_r = 0), its bed drawn from `library` packings (None:
    the case's)."""
    if not 0.0 <= eta_r <= 1.0:
        raise SystemExit(f"ETA_R {eta_r}: valid 0 to 1")
    case = gs.load_case(path if path is not None else SHAPES[shape])
    if library is not None:
        case.materials["sand"].library = library
        case.title += f", a bed of {library} packings"
    if eta_r > 0.0:
        # both keys at once: each alone is refused (the [rve] table's rule)
        case.rve = type(case.rve).model_validate(
            {**case.rve.model_dump(), "rolling_stiffness": ALPHA_R, "rolling_friction": eta_r})
        case.title += f", rolling resistance alpha_r {ALPHA_R:g}, eta_r {eta_r:g}"
    return case


def run(eta_r: float, shape: str, out: Path, threads: int | None,
        library: int | None = None, path: Path | None = None) -> None:
    case = angle_case(eta_r, shape, library, path).check()
    resume = any((out / name).is_file() for name in ("checkpoint.h5", "checkpoint.prev.h5"))
    gs.run(case, out, resume=resume, threads=threads)


def collect(run_dir: Path, name: str, eta_r: float | None, twin_phi: float | None,
            data: Path, partial: bool = False) -> Path:
    """Copy a finished run's small files to data/name with meta.json (module docstring;
    the intruder's shape read from the run's case); with `partial`, a run stopped before
    time.end too, its last d/R recorded."""
    if (run_dir / "run" / "history.csv").is_file():  # a baselines.py folder
        run_dir = run_dir / "run"
    result = gs.open_result(run_dir)
    h = result.history
    stopped = h["time"][-1] < result.case.time.end - 1e-9
    if stopped and not partial:
        raise SystemExit(f"{run_dir}: stopped at t = {h['time'][-1]:.4g} s before "
                         f"time.end {result.case.time.end:g} s; finish it first (or "
                         "--partial)")
    to = data / name
    to.mkdir(parents=True, exist_ok=True)
    for f in ("history.csv", "case.resolved.toml", "cost.json"):
        if (run_dir / f).is_file():
            shutil.copy2(run_dir / f, to / f)
    meta = {"shape": "cuboid" if result.case.rigid.shape == "box" else "cylinder"}
    if stopped:
        meta["stopped_at_d_over_R"] = round(float(h["depth_over_R"][-1]), 4)
    if twin_phi is not None:
        meta |= {"kind": "twin", "phi_deg": twin_phi}
    else:
        meta |= {"kind": "multiscale", "eta_r": eta_r,
                 "phi_file": str(phi_file(eta_r).relative_to(ROOT))}
        out = subprocess.run(
            [sys.executable, str(CASES / "stagnant.py"), str(run_dir), "--field", "velocity",
             "--depths", *map(str, CARRIED_AT), "--png", str(run_dir / "carried.png")],
            capture_output=True, text=True, check=True).stdout
        (to / "stagnant.json").write_text(out.strip().splitlines()[-1] + "\n")
    (to / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    return to


def fit(folder: Path, phi: float, min_window: float, start: float | None = None,
        stop: float | None = None) -> dict:
    """analyse.py on one collected run: K_phi, p_0, their standard errors, the window (the
    rule's, or [start, stop] where given), its linearity test and the slope's uncertainty
    with the model error (K_phi_u; analyse.linearity). `steady`: the rule's window is at
    least min_window long and passed the linearity test."""
    try:
        with tempfile.TemporaryDirectory() as tmp:  # analyse() plots; `table` draws its own
            r = analyse([folder], phi, start=start, stop=stop,
                        png=Path(tmp) / "fit.png")["runs"][0]
    except InputError as err:
        raise SystemExit(str(err)) from None
    r["steady"] = bool(r["window"][1] - r["window"][0] >= min_window - 1e-9
                       and r["linear"] is not False and r["window_rule"] != "fallback")
    return r


def verdict(k: float, u: float, law: float) -> str:
    """Whether a slope K +- u follows a law's value (within FOLLOWS of it): "follows" or
    "not", firm when all of [K - u, K + u] lies on one side of the band's edges, else
    "undecided" (the uncertainty straddles an edge)."""
    lo, hi = (k - u) / law, (k + u) / law
    if 1 - FOLLOWS <= lo and hi <= 1 + FOLLOWS:
        return "follows"
    if hi < 1 - FOLLOWS or lo > 1 + FOLLOWS:
        return "not"
    return "undecided"


def bed_angles(meta: dict, library: int) -> dict:
    """The steady and peak angles of the bed's own packings (the first `library` of the
    recipe's, friction_angle.py's per-packing results) with their 95 % bands, and the
    recipe's (all packings measured) beside them."""
    phi = json.loads((ROOT / meta["phi_file"]).read_text())
    steady, peak = phi["phi_per_packing_deg"], phi["peak_phi_per_packing_deg"]
    if library > len(steady):
        raise SystemExit(f"{meta['phi_file']}: {len(steady)} packings measured, the bed "
                         f"holds {library}; measure them (friction_angle.py --realisations)")
    s, sb = angle_summary(np.array(steady[:library]))
    p, pb = angle_summary(np.array(peak[:library]))
    return {"library": library, "phi_deg": round(s, 2), "phi_band95_deg": round(sb, 2),
            "peak_phi_deg": round(p, 2), "peak_phi_band95_deg": round(pb, 2),
            "phi_recipe_deg": phi["phi_deg"], "peak_phi_recipe_deg": phi["peak_phi_deg"]}


def common_ratio(folder_a: Path, a: dict, folder_b: Path, b: dict) -> dict:
    """K_a / K_b fitted over the two rule windows' common span, with its uncertainty
    from both K_phi_u."""
    lo, hi = max(a["window"][0], b["window"][0]), min(a["window"][1], b["window"][1])
    fa = fit(folder_a, 20.0, 0.0, start=lo, stop=hi + 1e-6)
    fb = fit(folder_b, 20.0, 0.0, start=lo, stop=hi + 1e-6)
    ratio = fa["K_phi"] / fb["K_phi"]
    rel = math.hypot(fa.get("K_phi_u", fa["K_phi_stderr"]) / fa["K_phi"],
                     fb.get("K_phi_u", fb["K_phi_stderr"]) / fb["K_phi"])
    return {"window": [lo, hi], "ratio": ratio, "ratio_u": ratio * rel}


def rows(data: Path, min_window: float) -> list[dict]:
    out = []
    for meta_file in sorted(data.glob("*/meta.json")):
        meta = json.loads(meta_file.read_text())
        folder = meta_file.parent
        grid = tomllib.loads((folder / "case.resolved.toml").read_text())["grid"]
        row = {"name": folder.name, **meta,  # a graded grid: its fine cells
               "cell_m": grid.get("cell_size") or grid["nodes_z"]["cell"]}
        if meta["kind"] == "multiscale":
            resolved = tomllib.loads((folder / "case.resolved.toml").read_text())
            library = next(m["library"] for m in resolved["materials"].values()
                           if m.get("type") == "dem")
            row |= bed_angles(meta, library)
            stag = folder / "stagnant.json"
            if stag.is_file():
                row["carried"] = [{k: f[k] for k in ("depth_over_R", "carried_depth_axis",
                                                     "carried_depth_edge")}
                                  for f in json.loads(stag.read_text())["frames"]]
        f = fit(folder, row["phi_deg"], min_window)
        row |= {k: f[k] for k in ("K_phi", "K_phi_stderr", "p_0", "p_0_stderr", "window",
                                  "window_rule", "steady", "ripple_rms_pct", "linear",
                                  "local_slopes", "period")}
        for k in ("K_phi_u", "model_error", "curvature_t", "curvature_t95", "slope_change"):
            row[k] = f.get(k)
        row["K_phi_u"] = row["K_phi_u"] or row["K_phi_stderr"]
        row["K_kang_steady"] = k_phi(row["phi_deg"])
        row["windows"] = []
        for lo, hi in WINDOWS:
            hi = min(hi, row["window"][1])
            w = fit(folder, row["phi_deg"], 0.0, start=lo, stop=hi + 1e-6)
            row["windows"].append({"window": [lo, hi], "K_phi": w["K_phi"],
                                   "K_phi_u": w.get("K_phi_u") or w["K_phi_stderr"],
                                   "linear": w["linear"]})
        if meta["kind"] == "multiscale":
            b, pb = row["phi_band95_deg"], row["peak_phi_band95_deg"]
            row["K_kang_steady_band95"] = [k_phi(row["phi_deg"] - b), k_phi(row["phi_deg"] + b)]
            row["K_kang_peak"] = k_phi(row["peak_phi_deg"])
            row["K_kang_peak_band95"] = [k_phi(row["peak_phi_deg"] - pb),
                                         k_phi(row["peak_phi_deg"] + pb)]
            row["follows_steady"] = abs(row["K_phi"] / row["K_kang_steady"] - 1) <= FOLLOWS
            row["follows_peak"] = abs(row["K_phi"] / row["K_kang_peak"] - 1) <= FOLLOWS
            for w in [row, *row["windows"]]:
                w["verdict_steady"] = verdict(w["K_phi"], w["K_phi_u"], row["K_kang_steady"])
                w["verdict_peak"] = verdict(w["K_phi"], w["K_phi_u"], row["K_kang_peak"])
        out.append(row)
    by_name = {r["name"]: r for r in out}
    for r in out:  # ratios over common windows: cuboid / cylinder, multiscale / twin
        if r["kind"] != "multiscale":
            continue
        for other in out:
            if other is r or other["kind"] not in ("multiscale", "twin"):
                continue
            pair = None
            if (other["kind"] == "multiscale" and r["shape"] == "cuboid"
                    and other["shape"] == "cylinder" and other["eta_r"] == r["eta_r"]
                    and other.get("library") == r.get("library")):
                pair = "over_cylinder"
            elif (other["kind"] == "twin" and other["shape"] == r["shape"]
                  and abs(other["phi_deg"] - r["phi_recipe_deg"]) < 0.01):
                pair = "over_twin"
            if pair:
                r[pair] = {"name": other["name"], **common_ratio(
                    data / r["name"], r, data / other["name"], by_name[other["name"]])}
    if not out:
        raise SystemExit(f"{data}: no collected runs (*/meta.json); see `collect`")
    return out


def print_table(table: list[dict]) -> None:
    """The table: per run the angles of its bed's packings, K_phi +- its uncertainty with
    the model error over the rule's window, the linearity test, the ratio to Kang's law
    at both angles with the verdicts; then the same over each of WINDOWS; then the
    ratios over common windows."""
    print(f"{'run':<16} {'shape':<8} {'lib':>3} {'phi steady':>12} {'phi peak':>12} "
          f"{'window':>10} {'K_phi +- u (se)':>22} {'t curv':>11} {'K/Kang st':>9} "
          f"{'K/Kang pk':>9}  verdicts steady/peak")
    for r in table:
        win = f"{r['window'][0]:.2f}-{r['window'][1]:.2f}" + ("" if r["steady"] else "*")
        curv = ("-" if r["curvature_t"] is None
                else f"{r['curvature_t']:+.1f}/{r['curvature_t95']:.1f}")
        k = f"{r['K_phi']:>7.2f} +- {r['K_phi_u']:<5.2f} ({r['K_phi_stderr']:.2f})"
        if r["kind"] == "twin":
            print(f"{r['name']:<16} {r['shape']:<8} {'MC':>3} {r['phi_deg']:>12.2f} "
                  f"{'':>12} {win:>10} {k:>22} {curv:>11} "
                  f"{r['K_phi'] / r['K_kang_steady']:>9.2f}")
            continue
        print(f"{r['name']:<16} {r['shape']:<8} {r['library']:>3} "
              f"{r['phi_deg']:>6.2f} +-{r['phi_band95_deg']:<4.2f} "
              f"{r['peak_phi_deg']:>6.2f} +-{r['peak_phi_band95_deg']:<4.2f} {win:>10} "
              f"{k:>22} {curv:>11} {r['K_phi'] / r['K_kang_steady']:>9.2f} "
              f"{r['K_phi'] / r['K_kang_peak']:>9.2f}  {r['verdict_steady']}/"
              f"{r['verdict_peak']}")
    print("*: not a steady slope (window shorter than --min-window, curved by the linearity "
          "test, or the rule's fallback); u: the slope's uncertainty with the model error")
    for lo, hi in WINDOWS:
        print(f"\nover d/R {lo:g}-{hi:g} (or to the run's end):")
        for r in table:
            w = next(w for w in r["windows"] if w["window"][0] == lo)
            text = (f"  {r['name']:<16} {w['window'][0]:.2f}-{w['window'][1]:.2f} "
                    f"K {w['K_phi']:7.2f} +- {w['K_phi_u']:<6.2f} linear {w['linear']}")
            if r["kind"] == "multiscale":
                text += (f"  K/Kang {w['K_phi'] / r['K_kang_steady']:.2f} / "
                         f"{w['K_phi'] / r['K_kang_peak']:.2f}  {w['verdict_steady']}/"
                         f"{w['verdict_peak']}")
            print(text)
    print("\nratios over common windows:")
    for r in table:
        for key in ("over_cylinder", "over_twin"):
            if key in r:
                c = r[key]
                print(f"  {r['name']} / {c['name']}: {c['ratio']:.3f} +- {c['ratio_u']:.3f} "
                      f"over d/R {c['window'][0]:.2f}-{c['window'][1]:.2f}")


def figure(table: list[dict], data: Path, png: Path) -> None:
    """Left: p_u/(rho g R) against d/R of every collected run with its fit over the
    rule's window; right: K_phi against phi (module docstring)."""
    fig, (ax0, ax) = plt.subplots(1, 2, figsize=(12.0, 4.8))
    for r, colour in zip(table, plt.cm.tab10.colors * 2, strict=False):
        run = load_run(data / r["name"])
        what = (f"eta_r {r['eta_r']:g}, {r['phi_deg']:.1f} deg" if r["kind"] == "multiscale"
                else f"Mohr-Coulomb {r['phi_deg']:.1f} deg")
        style = "." if r["kind"] == "multiscale" else "x"
        ax0.plot(run["x"], run["y"], style, ms=3, color=colour,
                 label=f"{r['shape']}, {what}: K = {r['K_phi']:.1f}")
        xs = np.array(r["window"])
        ax0.plot(xs, r["K_phi"] * xs + r["p_0"], "-", color=colour, lw=1.2)
    ax0.set(xlabel="d / R", ylabel="p_u / (rho g R)", xlim=(0, None), ylim=(0, None))
    ax0.legend(fontsize=6, loc="upper left")
    phis = np.linspace(15.0, 45.0, 121)
    ax.semilogy(phis, [k_phi(p) for p in phis], "k-", lw=1.2,
                label="Kang et al. 2018 (seed Eq. 27-29)")
    groups = [("multiscale", "cylinder", None, "o", "C0", "multiscale cylinder"),
              ("multiscale", "cuboid", None, "s", "C1", "multiscale cuboid")]
    for i, cell in enumerate(sorted({r["cell_m"] for r in table if r["kind"] == "twin"},
                                    reverse=True)):
        for shape, mark in (("cylinder", "^"), ("cuboid", "v")):
            groups.append(("twin", shape, cell, mark, ("C2", "C4", "C5", "C6")[i % 4],
                           f"Mohr-Coulomb twin, {shape}, {cell:.3g} m cells"))
    for kind, shape, cell, mark, colour, label in groups:
        sel = [r for r in table if r["kind"] == kind and r["shape"] == shape
               and (cell is None or r["cell_m"] == cell)]
        if not sel:
            continue
        k = np.array([r["K_phi"] for r in sel])
        dk = np.array([r["K_phi_stderr"] for r in sel])
        phi = np.array([r["phi_deg"] for r in sel])
        dphi = np.array([r.get("phi_band95_deg", 0.0) for r in sel])
        ax.errorbar(phi, k, xerr=dphi, yerr=dk, fmt=mark, color=colour, ms=6, capsize=2,
                    label=f"{label}, steady angle" if kind == "multiscale" else label)
        if kind == "multiscale":
            ax.errorbar([r["peak_phi_deg"] for r in sel], k,
                        xerr=[r["peak_phi_band95_deg"] for r in sel], yerr=dk, fmt=mark,
                        mfc="none", color=colour, ms=6, capsize=2,
                        label=f"{label}, peak angle")
    phi_s, dphi_s, k_s = SEED_POINT
    ax.errorbar([phi_s], [k_s], xerr=[dphi_s], fmt="*", color="C3", ms=11,
                label="seed (repose angle 26.8 deg)")
    ax.set(xlabel="friction angle phi (deg)", ylabel="K_phi", xlim=(15, 45))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("eta_r", type=float)
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--shape", choices=sorted(SHAPES), default="cylinder")
    r.add_argument("--case", type=Path, help="another no-slip case (default: by --shape)")
    r.add_argument("--threads", type=int)
    r.add_argument("--library", type=int,
                   help="packings the bed is drawn from (default: the case's 2)")
    c = sub.add_parser("collect")
    c.add_argument("run_dir", type=Path)
    c.add_argument("--name", required=True)
    g = c.add_mutually_exclusive_group(required=True)
    g.add_argument("--eta-r", type=float)
    g.add_argument("--twin-phi", type=float)
    c.add_argument("--data", type=Path, default=DATA)
    c.add_argument("--partial", action="store_true",
                   help="accept a run stopped before time.end (its last d/R recorded)")
    t = sub.add_parser("table")
    t.add_argument("--data", type=Path, default=DATA)
    t.add_argument("--png", type=Path, default=ROOT / "docs" / "img" / "kphi_angles.png")
    t.add_argument("--min-window", type=float, default=0.8,
                   help="d/R: the shortest window that counts as a steady slope")
    args = ap.parse_args()
    if args.cmd == "run":
        run(args.eta_r, args.shape, args.out, args.threads, args.library, args.case)
    elif args.cmd == "collect":
        if args.eta_r is not None:
            phi_file(args.eta_r)  # refused before anything is copied
        print(collect(args.run_dir, args.name, args.eta_r, args.twin_phi, args.data,
                      args.partial))
    else:
        table = rows(args.data, args.min_window)
        print_table(table)
        figure(table, args.data, args.png)
        print(json.dumps({"png": str(args.png), "runs": table}))


if __name__ == "__main__":
    main()

"""Steady intrusion slope K_phi of intrusion runs against the modified Archimedes law.

    python examples/intrusion/analyse.py OUT [OUT2 ...] (--phi DEG | --phi-from FILE)
        [--from D] [--to D] [--tol 0.002] [--min-span 0.4] [--png PATH] [--labels L ...]

Each OUT is the output folder of an intrusion run (validation case 3, seed section 4.3):
its history.csv must have the columns depth_over_R (d/R) and force_normalized
(p_u/(rho g R), p_u the resistance over the projected area of the quarter-model
intruder); rows before the intrusion starts (time < 0, the geostatic stage) are left
out. The label of a run is its folder name and, from case.resolved.toml, the intruder's
[rigid] shape (`--labels` gives one label a run instead).

For each run, the steady regime p_u/(rho g R) = K_phi d/R + p_0 is fitted by least
squares over d/R in [s, d_max], d_max the deepest row (or the deepest at d/R <= --to:
runs that went to different depths compared over the same span). The window start s is,
by default, the smallest of 0, 0.05, 0.10, ... (in units of R) whose window passes the
linearity test below (where it holds at least 4 ripple periods) and a slope-stability
rule: moving the start 0.1 R and 0.2 R deeper changes the fitted slope K(s) by less
than

    max(tol K(s), 2 sqrt(sigma^2 (1/Sxx' - 1/Sxx)))

for both moves, Sxx and Sxx' the sums of squared d/R deviations of the two windows and
sigma^2 the residual variance of the shorter one. The second term is twice the standard
deviation of the difference of two nested least-squares slopes when the data are a line
plus independent scatter (the longer window's slope is the efficient one, so the variance
of the difference is that of the shorter window's slope less that of the longer's); tol
(--tol, default 0.2 %) only matters for nearly scatter-free curves, and 0.2 % of K_phi is
about 0.014 deg of friction angle near 27 deg (K_phi grows 14.5 % a degree there), far
below any comparison with the law.
Windows keep at least --min-span (default 0.4 R: more than one and a half of the
one-cell ripples of the reaction in the reduced case, 0.125 m cells and R = 0.5 m).
Rationale: the nonlinear start (the stagnant zone forming, seed Fig. 13 and 15) bends the
force-depth curve, so while part of it is inside the window the slope moves as the start
moves; once the window holds the linear regime alone, moving the start changes the slope
by no more than the scatter explains. On synthetic curves (a quadratic or exponential
approach to a line of slope 26 by d/R ~ 0.3, 43 rows to d/R = 1.05, white scatter or a
one-cell ripple) the rule starts at d/R 0.15-0.3 and the slope is within 0.5-2 % of the
truth, its bias below 1.4 standard errors on average. When no start qualifies, the
shortest window (from d_max - min_span) is used and the rule is reported as "fallback".
--from D fixes s = D instead ("fixed").

The standard errors are ordinary least squares ones (independent residuals assumed); the
reaction's ripple with depth is correlated, so read them as lower bounds.

Is it a line, and how well is its slope known? (`linearity`.) The no-slip reaction
ripples with the grid: the set of driven nodes changes each time the base crosses a node
layer, a period P of one cell along the motion over R (from case.resolved.toml and the
history; 0.25 where they do not give it). Over evenly spaced rows a whole period of a
periodic ripple averages out, so the window is cut into whole periods and their means
are the data of three measures:
- the local slope between consecutive periods (`local_slopes`): the slope against depth
  with the ripple averaged out;
- the linearity test: a quadratic through the period means; the window is `linear` when
  its curvature's |t| = |c / se(c)| is within Student's 95 % quantile (m - 3 dof, m
  periods; no test below 4 periods), and `slope_change` = 2 c x span says how much the
  local slope changes over the window;
- the slope's uncertainty with the model error, `K_phi_u` = sqrt(se_b^2 + e_m^2): se_b the
  standard error of the period means' slope (m - 2 dof: the means of distinct periods are
  close to independent, which the rows are not) and e_m half the difference between the
  slopes of the first and the last half of the periods, how much the slope depends on
  where along the window it is measured (for y = a + b d + c d^2 it is c times the
  distance of the halves' centres), which a straight-line fit leaves out. A straight
  window's e_m is its scatter's; a curved one's is the curvature's.

Theory: K_theory = k_phi(phi) from grainscale.analysis (seed Eq. 27-29, Kang et
al. 2018, Eq. 29c without the printed inner R), phi the friction angle measured on the
RVE (--phi, or --phi-from a JSON file with {"phi_deg": ...}). Each fitted slope is also
turned into the angle it implies (phi_for_k). Where the JSON also gives the angle's 95 %
band ("phi_band95_deg", as friction_angle.py writes it), the summary adds K_theory at
its two ends (`K_theory_band95`): the range of the law that the measured angle allows.

The ripple of each run is the departure of its fitted rows from the fitted line, in %
of the fitted rows' mean (studies/intrusion/ripple.py's measure): printed as its rms and
range (`ripple_rms_pct`,
`ripple_range_pct`), the force ripple of seed Fig. 13's curves.

Writes a plot (--png, default OUT/intrusion.png of the first run): p_u/(rho g R) against
d/R for every run, each fit over its window, and the theory line K_theory d/R + p_0 (p_0
of the first run's fit). Prints a table; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tomllib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import grainscale as gs  # noqa: E402
from grainscale.analysis import k_phi, phi_for_k, t95  # noqa: E402

REQUIRED = ("depth_over_R", "force_normalized")
START_STEP = 0.05   # R: spacing of candidate window starts
START_SHIFTS = (0.1, 0.2)  # R: the start is moved this much deeper to test the slope
PERIOD_DEFAULT = 0.25  # d/R: the ripple's period where the case does not give it (one
#                        0.125 m cell over R = 0.5 m, the reduced cases)
MIN_BLOCKS = 4  # ripple periods a window needs for the linearity test (a quadratic: 1 dof)


class InputError(Exception):
    """A bad run folder or file: the message names it."""


def read_history(path: Path) -> dict[str, np.ndarray]:
    """The columns of a run's history.csv (gs.open_result(...).history: a last row cut
    short is dropped), its errors as InputError."""
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        return gs.open_result(path.parent).history
    except ValueError as err:
        raise InputError(str(err)) from None


def load_run(out: Path) -> dict:
    """d/R and p_u/(rho g R) of the intrusion stage of one run, and its label (the name of
    OUT; a study's folder holding the run in OUT/run, as baselines.py and mc_variants.py
    write them, is read there)."""
    name = out.resolve().name
    if not (out / "history.csv").is_file() and (out / "run" / "history.csv").is_file():
        out = out / "run"
    path = out / "history.csv"
    h = read_history(path)
    for col in REQUIRED:
        if col not in h:
            raise InputError(f"{path}: missing column '{col}' (columns: {', '.join(h)})")
    keep = np.isfinite(h["depth_over_R"]) & np.isfinite(h["force_normalized"])
    if "time" in h:
        keep &= h["time"] >= 0.0
    x, y = h["depth_over_R"][keep], h["force_normalized"][keep]
    if x.size < 4:
        raise InputError(f"{path}: {x.size} rows in the intrusion stage (time >= 0), need 4")
    shape, period = None, None
    case = out / "case.resolved.toml"
    if case.is_file():
        try:
            resolved = tomllib.loads(case.read_text())
        except tomllib.TOMLDecodeError as err:
            raise InputError(f"{case}: {err}") from None
        shape = resolved.get("rigid", {}).get("shape")
        period = ripple_period(resolved, h)
    return {"label": f"{name} ({shape})" if shape else name, "folder": str(out),
            "shape": shape, "x": x, "y": y,
            "period": period or PERIOD_DEFAULT,
            "period_source": "case" if period else "default"}


def ripple_period(resolved: dict, h: dict[str, np.ndarray]) -> float | None:
    """The no-slip ripple's period in d/R: the grid's cell along the intruder's motion
    (the set of driven nodes changes each time its base crosses a node layer; a graded
    axis: its fine cells, where the intruder is), over R (depth / depth_over_R of the
    history); None where the case or history does not give them."""
    grid, rigid = resolved.get("grid", {}), resolved.get("rigid", {})
    velocity = rigid.get("velocity")
    if velocity is None or "depth" not in h or sum(v != 0.0 for v in velocity) != 1:
        return None
    axis = "xyz"[next(i for i, v in enumerate(velocity) if v != 0.0)]
    cell = grid.get("cell_size") or grid.get(f"nodes_{axis}", {}).get("cell")
    deep = np.abs(h["depth_over_R"]) > 1e-9
    if not cell or not deep.any():
        return None
    radius = float(np.median(h["depth"][deep] / h["depth_over_R"][deep]))
    return float(cell) / radius


def linear_fit(x: np.ndarray, y: np.ndarray) -> dict[str, float]:
    """y = slope x + intercept by least squares, with OLS standard errors."""
    n = x.size
    xm, ym = x.mean(), y.mean()
    sxx = float(np.sum((x - xm) ** 2))
    slope = float(np.sum((x - xm) * (y - ym)) / sxx)
    intercept = float(ym - slope * xm)
    rss = float(np.sum((y - intercept - slope * x) ** 2))
    s2 = rss / (n - 2) if n > 2 else 0.0
    return {"slope": slope, "intercept": intercept, "slope_se": float(np.sqrt(s2 / sxx)),
            "intercept_se": float(np.sqrt(s2 * (1.0 / n + xm * xm / sxx))), "n": n,
            "sxx": sxx, "s2": s2}


def fit_window(x, y, start: float) -> dict[str, float]:
    sel = x >= start - 1e-12
    if np.count_nonzero(sel) < 3 or np.ptp(x[sel]) <= 0.0:
        raise InputError(f"fewer than 3 distinct rows at d/R >= {start:g}")
    return linear_fit(x[sel], y[sel])


def period_means(x, y, start: float, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Means of x and y over the whole ripple periods [start + k P, start + (k+1) P) of
    the rows from `start` on: over evenly spaced rows a whole period of a periodic ripple
    averages out, and the means of distinct periods are close to independent."""
    xb, yb = [], []
    # a period is whole when its rows reach to within half a row spacing of its end
    half_row = 0.5 * float(np.median(np.diff(x))) if x.size > 1 else 0.0
    for k in range(int(math.floor((x.max() + half_row - start) / period + 1e-9))):
        sel = (x >= start + k * period - 1e-12) & (x < start + (k + 1) * period - 1e-12)
        if np.count_nonzero(sel) >= 2:
            xb.append(x[sel].mean())
            yb.append(y[sel].mean())
    return np.array(xb), np.array(yb)


def quadratic_fit(x: np.ndarray, y: np.ndarray) -> dict[str, float]:
    """y = a + b x + c x^2 by least squares: c and its OLS standard error (n - 3 dof)."""
    xm = x.mean()
    design = np.stack([np.ones_like(x), x - xm, (x - xm) ** 2], axis=1)
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    rss = float(np.sum((y - design @ coef) ** 2))
    dof = x.size - 3
    cov = rss / dof * np.linalg.inv(design.T @ design) if dof > 0 else np.full((3, 3), np.inf)
    return {"c": float(coef[2]), "c_se": float(np.sqrt(cov[2, 2])), "dof": dof}


def linearity(x, y, start: float, period: float) -> dict:
    """Whether the rows from `start` on are a straight line, and how well its slope is
    known, from the means over whole ripple periods (period_means; m of them):
    - `local_slopes`: [(d/R, slope)] between consecutive periods: the slope against
      depth with the ripple averaged out;
    - the curvature c of a quadratic through the period means and its t = c / se(c)
      (m - 3 dof): `linear` when |t| <= t95(m - 3) (None with fewer than MIN_BLOCKS
      periods: no test), and `slope_change`, 2 c times the window's span: how much the
      local slope changes over the window by that curvature;
    - the slope of the period means (`K_blocks`) with its standard error (m - 2 dof; the
      rows' own standard error treats the correlated ripple as independent scatter);
    - `model_error`: half the difference between the slopes of the first and the last
      max(2, m // 2) periods: how much the slope depends on where along the window it
      is measured, which a straight-line fit leaves out;
    - `K_phi_u`: sqrt(se_blocks^2 + model_error^2), the slope's uncertainty with both."""
    xb, yb = period_means(x, y, start, period)
    m = xb.size
    out = {"period": period, "periods": int(m), "linear": None,
           "local_slopes": [[float((xb[i] + xb[i + 1]) / 2), float((yb[i + 1] - yb[i])
                                                                   / (xb[i + 1] - xb[i]))]
                            for i in range(m - 1)]}
    if m >= 3:
        b = linear_fit(xb, yb)
        h = max(2, m // 2)
        early, late = linear_fit(xb[:h], yb[:h]), linear_fit(xb[-h:], yb[-h:])
        out.update(K_blocks=b["slope"], K_blocks_se=b["slope_se"],
                   model_error=abs(late["slope"] - early["slope"]) / 2.0)
        out["K_phi_u"] = float(math.hypot(b["slope_se"], out["model_error"]))
    if m >= MIN_BLOCKS:
        q = quadratic_fit(xb, yb)
        t = q["c"] / q["c_se"] if q["c_se"] > 0 else (0.0 if q["c"] == 0 else math.inf)
        out.update(curvature=q["c"], curvature_se=q["c_se"], curvature_t=float(t),
                   curvature_t95=t95(q["dof"]), linear=bool(abs(t) <= t95(q["dof"])),
                   slope_change=float(2.0 * q["c"] * (xb[-1] - xb[0])))
    return out


def choose_start(x, y, tol: float, min_span: float, period: float = PERIOD_DEFAULT
                 ) -> tuple[float, str]:
    """The window start (module docstring): the first candidate whose window passes the
    slope-stability rule and, where it holds MIN_BLOCKS ripple periods, the linearity
    test; (start, 'auto' or 'fallback')."""
    d_max = float(x.max())
    last = d_max - min_span
    if last < 0.0:
        raise InputError(f"the run reaches d/R = {d_max:.3g}, less than --min-span "
                         f"{min_span:g}")
    k = 0
    while (s := k * START_STEP) + max(START_SHIFTS) <= last + 1e-9:
        k += 1
        a = fit_window(x, y, s)
        for shift in START_SHIFTS:
            b = fit_window(x, y, s + shift)
            spread = 2.0 * np.sqrt(max(b["s2"] * (1.0 / b["sxx"] - 1.0 / a["sxx"]), 0.0))
            if abs(b["slope"] - a["slope"]) >= max(tol * abs(a["slope"]), spread):
                break
        else:
            if linearity(x, y, s, period)["linear"] is not False:
                return s, "auto"
    return last, "fallback"


def analyse(outs: list[Path], phi_deg: float, start: float | None = None,
            tol: float = 0.002, min_span: float = 0.4, png: Path | None = None,
            phi_band: float | None = None, stop: float | None = None,
            labels: list[str] | None = None) -> dict:
    if stop is not None and start is not None and start >= stop:
        raise InputError(f"--from {start:g} and --to {stop:g}: valid --from < --to")
    if labels is not None and len(labels) != len(outs):
        raise InputError(f"--labels: {len(labels)} given for {len(outs)} runs; give one "
                         "a run")
    runs = [load_run(o) for o in outs]
    for r, label in zip(runs, labels or [], strict=False):
        r["label"] = label
    if stop is not None:  # the rows beyond --to left out, before the rule and the fit
        for r in runs:
            keep = r["x"] <= stop + 1e-12
            if np.count_nonzero(keep) < 4:
                raise InputError(f"{r['folder']}: {np.count_nonzero(keep)} rows at d/R <= "
                                 f"--to {stop:g}, need 4")
            r["x"], r["y"] = r["x"][keep], r["y"][keep]
    k_theory = k_phi(phi_deg)
    results = []
    for r in runs:
        try:
            s, rule = (start, "fixed") if start is not None else \
                choose_start(r["x"], r["y"], tol, min_span, r["period"])
            f = fit_window(r["x"], r["y"], s)
            lin = linearity(r["x"], r["y"], s, r["period"])
        except InputError as err:
            raise InputError(f"{r['folder']}: {err}") from None
        # the ripple: each fitted row's departure from the line, in % of the rows' mean
        # (ripple.py's measure; the line's own value vanishes near d/R 0)
        sel = r["x"] >= s - 1e-12
        line = f["slope"] * r["x"][sel] + f["intercept"]
        dev = 100.0 * (r["y"][sel] - line) / np.mean(r["y"][sel])
        try:
            implied = phi_for_k(f["slope"])
        except ValueError:
            implied = None  # a slope below 1 or beyond k_phi(60 deg)
        results.append({
            "label": r["label"], "folder": r["folder"], "shape": r["shape"],
            "K_phi": f["slope"], "K_phi_stderr": f["slope_se"], "p_0": f["intercept"],
            "p_0_stderr": f["intercept_se"], "window": [float(s), float(r["x"].max())],
            "window_rule": rule, "rows_fitted": f["n"],
            "ripple_rms_pct": float(np.sqrt(np.mean(dev ** 2))),
            "ripple_range_pct": [float(dev.min()), float(dev.max())],
            "depth_over_R_max": float(r["x"].max()), "phi_implied_deg": implied,
            "period_source": r["period_source"], **lin})
    first = results[0]
    summary = {"K_phi": first["K_phi"], "K_phi_stderr": first["K_phi_stderr"],
               "p_0": first["p_0"], "phi_deg": phi_deg, "K_theory": k_theory,
               "K_phi_over_theory": first["K_phi"] / k_theory,
               "phi_implied_deg": first["phi_implied_deg"],
               "depth_over_R_max": first["depth_over_R_max"], "window": first["window"],
               "runs": results}
    if phi_band is not None and math.isfinite(phi_band):
        # the law is steep in phi: the angle's own uncertainty spans this range of K
        summary["phi_band95_deg"] = phi_band
        summary["K_theory_band95"] = [k_phi(phi_deg - phi_band), k_phi(phi_deg + phi_band)]
    if len(results) >= 2:
        summary["slope_ratio"] = results[1]["K_phi"] / first["K_phi"]
    png = png if png is not None else outs[0] / "intrusion.png"
    plot(runs, results, k_theory, phi_deg, png)
    summary["png"] = str(png)
    return summary


def plot(runs, results, k_theory, phi_deg, png: Path) -> None:
    fig, ax = plt.subplots(figsize=(6.0, 4.5))
    for r, f, c in zip(runs, results, plt.cm.tab10.colors, strict=False):
        ax.plot(r["x"], r["y"], ".", ms=4, color=c, label=r["label"])
        lo, hi = f["window"]
        xs = np.array([lo, hi])
        ax.plot(xs, f["K_phi"] * xs + f["p_0"], "-", color=c, lw=1.5,
                label=f"fit d/R in [{lo:.2f}, {hi:.2f}]: K = {f['K_phi']:.2f}")
    x_max = max(float(r["x"].max()) for r in runs)
    xs = np.array([0.0, x_max])
    ax.plot(xs, k_theory * xs + results[0]["p_0"], "k--", lw=1,
            label=f"Kang et al. 2018, phi = {phi_deg:g} deg: K = {k_theory:.1f}")
    ax.set_xlabel("d / R")
    ax.set_ylabel("p_u / (rho g R)")
    ax.set_xlim(left=0.0)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=120)
    plt.close(fig)


def table(summary: dict) -> str:
    lines = [f"{'run':<28} {'window d/R':>13} {'rows':>4} {'K_phi +- se':>17} "
             f"{'p_0 +- se':>16} {'phi(K) deg':>11} {'d/R max':>8} "
             f"{'ripple % rms (range)':>22}"]
    for r in summary["runs"]:
        phi = "-" if r["phi_implied_deg"] is None else f"{r['phi_implied_deg']:.2f}"
        win = f"{r['window'][0]:.2f}-{r['window'][1]:.2f}"
        if r["window_rule"] == "fallback":
            win += "!"
        lines.append(f"{r['label']:<28} {win:>13} {r['rows_fitted']:>4} "
                     f"{r['K_phi']:>10.3f} +- {r['K_phi_stderr']:<5.3f}"
                     f"{r['p_0']:>9.3f} +- {r['p_0_stderr']:<5.3f}{phi:>11} "
                     f"{r['depth_over_R_max']:>8.3f} {r['ripple_rms_pct']:>8.1f} "
                     f"({r['ripple_range_pct'][0]:+.0f} to {r['ripple_range_pct'][1]:+.0f})")
    lines.append(f"modified Archimedes law at phi = {summary['phi_deg']:g} deg: "
                 f"K_theory = {summary['K_theory']:.3f} (first run / theory = "
                 f"{summary['K_phi_over_theory']:.3f})")
    if "K_theory_band95" in summary:
        lo, hi = summary["K_theory_band95"]
        lines.append(f"  phi's 95 % band +-{summary['phi_band95_deg']:g} deg: K_theory "
                     f"{lo:.3f} to {hi:.3f}")
    if "slope_ratio" in summary:
        lines.append(f"slope ratio (second / first run): {summary['slope_ratio']:.4f}")
    if any(r["window_rule"] == "fallback" for r in summary["runs"]):
        lines.append("!: no window start met the slope-stability rule; the shortest "
                     "window was used")
    return "\n".join(lines)


def read_phi(path: Path) -> tuple[float, float | None]:
    """phi_deg and, where the file gives it, phi_band95_deg (friction_angle.py's JSON)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise InputError(f"{path}: {err}") from None
    if not isinstance(data, dict) or "phi_deg" not in data:
        raise InputError(f"{path}: missing key 'phi_deg'")
    band = data.get("phi_band95_deg")
    return float(data["phi_deg"]), (None if band is None else float(band))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outs", type=Path, nargs="+", metavar="OUT", help="run folders")
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--phi", type=float, help="friction angle of the RVE, degrees")
    src.add_argument("--phi-from", type=Path, help='JSON file with {"phi_deg": ...}')
    ap.add_argument("--from", dest="start", type=float, default=None,
                    help="fix the window start d/R (default: the slope-stability rule)")
    ap.add_argument("--to", dest="stop", type=float, default=None,
                    help="leave out the rows deeper than this d/R (default: none)")
    ap.add_argument("--tol", type=float, default=0.002,
                    help="relative slope change the rule always accepts (default 0.002)")
    ap.add_argument("--min-span", type=float, default=0.4,
                    help="shortest fitted window, in R (default 0.4)")
    ap.add_argument("--png", type=Path, default=None, help="default OUT/intrusion.png")
    ap.add_argument("--labels", nargs="+", default=None,
                    help="one label a run for the table and plot (default: folder names)")
    args = ap.parse_args(argv)
    try:
        phi, band = (args.phi, None) if args.phi is not None else read_phi(args.phi_from)
        summary = analyse(args.outs, phi, args.start, args.tol, args.min_span, args.png,
                          band, args.stop, args.labels)
    except (InputError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(table(summary))
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())

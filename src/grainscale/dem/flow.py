"""The flow rule of an RVE: steady simple shear at constant normal stress, and its mu(I) fit.

An RVE sheared at a constant rate gdot with its normal stress held at P reaches, after a
shear strain of order one, a steady state whose time averages define the local rheology
of dense granular flow (GDR MiDi 2004, Eur. Phys. J. E 14:341; da Cruz et al. 2005,
Phys. Rev. E 72:021309):

    I  = gdot d sqrt(rho_s / P)                 inertial number [-]
    mu = tau / P                                effective friction [-]
    mu(I) = mu_s + (mu_2 - mu_s) / (I_0 / I + 1)     (Jop, Forterre & Pouliquen 2006)

Two measures are reported, because they differ in a DEM cell whose normal stresses are
not equal:

- the shear-cell measure, P = sigma_n (the servo-held normal stress on the shear plane,
  sigma_zz) and tau = tau_xz: `mu`, `I` (what experiments and DEM studies report);
- the invariant measure, P = p (mean stress) and tau = sqrt(s:s/2) = q/sqrt(3): `mu_p`,
  `I_p`.

The fitted `[materials.X]` table is the shear-cell fit. The `mu_i` material
(mpm/materials/mu_i.py) flows with a deviator coaxial with its strain rate, so in simple
shear its only deviator is s_xz: it carries tau_xz / sigma_n = sqrt(s:s/2) / p. The
grains carry normal-stress differences as well (sqrt(s:s/2)/p is 10-30 % above
tau/sigma_n, docs/validation.md §2.2), which resist no shearing on the shear plane; a
continuum given the invariant measure is that much too strong on its shear planes
(docs/validation.md §2.3, "Which friction the continuum takes").

Steady values are means over shear strain >= `steady_from`; their 95 % confidence band
is a batch-means estimate (the window split into BLOCKS consecutive blocks, Student t
with BLOCKS - 1 degrees of freedom), which accounts for the correlation of successive
samples as long as a block is longer than the correlation strain (~0.1 in dense flow).
d is the mean grain diameter of the RVE, rho_s its grain density.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from grainscale.config.rve import RVEParams, ShearTest
from grainscale.dem import element_tests
from grainscale.dem.retile import multiply_cell
from grainscale.dem.state import RVEBatch

SAMPLE_STRAIN = 0.01  # shear strain between samples [-]
BLOCKS = 8            # batch means for the confidence band
T_975 = 2.365         # Student t quantile 0.975 at BLOCKS - 1 = 7 degrees of freedom
MIN_WINDOW = 0.2      # shortest steady window [-]: BLOCKS blocks of >= 2.5 samples

COLUMNS = ("pressure_target", "shear_rate", "tiles", "particles", "I", "I_err", "mu",
           "mu_err", "I_p", "I_p_err", "mu_p", "mu_p_err", "porosity", "porosity_err",
           "sigma_n", "p", "coordination", "samples")
COLUMN_DOC = (
    "units SI (Pa, 1/s); one row per (pressure, rate); steady means over shear strain >= "
    "steady_from, *_err = half-width of their 95 % batch-means confidence band; "
    "I = shear_rate d sqrt(rho_s / sigma_n), mu = tau_xz / sigma_n (shear-cell measure); "
    "I_p = shear_rate d sqrt(rho_s / p), mu_p = sqrt(s:s/2) / p (the mu_i material's "
    "measure); sigma_n, p compression positive; d = mean grain diameter")


def mean_diameter(batch: RVEBatch) -> float:
    """Mean grain diameter d = 2 mean(r) of RVE 0 [m] (the d of the inertial number)."""
    return float(2.0 * batch.radius[0].mean())


def inertial_number(rate, d: float, rho_s: float, pressure):
    """I = gdot d sqrt(rho_s / P) [-] (rate 1/s, d m, rho_s kg/m^3, P Pa)."""
    return np.asarray(rate) * d * np.sqrt(rho_s / np.asarray(pressure))


def rate_for(inertial, d: float, rho_s: float, pressure: float):
    """The shear rate [1/s] that gives inertial number I at normal stress P."""
    return np.asarray(inertial) * math.sqrt(pressure / rho_s) / d


def tile(batch: RVEBatch, n: int, seed: int = 0) -> RVEBatch:
    """RVE 0 as an n x n x n supercell: the same grains n^3 times in a cell n h, every
    contact with its tangential history (retile.multiply_cell along each edge).

    The copies start identical, and exact periodicity would keep them so; positions are
    perturbed by 1e-6 of the smallest radius (a few % of the contacts' overlap at the
    pressures of a column, ~1e-4 of it at 100 kPa) so that shear chaos makes them
    independent within a strain of order one. n = 1 returns RVE 0 unchanged.
    """
    big = batch.take([0])
    if n == 1:
        return big
    for k in range(3):
        big = multiply_cell(big, 0, k, n)
    rng = np.random.default_rng(seed)
    if big.clumped:  # a clump moves whole: its centre and its members by one shift
        dx = 1e-6 * batch.radius[0].min() * rng.standard_normal(big.bs[0].shape)
        ds = np.linalg.solve(big.h[0], dx.T).T
        big.bs[0] += ds
        big.s[0] += ds[big.body[0]]
    else:
        dx = 1e-6 * batch.radius[0].min() * rng.standard_normal(big.s[0].shape)
        big.s[0] += np.linalg.solve(big.h[0], dx.T).T
        big.s[0] -= np.floor(big.s[0])
    big.s_ref[0] = big.s[0]
    return big


def steady_mean(x: np.ndarray) -> tuple[float, float]:
    """Mean of a correlated series and the half-width of its 95 % confidence band by
    batch means: BLOCKS consecutive blocks, T_975 std(block means) / sqrt(BLOCKS)."""
    x = np.asarray(x, float)
    if len(x) < 2 * BLOCKS:
        raise ValueError(f"{len(x)} samples: at least {2 * BLOCKS} needed for a band")
    means = np.array([b.mean() for b in np.array_split(x, BLOCKS)])
    return float(x.mean()), float(T_975 * means.std(ddof=1) / math.sqrt(BLOCKS))


def shear_test(pressure: float, rate: float, strain: float) -> ShearTest:
    """The simple-shear test of one (pressure [Pa], rate [1/s]) run to `strain`."""
    return ShearTest(normal_stress=pressure, shear_strain=strain, strain_rate=rate,
                     output_interval=SAMPLE_STRAIN)


def steady_shear(batch: RVEBatch, params: RVEParams, pressure: float, rate: float,
                 strain: float, steady_from: float,
                 on_row: Callable[[dict], None] | None = None) -> tuple[dict, dict]:
    """Simple shear of RVE 0 of `batch` (left unchanged) at `rate` [1/s] with sigma_zz
    held at -pressure [Pa], to `strain`; returns (steady values as a COLUMNS row, the
    sampled series {column: array}). mu is the Cauchy sigma_xz over sigma_n, positive for
    a positive rate (the report's tau_xz is compression-positive, hence negative here)."""
    test = shear_test(pressure, rate, strain)
    rows = element_tests.simple_shear(batch.take([0]), params, test, on_row=on_row)
    series = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    d, rho = mean_diameter(batch), params.density
    sel = series["shear_strain"] >= steady_from - 1e-9
    sig_n = series["sigma_zz"][sel]
    p = series["p"][sel]
    per_sample = {
        "I": inertial_number(rate, d, rho, sig_n), "mu": -series["tau_xz"][sel] / sig_n,
        "I_p": inertial_number(rate, d, rho, p), "mu_p": series["q"][sel] / (math.sqrt(3) * p),
        "porosity": series["porosity"][sel],
    }
    row = {"pressure_target": pressure, "shear_rate": rate, "particles": batch.n_particles}
    for key, x in per_sample.items():
        row[key], row[f"{key}_err"] = steady_mean(x)
    row.update(sigma_n=float(sig_n.mean()), p=float(p.mean()),
               coordination=float(series["coordination"][sel].mean()),
               samples=int(sel.sum()))
    return row, series


def _linear_fit(I, mu, w, I_0):
    """Weighted least squares of mu = mu_s + (mu_2 - mu_s) x, x = I / (I_0 + I), at a
    fixed I_0, under 0 <= mu_s <= mu_2 (friction rises with rate): returns (mu_s, mu_2,
    weighted residual sum of squares). The problem has two unknowns, so the constrained
    optimum is the unconstrained one or lies on one of the two constraint lines."""
    x = I / (I_0 + I)

    def rss(mu_s, mu_2):
        r = (mu_s + (mu_2 - mu_s) * x - mu) * w
        return float(r @ r)

    a = np.stack([1.0 - x, x], axis=1) * w[:, None]
    (mu_s, mu_2), *_ = np.linalg.lstsq(a, mu * w, rcond=None)
    if 0.0 <= mu_s <= mu_2:
        return float(mu_s), float(mu_2), rss(mu_s, mu_2)
    flat = float(np.sum(w**2 * mu) / np.sum(w**2))  # mu_s = mu_2: no rate dependence
    best = (flat, flat, rss(flat, flat))
    zero = float(np.sum(w**2 * x * mu) / max(np.sum(w**2 * x * x), 1e-300))  # mu_s = 0
    if zero >= 0.0 and rss(0.0, zero) < best[2]:
        best = (0.0, zero, rss(0.0, zero))
    return best


def fit_mu_i(I, mu, err=None) -> dict:
    """Fit mu(I) = mu_s + (mu_2 - mu_s)/(I_0/I + 1) to steady points (weights 1/err).

    The model is linear in (mu_s, mu_2) at a fixed I_0, so those are solved exactly (with
    0 <= mu_s <= mu_2) and I_0 alone is searched: a scan of log I_0 over two decades
    either side of the measured I, then golden-section refinement. Returns mu_s, mu_2,
    I_0, rms (weighted residual: in units of the bands when err is given), their
    standard errors mu_s_err, mu_2_err and ln_I_0_err (of ln I_0; from the scatter about
    the fit, NaN when a parameter is on a bound) and `warning`,
    empty unless a parameter sits on a bound (I_0 at the end of the scan, mu_s = 0 or
    mu_s = mu_2) or I_0 exceeds the largest measured I: the data then do not bracket the
    law's knee and its parameters are not separately determined (measure over a wider
    range of I)."""
    I, mu = np.asarray(I, float), np.asarray(mu, float)
    if len(np.unique(I)) < 3:
        raise ValueError(f"{len(np.unique(I))} distinct inertial numbers: the mu(I) law "
                         "has 3 parameters, measure at >= 3 rates")
    w = np.ones_like(I) if err is None else 1.0 / np.maximum(np.asarray(err, float), 1e-12)
    lo, hi = np.log(I.min() / 100), np.log(I.max() * 100)
    grid = np.linspace(lo, hi, 241)
    rss = [_linear_fit(I, mu, w, math.exp(g))[2] for g in grid]
    k = int(np.argmin(rss))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    phi = (math.sqrt(5) - 1) / 2
    for _ in range(60):
        c, e = b - phi * (b - a), a + phi * (b - a)
        if _linear_fit(I, mu, w, math.exp(c))[2] < _linear_fit(I, mu, w, math.exp(e))[2]:
            b = e
        else:
            a = c
    I_0 = math.exp(0.5 * (a + b))
    mu_s, mu_2, r = _linear_fit(I, mu, w, I_0)
    warning = ("I_0 at the end of its scan" if k in (0, len(grid) - 1) else
               "mu_s at its bound 0" if mu_s == 0.0 else
               "no rate dependence (mu_s = mu_2)" if mu_s == mu_2 else
               f"I_0 = {I_0:.3g} above the largest measured I: mu_2 is an extrapolation"
               if I_0 > I.max() else "")
    if warning:  # no linearisation on a bound
        warning += "; the law is not determined by these points: widen the range of I"
        errors = dict.fromkeys(_ERRORS, math.nan)
    else:
        errors = _standard_errors(I, w, mu_s, mu_2, I_0, r)
    return {"mu_s": mu_s, "mu_2": mu_2, "I_0": I_0, "rms": math.sqrt(r / len(I)),
            "warning": warning, **errors}


_ERRORS = ("mu_s_err", "mu_2_err", "ln_I_0_err")


def _standard_errors(I, w, mu_s, mu_2, I_0, rss) -> dict:
    """Standard errors of mu_s, mu_2 and ln I_0 from the linearised least squares:
    cov = s^2 (J^T W^2 J)^-1, s^2 = rss / (n - 3) the weighted residual variance (so the
    weights need only be relative), J the model's derivatives at the optimum:
    d mu/d mu_s = 1 - x, d mu/d mu_2 = x, d mu/d ln I_0 = -(mu_2 - mu_s) x (1 - x), with
    x = I / (I_0 + I). NaN with no residual degree of freedom or a singular J."""
    nan = dict.fromkeys(_ERRORS, math.nan)
    if len(I) <= 3:
        return nan
    x = I / (I_0 + I)
    jac = np.stack([1.0 - x, x, -(mu_2 - mu_s) * x * (1.0 - x)], axis=1) * w[:, None]
    normal = jac.T @ jac
    if np.linalg.cond(normal) > 1e12:
        return nan
    se = np.sqrt(np.diag(np.linalg.inv(normal)) * rss / (len(I) - 3))
    return dict(zip(_ERRORS, map(float, se), strict=True))


def mu_i_table(name: str, fit: dict, params: RVEParams, d: float, porosity: float,
               young: float, source: str) -> str:
    """A `[materials.NAME] type = "mu_i"` table for a case file (mpm/materials/mu_i.py).

    density is the bulk density (1 - porosity) rho_s at the lowest measured rate;
    youngs_modulus is the caller's estimate (it only sets the elastic predictor and the
    MPM time step of a flowing continuum)."""
    bound = f"; {fit['warning']}" if fit["warning"] else ""
    rho = (1.0 - porosity) * params.density
    return "\n".join([
        f"# mu(I) of the RVE of {source}, fitted by `grainscale rve flow`",
        "# (shear-cell measure: tau_xz / sigma_n against I of sigma_n; rms residual "
        f"{fit['rms']:.3g} bands{bound})",
        f"# standard errors: mu_s {fit['mu_s_err']:.2g}, mu_2 {fit['mu_2_err']:.2g}, "
        f"ln I_0 {fit['ln_I_0_err']:.2g}",
        f"[materials.{name}]",
        'type = "mu_i"',
        f"density = {rho:.6g}        # kg/m3: (1 - {porosity:.4f}) x rho_s",
        f"youngs_modulus = {young:.4g}",
        "poisson_ratio = 0.3",
        f"mu_s = {fit['mu_s']:.4f}",
        f"mu_2 = {fit['mu_2']:.4f}",
        f"I_0 = {fit['I_0']:.4g}",
        f"grain_diameter = {d:.6g}      # m: mean diameter of the RVE's grains",
        f"grain_density = {params.density:.6g}",
        "",
    ])

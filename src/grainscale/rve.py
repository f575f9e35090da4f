"""The RVE alone from Python: what `grainscale rve generate|triaxial|undrained|isotropic|
shear|flow` do (docs/api.md, docs/dem.md), returning the packing and the curves as
arrays. The command line calls these functions and writes what they return.

    from grainscale import rve
    params = rve.load("examples/rve/unit_element.toml")     # [rve] and test tables
    packing = rve.generate(params)
    curve = rve.triaxial(params, packing)
    curve["axial_strain"], curve["q_over_p"]
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from grainscale.config.base import ConfigError
from grainscale.config.case import Case, load_rve_case
from grainscale.config.rve import RVECase, check_particles
from grainscale.dem import element_tests, engine
from grainscale.dem.generate import contact_params
from grainscale.dem.generate import generate as _generate
from grainscale.dem.state import RVEBatch, concatenate, member_positions
from grainscale.io.packing import load_packing, write_packing
from grainscale.io.progress import Progress
from grainscale.io.rve_h5 import write_rve_state

Curve = dict[str, np.ndarray]


def load(path: str | Path) -> RVECase:
    """The [rve] table and the element-test tables of a file.

    The element-test tables are [triaxial], [undrained], [isotropic] and [shear]; the
    file is an RVE parameter file or a multiscale case file (docs/case-files.md), whose
    other tables are validated as a case too.

    Parameters
    ----------
    path : str or pathlib.Path
        The TOML file.

    Returns
    -------
    RVECase
        The validated [rve] table and those test tables the file has.

    Raises
    ------
    ConfigError
        Naming a bad key, its value and the valid range (or a missing or non-TOML file).

    Examples
    --------
    >>> from grainscale import rve
    >>> params = rve.load("examples/rve/unit_element.toml")
    >>> params.triaxial.confining_pressure
    """
    return load_rve_case(path)


def generate(params: RVECase | Case | str | Path, *, seed: int | None = None,
             path: str | Path | None = None,
             progress: bool | Callable[[str], None] = True) -> RVEBatch:
    """A consolidated packing as [rve] asks (docs/dem.md: generation), ready to load.

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
    seed : int, optional
        The generator's seed (default rve.seed; a multiscale run's packing k has seed
        rve.seed + k).
    path : str or pathlib.Path, optional
        A .h5 file that caches the packing: read back if it holds the packing of this
        very recipe and seed, else generated and written there.
    progress : bool or callable, default True
        A status line on stderr after each compaction stage (True), none (False), or
        each line given to a callable ``progress(line)``.

    Returns
    -------
    RVEBatch
        A batch of one RVE, its contact state refreshed.

    Raises
    ------
    ConfigError
        If `path` does not end in .h5, or as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.

    Examples
    --------
    >>> from grainscale import rve
    >>> params = rve.load("examples/rve/unit_element.toml")
    >>> start = rve.generate(params, progress=False)
    >>> start.porosity()
    >>> cached = rve.generate(params, seed=3, path="packing_3.h5")
    """
    case = _case(params)
    rve = case.rve if seed is None else case.rve.model_copy(update={"seed": int(seed)})
    check_particles(rve)  # before any generation
    if path is not None:
        from grainscale.coupling.materials import cached_packing

        if Path(path).suffix != ".h5":
            raise ConfigError(f"path = {str(path)!r}: a packing cache must end in .h5")
        batch = cached_packing(rve.model_copy(update={"seed": case.rve.seed}),
                               rve.seed - case.rve.seed, Path(path), progress=bool(progress))
    else:
        if progress is True:
            def say(text: str) -> None:
                print(f"generate: {text}", file=sys.stderr)
        else:
            say = progress or None
        batch = _generate(rve, progress=say)
    engine.refresh(batch, contact_params(rve))
    return batch


def packing(params: RVECase | Case | str | Path,
            path: str | Path | Sequence[str | Path]) -> RVEBatch:
    """A packing file with the contact law of `params`: the start of a test instead of
    generate().

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
    path : str or pathlib.Path or sequence of them
        A packing file (.txt exchange format or .h5 state). A list of files gives one
        batch of as many RVEs, tested together (``per_rve``).

    Returns
    -------
    RVEBatch
        The packing(s), contact state refreshed.

    Raises
    ------
    ConfigError
        If a file does not exist, or as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.
    """
    case = _case(params)
    paths = [path] if isinstance(path, (str, Path)) else list(path)
    for p in paths:
        if not Path(p).is_file():
            raise ConfigError(f"packing = {str(p)!r}: file does not exist")
    batch = concatenate([load_packing(Path(p), case.rve) for p in paths])
    engine.refresh(batch, contact_params(case.rve))
    return batch


def timestep(params: RVECase | Case | str | Path, batch: RVEBatch) -> float:
    """The DEM step [s] of the tests here and of a quasi-static coupled run's RVEs:
    dt = safety sqrt(m_min / (E r_max)) over the batch's spheres ([rve.numerics]
    timestep_safety, E the grains' Young's modulus). A test's strain per DEM step is its
    rate times dt, comparable with a coupled run's `strain_per_substep`.

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables, as for `packing`.
    batch : RVEBatch
        The packing(s) (`generate`, `packing`).

    Returns
    -------
    float
        The step [s].
    """
    return element_tests.timestep(batch, _case(params).rve)


def save(params: RVECase | Case | str | Path, batch: RVEBatch, path: str | Path) -> Path:
    """Write RVE 0 of `batch` as `grainscale rve generate --out` does.

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
        Its [rve] table is the recipe written into a .h5 file.
    batch : RVEBatch
        The packing; only its RVE 0 is written.
    path : str or pathlib.Path
        The file: .h5 (the full state and the [rve] recipe, what a case's `packings` and
        packing() read back exactly) or .txt (the exchange format: cell, centres, radii).

    Returns
    -------
    pathlib.Path
        `path`.

    Raises
    ------
    ConfigError
        If `path` ends in neither .h5 nor .txt, or as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.
    """
    case = _case(params)
    path = Path(path)
    if path.suffix == ".h5":
        write_rve_state(path, batch.take([0]), case.rve.recipe())
    elif path.suffix == ".txt" and batch.clumped:
        write_packing(path, batch.h[0], member_positions(batch), batch.radius[0],
                      bodies=batch.body[0])
    elif path.suffix == ".txt":
        write_packing(path, batch.h[0], batch.s[0] @ batch.h[0].T, batch.radius[0])
    else:
        raise ConfigError(f"path = {str(path)!r}: must end in .h5 or .txt")
    return path


def triaxial(params: RVECase | Case | str | Path, start: RVEBatch | None = None,
             on_row: Callable[[dict], None] | None = None, *, progress: bool = True,
             per_rve: bool = False) -> Curve | list[Curve]:
    """Drained triaxial compression of `start` ([triaxial]).

    The lateral stresses are servo-held at the confining pressure [Pa] and the axis is
    compressed at the strain rate [1/s].

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
    start : RVEBatch, optional
        The packing to test, copied first (default: a packing generated from [rve]).
    on_row : callable, optional
        ``on_row(row)`` is called with each output row (a dict) as it is computed.
    progress : bool, default True
        Show progress on stderr.
    per_rve : bool, default False
        For a start of several RVEs (packing() of several files): one curve per RVE,
        all tested together; else the curve of RVE 0.

    Returns
    -------
    Curve or list of Curve
        The curve as arrays, one per column of the CLI's CSV (docs/dem.md:
        axial_strain, p, q, q_over_p, volumetric_strain, porosity, ...); a list of
        curves, one per RVE, with `per_rve`.

    Raises
    ------
    ConfigError
        If the parameters have no [triaxial] table, or as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.

    Examples
    --------
    >>> from grainscale import rve
    >>> params = rve.load("examples/rve/unit_element.toml")
    >>> start = rve.generate(params)
    >>> curve = rve.triaxial(params, start)
    >>> curve["axial_strain"], curve["q_over_p"].max()
    """
    case = _case(params)
    return _test("triaxial", element_tests.triaxial, case, case.triaxial, start, on_row,
                 progress, per_rve)


def triaxial_ensemble(params: RVECase | Case | str | Path, start: RVEBatch | None = None,
                      *, replicas: int = 8, seed: int = 0, progress: bool = True) -> Curve:
    """Mean drained triaxial curve over `replicas` copies of `start`.

    The copies' grain velocities differ by ~1e-9 [m/s]: chaos makes each a different
    realisation of the same RVE, as the RVEs of a multiscale run's points become, so
    this is the like-for-like reference of a multiscale curve (docs/validation.md §1).

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
    start : RVEBatch, optional
        The packing to copy (default: generated from [rve]).
    replicas : int, default 8
        Number of copies, at least 2.
    seed : int, default 0
        Seed of the velocity perturbations.
    progress : bool, default True
        Show progress on stderr.

    Returns
    -------
    Curve
        Every column of `triaxial`'s curve as the mean over the copies, plus
        `q_over_p_sem` and `volumetric_strain_sem`: the standard errors of those means,
        std / sqrt(replicas), the realisation noise left in them.

    Raises
    ------
    ConfigError
        If `replicas` < 2 (a spread needs two), the parameters have no [triaxial] table,
        or as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.
    """
    case = _case(params)
    if replicas < 2:
        raise ConfigError(f"replicas = {replicas}: valid >= 2 (a spread needs two)")
    start = start if start is not None else generate(case, progress=progress)
    rng = np.random.default_rng(seed)
    copies = []
    for _ in range(replicas):
        b = start.copy()
        b.v += rng.normal(0.0, 1e-9, b.v.shape)
        copies.append(b)
    curves = triaxial(case, concatenate(copies), progress=progress, per_rve=True)
    out = {k: np.mean([c[k] for c in curves], axis=0) for k in curves[0]}
    for k in ("q_over_p", "volumetric_strain"):
        out[f"{k}_sem"] = np.std([c[k] for c in curves], axis=0, ddof=1) / np.sqrt(replicas)
    return out


def undrained(params: RVECase | Case | str | Path, start: RVEBatch | None = None,
              on_row: Callable[[dict], None] | None = None, *,
              progress: bool = True) -> Curve:
    """Constant-volume compression of `start` ([undrained]).

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
    start : RVEBatch, optional
        The packing to test, copied first (default: a packing generated from [rve]).
    on_row : callable, optional
        ``on_row(row)`` is called with each output row (a dict) as it is computed.
    progress : bool, default True
        Show progress on stderr.

    Returns
    -------
    Curve
        The curve of RVE 0 as arrays, one per column of the CLI's CSV (docs/dem.md).

    Raises
    ------
    ConfigError
        If the parameters have no [undrained] table, or as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.
    """
    case = _case(params)
    return _test("undrained", element_tests.undrained, case, case.undrained, start, on_row,
                 progress)


def isotropic(params: RVECase | Case | str | Path, start: RVEBatch | None = None,
              on_row: Callable[[dict], None] | None = None, *,
              progress: bool = True) -> Curve:
    """Isotropic compression of `start` to [isotropic] pressure_final [Pa].

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
    start : RVEBatch, optional
        The packing to test, copied first (default: a packing generated from [rve]).
    on_row : callable, optional
        ``on_row(row)`` is called with each output row (a dict) as it is computed.
    progress : bool, default True
        Show progress on stderr.

    Returns
    -------
    Curve
        The curve of RVE 0 as arrays, one per column of the CLI's CSV (docs/dem.md).

    Raises
    ------
    ConfigError
        If the parameters have no [isotropic] table, or as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.
    """
    case = _case(params)
    return _test("isotropic", element_tests.isotropic, case, case.isotropic, start, on_row,
                 progress)


def shear(params: RVECase | Case | str | Path, start: RVEBatch | None = None,
          on_row: Callable[[dict], None] | None = None, *, progress: bool = True) -> Curve:
    """Simple shear of `start` in x-z at constant normal stress ([shear]).

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
    start : RVEBatch, optional
        The packing to test, copied first (default: a packing generated from [rve]).
    on_row : callable, optional
        ``on_row(row)`` is called with each output row (a dict) as it is computed.
    progress : bool, default True
        Show progress on stderr.

    Returns
    -------
    Curve
        The curve of RVE 0 as arrays, one per column of the CLI's CSV (docs/dem.md).

    Raises
    ------
    ConfigError
        If the parameters have no [shear] table, or as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.
    """
    case = _case(params)
    return _test("shear", element_tests.simple_shear, case, case.shear, start, on_row,
                 progress)


def flow(params: RVECase | Case | str | Path, start: RVEBatch | None = None, *,
         inertial: Sequence[float] | None = None, rates: Sequence[float] | None = None,
         pressures: Sequence[float] | None = None, strain: float = 3.0,
         steady_from: float = 1.0, tiles: int = 1, allow_damping: bool = False,
         material: str = "rve_fit", on_point: Callable[[dict], None] | None = None,
         progress: bool = True, names: dict[str, str] | None = None,
         source: str | None = None) -> dict:
    """Steady simple shear of `start` at each pressure and rate; the mu(I) law fitted.

    The packing is tiled tiles x tiles x tiles, sheared to `strain` at each pressure and
    each inertial number (or shear rate), and averaged from `steady_from`
    (docs/dem.md: flow rule).

    Parameters
    ----------
    params : RVECase or Case or dict or str or pathlib.Path
        The RVE tables: an RVECase (`load`), a file's path, the tables as a dict
        (``{"rve": {...}, "triaxial": {...}}``, as the TOML holds them) or a multiscale
        Case (its [rve] and test tables).
    start : RVEBatch, optional
        The packing to shear (default: generated from [rve]).
    inertial : sequence of float, optional
        Inertial numbers I to shear at; give this or `rates`.
    rates : sequence of float, optional
        Shear rates [1/s] to shear at, instead of `inertial`.
    pressures : sequence of float, optional
        Normal pressures [Pa] (default rve.preparation.pressure).
    strain : float, default 3.0
        Shear strain of each run, in (0, 20].
    steady_from : float, default 1.0
        Shear strain from which the steady means are taken.
    tiles : int, default 1
        Copies of the cell along each axis (at most 10,000,000 particles in all).
    allow_damping : bool, default False
        Measure even with rve.damping > 0 (local damping acts as a viscosity and changes
        the measured mu(I)).
    material : str, default "rve_fit"
        Name of the fitted material table (a TOML bare key).
    on_point : callable, optional
        ``on_point(row)`` receives each row of the table as it is measured.
    progress : bool, default True
        Show progress on stderr.
    names : dict of str to str, optional
        Maps these keywords to the caller's spelling in error messages (e.g. the CLI's
        options).
    source : str, optional
        Names the parameters in the material table's comment.

    Returns
    -------
    dict
        ``"table"``: a Curve with one row per (pressure, rate), columns those of the
        CLI's CSV (I, mu, mu_err, mu_p, sigma_n, porosity, ...). ``"fits"``:
        ``{"mu": fit of mu(I), "mu_p": of mu_p(I_p)}``, each mu_s, mu_2, I_0 with
        standard errors; empty where the points do not determine a law.
        ``"material"``: the fitted ``[materials.MATERIAL] type = "mu_i"`` table as TOML
        text (None without a fit). ``"diameter"``: the mean grain diameter [m].
        ``"fit_error"``: why there is no fit (or None).

    Raises
    ------
    ConfigError
        Naming a bad argument, its value and the valid range, before any shearing; or
        as for an invalid `params`.
    TypeError
        If `params` is none of the accepted kinds.

    Examples
    --------
    >>> from grainscale import rve
    >>> law = rve.flow("examples/column_collapse/quick.toml", inertial=[0.01, 0.05, 0.2],
    ...                pressures=[500.0], strain=2.0, steady_from=0.8)
    >>> law["fits"]["mu"]["mu_s"], law["material"]
    """
    from grainscale.dem import flow as _flow

    case = _case(params)
    name = {k: k for k in ("pressures", "inertial", "rates", "strain", "steady_from",
                           "tiles", "allow_damping", "material")} | (names or {})
    if (inertial is None) == (rates is None):
        raise ConfigError(f"give one of {name['inertial']} and {name['rates']}")
    pressures = list(pressures) if pressures else [case.rve.preparation.pressure]
    speeds = list(rates if rates is not None else inertial)
    _check_flow(case, pressures, speeds, "rates" if rates is not None else "inertial",
                strain, steady_from, tiles, allow_damping, material, name)
    rve = case.rve
    start = start if start is not None else generate(case, progress=progress)
    d = _flow.mean_diameter(start)
    # affine (Voigt) P-wave modulus of the packing's contacts -> E at nu = 0.3: an upper
    # bound, used only for the continuum's elastic predictor and time step
    young = float(np.diagonal(start.stiffness[0]).mean()) * 1.3 * 0.4 / 0.7
    batch = _flow.tile(start, tiles, seed=rve.seed)
    points = [(p, float(g)) for p in pressures
              for g in (speeds if rates is not None
                        else _flow.rate_for(speeds, d, rve.density, p))]
    dt = element_tests.timestep(batch, rve)
    durations = []  # simulated time of each run, as simple_shear rounds it to whole steps
    for p, g in points:
        steps, n_rows = element_tests.shear_schedule(_flow.shear_test(p, g, strain), dt)
        durations.append(n_rows * steps * dt)
    bar = Progress(0.0, sum(durations), 0.0, 0, enabled=progress, label="rve flow")
    rows = []
    for (p, g), done in zip(points, np.cumsum([0.0, *durations[:-1]]), strict=True):
        def on_row(row, done=done):
            t = done + row["time"]
            bar.update(t - bar.time, round(t / dt))

        row, _ = _flow.steady_shear(batch, rve, p, g, strain, steady_from, on_row)
        row["tiles"] = tiles
        rows.append({c: row[c] for c in _flow.COLUMNS})
        if on_point is not None:
            on_point(rows[-1])
    bar.close()
    table = {c: np.array([r[c] for r in rows]) for c in _flow.COLUMNS}
    fits, fit_error, toml = {}, None, None
    try:
        for m, i in (("mu", "I"), ("mu_p", "I_p")):
            fits[m] = _flow.fit_mu_i(table[i], table[m], table[f"{m}_err"])
    except ValueError as err:
        fits, fit_error = {}, str(err)
    if fits:
        slowest = int(np.argmin(table["I"]))
        toml = _flow.mu_i_table(material, fits["mu"], rve, d,
                                float(table["porosity"][slowest]), young,
                                source or ("the RVE" if isinstance(params, RVECase)
                                           else str(params)))
    return {"table": table, "fits": fits, "material": toml, "diameter": d,
            "fit_error": fit_error}


def _check_flow(case: RVECase, pressures, speeds, speed_key: str, strain: float,
                steady_from: float, tiles: int, allow_damping: bool, material: str,
                name: dict[str, str]) -> None:
    """Every bad argument of flow() named with its value and valid range."""
    from grainscale.dem.flow import MIN_WINDOW

    for key, values in (("pressures", pressures), (speed_key, speeds)):
        for v in values:
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"{name[key]} = {v!r}: must be a finite number > 0")
    if not 0 < strain <= 20:
        raise ConfigError(f"{name['strain']} = {strain!r}: valid range (0, 20]")
    if not 0 <= steady_from <= strain - MIN_WINDOW:
        raise ConfigError(
            f"{name['steady_from']} = {steady_from!r}: valid range [0, {name['strain']} - "
            f"{MIN_WINDOW}] = [0, {strain - MIN_WINDOW:.3g}] (the steady window needs "
            "enough samples for a confidence band)")
    if not (isinstance(tiles, int) and tiles >= 1):
        raise ConfigError(f"{name['tiles']} = {tiles!r}: must be an integer >= 1")
    if tiles**3 * case.rve.particles > 10_000_000:
        raise ConfigError(f"{name['tiles']} = {tiles}: {tiles}^3 x {case.rve.particles} "
                          "particles exceeds 10,000,000")
    if case.rve.damping > 0 and not allow_damping:
        raise ConfigError(
            f"rve.damping = {case.rve.damping!r}: local damping acts as a viscosity and "
            "changes the measured mu(I); set it to 0 (valid range for a flow "
            f"measurement: 0), or pass {name['allow_damping']} to measure it anyway")
    if not material.isidentifier():
        raise ConfigError(f"{name['material']} = {material!r}: must be a TOML bare key "
                          "(letters, digits, underscores)")


def rows_of(curve: Curve) -> list[dict[str, float]]:
    """The curve's rows, as the CLI writes them.

    Parameters
    ----------
    curve : Curve
        A curve: column name to an array, all of one length.

    Returns
    -------
    list of dict of str to float
        One dict per output row, column name to value.
    """
    n = len(next(iter(curve.values())))
    return [{k: float(v[i]) for k, v in curve.items()} for i in range(n)]


def _case(params: RVECase | Case | str | Path) -> RVECase:
    """The RVE tables of an RVECase, a file, a dict of tables ({"rve": {...},
    "triaxial": {...}}) or a multiscale Case (gs.load_case)."""
    if isinstance(params, RVECase):
        return params
    if isinstance(params, (str, Path)):
        return load(params)
    if isinstance(params, dict):  # the tables as a TOML file holds them
        from grainscale.config.base import validate

        return validate(RVECase, params, source="params")
    if isinstance(params, Case):
        if params.rve is None:
            raise ConfigError("the case has no [rve] table (a multiscale case's RVE)")
        tests = {k: getattr(params, k) for k in ("triaxial", "undrained", "isotropic", "shear")
                 if getattr(params, k) is not None}
        return RVECase(rve=params.rve, **tests)
    raise TypeError(f"params: an RVECase (grainscale.rve.load), a Case, a dict or a path, not "
                    f"{type(params).__name__}")


# what each test's progress follows: the row column, and its end in the test's table
_MEASURE = {"triaxial": ("axial_strain", "axial_strain"),
            "undrained": ("axial_strain", "axial_strain"),
            "shear": ("shear_strain", "shear_strain"),
            "isotropic": ("p", "pressure_final")}


def _test(name: str, run, case: RVECase, test, start: RVEBatch | None, on_row,
          progress: bool, per_rve: bool = False) -> Curve | list[Curve]:
    if test is None:
        raise ConfigError(f"no [{name}] table in the parameters: add one (docs/case-files.md)")
    batch = start.copy() if start is not None else generate(case, progress=progress)
    column, key = _MEASURE[name]
    end = float(getattr(test, key))
    bar = None

    def seen(row: dict) -> None:
        nonlocal bar
        x = row[column]
        if bar is None:  # from the first row's value: isotropic p starts where it is
            bar = Progress(x, end, x, None, enabled=progress and end > x,
                           quantity=column.replace("_", " "), unit="Pa" if column == "p" else "",
                           label=f"rve {name}")
        else:
            bar.update(min(x, end) - bar.time)
        bar.note(f"p={row['p']:.4g} q/p={row['q_over_p']:.3f}")
        if on_row is not None:
            on_row(row)

    extra = {"every_rve": True} if per_rve else {}
    rows = run(batch, case.rve, test, on_row=seen, **extra)
    if bar is not None:
        bar.close()
    if per_rve:
        return [{c: np.array([r[c] for r in one]) for c in one[0]} for one in rows]
    return {c: np.array([r[c] for r in rows]) for c in rows[0]}


__all__ = ["Curve", "flow", "generate", "isotropic", "load", "packing", "rows_of", "save",
           "shear", "timestep", "triaxial", "triaxial_ensemble", "undrained"]

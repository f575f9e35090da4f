"""The RVE alone from Python: what `grainscale rve generate|triaxial|undrained|isotropic|
shear` do (docs/api.md, docs/dem.md), returning the packing and the curves as arrays.
The command line calls these functions and writes what they return.

    from grainscale import rve
    params = rve.load("examples/rve/unit_element.toml")     # [rve] and test tables
    packing = rve.generate(params)
    curve = rve.triaxial(params, packing)
    curve["axial_strain"], curve["q_over_p"]
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from grainscale.config.case import load_rve_case
from grainscale.config.rve import RVECase
from grainscale.dem import element_tests, engine
from grainscale.dem.generate import contact_params
from grainscale.dem.generate import generate as _generate
from grainscale.dem.state import RVEBatch
from grainscale.io.packing import load_packing

Curve = dict[str, np.ndarray]


def load(path: str | Path) -> RVECase:
    """The [rve] table and the element-test tables ([triaxial], [undrained], [isotropic],
    [shear]) of a file: an RVE parameter file or a multiscale case file (docs/case-files.md);
    ConfigError names a bad key, its value and the valid range."""
    return load_rve_case(path)


def generate(params: RVECase | str | Path,
             progress: Callable[[str], None] | None = None) -> RVEBatch:
    """A consolidated packing as [rve] asks (docs/dem.md: generation), ready to load:
    a batch of one RVE, its contact state refreshed. `progress(text)` receives a status
    line after each compaction stage."""
    case = _case(params)
    batch = _generate(case.rve, progress=progress)
    engine.refresh(batch, contact_params(case.rve))
    return batch


def packing(params: RVECase | str | Path, path: str | Path) -> RVEBatch:
    """A packing file (.txt exchange format or .h5 state) with the contact law of
    `params`, its contact state refreshed: the start of a test instead of generate()."""
    case = _case(params)
    batch = load_packing(Path(path), case.rve)
    engine.refresh(batch, contact_params(case.rve))
    return batch


def triaxial(params: RVECase | str | Path, start: RVEBatch | None = None,
             on_row: Callable[[dict], None] | None = None) -> Curve:
    """Drained triaxial compression ([triaxial]: lateral stresses servo-held at the
    confining pressure, the axis compressed at the strain rate) of `start` (default: a
    packing generated from [rve]); the curve as arrays, one per column of the CLI's CSV
    (docs/dem.md: axial_strain, p, q, q_over_p, volumetric_strain, porosity, ...)."""
    case = _case(params)
    return _test(element_tests.triaxial, case, case.triaxial, start, on_row)


def undrained(params: RVECase | str | Path, start: RVEBatch | None = None,
              on_row: Callable[[dict], None] | None = None) -> Curve:
    """Constant-volume compression ([undrained]) of `start`; the curve as arrays."""
    case = _case(params)
    return _test(element_tests.undrained, case, case.undrained, start, on_row)


def isotropic(params: RVECase | str | Path, start: RVEBatch | None = None,
              on_row: Callable[[dict], None] | None = None) -> Curve:
    """Isotropic compression to [isotropic] pressure_final; the curve as arrays."""
    case = _case(params)
    return _test(element_tests.isotropic, case, case.isotropic, start, on_row)


def shear(params: RVECase | str | Path, start: RVEBatch | None = None,
          on_row: Callable[[dict], None] | None = None) -> Curve:
    """Simple shear in x-z at constant normal stress ([shear]); the curve as arrays."""
    case = _case(params)
    return _test(element_tests.simple_shear, case, case.shear, start, on_row)


def rows_of(curve: Curve) -> list[dict[str, float]]:
    """The curve's rows (one dict per output row), as the CLI writes them."""
    n = len(next(iter(curve.values())))
    return [{k: float(v[i]) for k, v in curve.items()} for i in range(n)]


def _case(params: RVECase | str | Path) -> RVECase:
    if isinstance(params, RVECase):
        return params
    if isinstance(params, (str, Path)):
        return load(params)
    raise TypeError(f"params: an RVECase (grainscale.rve.load) or a path, not "
                    f"{type(params).__name__}")


def _test(run, case: RVECase, test, start: RVEBatch | None, on_row) -> Curve:
    batch = start.copy() if start is not None else generate(case)  # start is the caller's
    rows = run(batch, case.rve, test, on_row=on_row)
    return {c: np.array([r[c] for r in rows]) for c in rows[0]}


__all__ = ["Curve", "generate", "isotropic", "load", "packing", "rows_of", "shear",
           "triaxial", "undrained"]

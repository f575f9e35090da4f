"""Building the DEM RVE materials of a case: packing libraries and the material factory.

A "dem" material needs its packings before the MPM points exist (their mass comes from
the packings' bulk density). Packings are read from `materials.NAME.packings` or
generated from the case's [rve] table (seeds rve.seed, rve.seed + 1, ...) and cached in
the output folder (`packings/NAME_k.h5`, reused when the [rve] table is unchanged), so a
resumed or repeated run does not generate them again. A geostatic library
(`geostatic_pressures`) holds `library` packings per pressure level
(`packings/NAME_pL_k.h5`), and each point takes one of the level that matches its depth.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import sys
from pathlib import Path

import numpy as np

from grainscale.config.base import ConfigError
from grainscale.config.case import Case
from grainscale.config.rve import RVEParams
from grainscale.coupling.rve_material import RVEMaterial, bulk_density
from grainscale.dem.generate import contact_params, generate
from grainscale.dem.state import RVEBatch
from grainscale.io.packing import load_packing
from grainscale.io.rve_h5 import read_rve_state, write_rve_state

STORE_ENV = "GRAINSCALE_PACKING_STORE"  # a folder of packings shared between runs


def _store_file(key: dict) -> Path | None:
    """The file of recipe `key` in the folder $GRAINSCALE_PACKING_STORE (unset: None)."""
    folder = os.environ.get(STORE_ENV)
    if not folder:
        return None
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:24]
    return Path(folder) / f"packing_{digest}.h5"


def _copy_atomic(src: Path, dst: Path) -> None:
    """dst <- src by a uniquely named temporary and a rename: concurrent processes (MPI
    ranks) writing the same file each leave a complete one."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(f"{dst.name}.{os.getpid()}.tmp")
    try:
        shutil.copyfile(src, tmp)
    except OSError:  # a full disk: nothing half-written left behind
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, dst)


def cached_packing(params: RVEParams, k: int, cache: Path, progress: bool) -> RVEBatch:
    """Packing k of the [rve] recipe (seed params.seed + k), read from `cache` if it holds
    that recipe's packing, else generated and written there. With the environment
    variable GRAINSCALE_PACKING_STORE naming a folder, a packing of the same recipe
    found there is copied instead of generated, and a generated one is added to it
    (parameter studies and the test suite generate each recipe once)."""
    p = params.model_copy(update={"seed": params.seed + k})
    key = p.recipe()
    if cache.is_file():
        batch, stored = read_rve_state(cache)
        if stored == key:
            return batch
    store = _store_file(key)
    if store is not None and store.is_file():
        batch, stored = read_rve_state(store)
        if stored == key:
            _copy_atomic(store, cache)
            return batch
    say = (lambda text: print(f"  packing {k}: {text}", file=sys.stderr)) if progress else None
    batch = generate(p, progress=say)
    cache.parent.mkdir(parents=True, exist_ok=True)
    write_rve_state(cache, batch, key)
    if store is not None:
        _copy_atomic(cache, store)
    return batch


def packing_library(case: Case, name: str, case_dir: Path, out: Path,
                    progress: bool = True) -> list[RVEBatch]:
    """The packings of material `name` (each a batch of one RVE); a geostatic library
    level by level, `library` packings each, from the lowest pressure up."""
    cfg = case.materials[name]
    if cfg.packings:
        library = []
        for i, f in enumerate(cfg.packings):
            path = case_dir / f
            if not path.is_file():
                raise ConfigError(f"materials.{name}.packings[{i}] = {f!r}: file not found "
                                  f"({path})")
            library.append(load_packing(path, case.rve))
        return library
    levels = cfg.geostatic_pressures
    if progress:
        at = f" at each of {levels} Pa" if levels else ""
        grains = "clumps" if case.rve.clump is not None else "spheres"
        print(f"preparing {cfg.library} packing(s){at} for material {name!r} "
              f"({case.rve.particles} {grains} each)", file=sys.stderr)
    if not levels:
        return [cached_packing(case.rve, k, out / "packings" / f"{name}_{k}.h5", progress)
                for k in range(cfg.library)]
    library = []
    for level, p in enumerate(levels):
        prep = case.rve.preparation.model_copy(update={"pressure": p})
        params = case.rve.model_copy(update={"preparation": prep})
        library += [cached_packing(params, k, out / "packings" / f"{name}_p{level}_{k}.h5",
                               progress) for k in range(cfg.library)]
    return library


def geostatic_assignment(x: np.ndarray, gravity, density: float, k0: float,
                         pressures: list[float], per_level: int, seed: int) -> np.ndarray:
    """The packing of each point in a geostatic library (level-major, `per_level`
    packings a level): one of the level whose pressure is nearest, in log, to the
    point's lithostatic mean stress p = rho |g| depth (1 + 2 k0) / 3 [Pa] (rho the bulk
    density [kg/m^3], depth [m] below the highest point along gravity: a flat free
    surface), drawn at random with `seed`. Points shallower than the lowest level take
    it."""
    g = np.asarray(gravity, dtype=float)
    gn = float(np.linalg.norm(g))
    height = -(x @ g) / gn
    p = density * gn * (height.max() - height) * (1 + 2 * k0) / 3
    logp = np.log(np.maximum(p, pressures[0]))
    level = np.abs(logp[:, None] - np.log(pressures)[None, :]).argmin(axis=1)
    rng = np.random.default_rng(seed)
    return level * per_level + rng.integers(per_level, size=len(x))


def check_retile_width(name: str, width: float, library: list[RVEBatch], skin: float
                       ) -> None:
    """A retile width (mean grain diameters) must exceed the narrowest cell the
    neighbour search accepts, 2 (2 r_max + skin), or cells would stop the run before
    they are doubled."""
    if width <= 0:
        return
    least = max(2 * (2 * b.radius[0].max() + skin) / (2 * b.radius[0].mean())
                for b in library)
    if width <= least:
        raise ConfigError(f"materials.{name}.retile_width = {width}: must exceed {least:.3g} "
                          "mean grain diameters for these packings (the narrowest cell the "
                          "neighbour search accepts, 2 (2 r_max + skin)), or be 0 (never "
                          "retile)")


def check_retile_width_of_recipe(name: str, width: float, rve: RVEParams) -> None:
    """check_retile_width before generating: with radii drawn uniformly in [r_min, r_max],
    the packing's mean radius exceeds (r_min + r_max)/2 + 3 sigma, sigma = (r_max - r_min)
    / sqrt(12 N), with probability ~1e-3, so a width below the bound of that mean is
    refused without generating anything; the exact check follows generation."""
    if width <= 0:
        return
    rmin, rmax = rve.radius_min, rve.radius_max
    mean_hi = 0.5 * (rmin + rmax) + 3.0 * (rmax - rmin) / math.sqrt(12.0 * rve.particles)
    least = (2 * rmax + contact_params(rve).skin) / mean_hi
    if width <= least:
        raise ConfigError(f"materials.{name}.retile_width = {width}: must exceed {least:.3g} "
                          "mean grain diameters for the [rve] recipe's radii (the narrowest "
                          "cell the neighbour search accepts, 2 (2 r_max + skin)), or be 0 "
                          "(never retile)")


def prepare(case: Case, case_dir: Path, out: Path, progress: bool = True):
    """Packings of every "dem" material; sets their bulk density in the case and
    returns the `material_factory` for `mpm.setup.build_state` (None if none)."""
    libraries = {}
    for name, cfg in case.materials.items():  # what can be checked before generating
        if cfg.type == "dem" and not cfg.packings:
            check_retile_width_of_recipe(name, cfg.retile_width, case.rve)
    for name, cfg in case.materials.items():
        if cfg.type != "dem":
            continue
        lib = packing_library(case, name, case_dir, out, progress)
        check_retile_width(name, cfg.retile_width, lib, contact_params(case.rve).skin)
        cfg.density = bulk_density(lib)
        libraries[name] = lib
    if not libraries:
        return None

    def factory(name: str, cfg, x: np.ndarray, local=None) -> RVEMaterial:
        assignment = None
        if cfg.geostatic_pressures:
            assignment = geostatic_assignment(x, case.solver.gravity, cfg.density,
                                              cfg.geostatic_k0, cfg.geostatic_pressures,
                                              cfg.library, cfg.assignment_seed)
        return RVEMaterial(name, case.rve, libraries[name], len(x), local=local,
                           assignment_seed=cfg.assignment_seed, assignment=assignment,
                           mode=cfg.time_integration,
                           min_substeps=cfg.min_substeps,
                           strain_per_substep=cfg.strain_per_substep,
                           retile_width=cfg.retile_width,
                           retile_max_factor=cfg.retile_max_factor,
                           device=case.solver.device,
                           update_tolerance=cfg.update_tolerance,
                           max_deferred_steps=cfg.max_deferred_steps)

    return factory


"""Building the DEM RVE materials of a case: packing libraries and the material factory.

A "dem" material needs its packings before the MPM points exist (their mass comes from
the packings' bulk density). Packings are read from `materials.NAME.packings` or
generated from the case's [rve] table (seeds rve.seed, rve.seed + 1, ...) and cached in
the output folder (`packings/NAME_k.h5`, reused when the [rve] table is unchanged), so a
resumed or repeated run does not generate them again.
"""

from __future__ import annotations

import sys
from pathlib import Path

from grainscale.config.base import ConfigError
from grainscale.config.case import Case
from grainscale.config.rve import RVEParams
from grainscale.coupling.rve_material import RVEMaterial, bulk_density
from grainscale.dem.generate import contact_params, generate
from grainscale.dem.state import RVEBatch
from grainscale.io.packing import load_packing
from grainscale.io.rve_h5 import read_rve_state, write_rve_state


def _generated(params: RVEParams, k: int, cache: Path, progress: bool) -> RVEBatch:
    p = params.model_copy(update={"seed": params.seed + k})
    key = p.model_dump(mode="json")
    if cache.is_file():
        batch, stored = read_rve_state(cache)
        if stored == key:
            return batch
    say = (lambda text: print(f"  packing {k}: {text}", file=sys.stderr)) if progress else None
    batch = generate(p, progress=say)
    cache.parent.mkdir(parents=True, exist_ok=True)
    write_rve_state(cache, batch, key)
    return batch


def packing_library(case: Case, name: str, case_dir: Path, out: Path,
                    progress: bool = True) -> list[RVEBatch]:
    """The packings of material `name` (each a batch of one RVE)."""
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
    if progress:
        print(f"preparing {cfg.library} packing(s) for material {name!r} "
              f"({case.rve.particles} spheres each)", file=sys.stderr)
    return [_generated(case.rve, k, out / "packings" / f"{name}_{k}.h5", progress)
            for k in range(cfg.library)]


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


def prepare(case: Case, case_dir: Path, out: Path, progress: bool = True):
    """Packings of every "dem" material; sets their bulk density in the case and
    returns the `material_factory` for `mpm.setup.build_state` (None if none)."""
    libraries = {}
    for name, cfg in case.materials.items():
        if cfg.type != "dem":
            continue
        lib = packing_library(case, name, case_dir, out, progress)
        check_retile_width(name, cfg.retile_width, lib, contact_params(case.rve).skin)
        cfg.density = bulk_density(lib)
        libraries[name] = lib
    if not libraries:
        return None

    def factory(name: str, cfg, n_points: int, local=None) -> RVEMaterial:
        return RVEMaterial(name, case.rve, libraries[name], n_points, local=local,
                           assignment_seed=cfg.assignment_seed, mode=cfg.time_integration,
                           min_substeps=cfg.min_substeps,
                           strain_per_substep=cfg.strain_per_substep,
                           retile_width=cfg.retile_width,
                           retile_max_factor=cfg.retile_max_factor,
                           device=case.solver.device)

    return factory


"""Compile DEM kernels into the test session's numba cache in the background, in the
order the tests need them (ORDER): once the session's tests are selected,
tests/conftest.py starts the CUDA simulator's process, which runs this first, or, with
no simulator test selected, this script alone.

- rve: the linear-contact step kernel and the generation and RVE-update kernels around
  it (~35 s cold): a 150-sphere packing generated and one update of quasi-static and
  dynamic RVEs, the path of the first coupling tests. tests/mpm, which needs none of
  them, runs first meanwhile (conftest).
- hertz, rolling: the step kernel's Hertz-Mindlin and rolling-resistance variants
  (dem/kernel.py), seconds each: one step of two spheres through engine.advance, the
  path every test and run takes, so the argument types (and thus the cached signature)
  are theirs.

Compiled here on the machine's other core while earlier tests run, the test that first
needs a kernel loads it from the cache instead.

    python tests/warm_kernels.py [rve] [hertz] [rolling]
"""

from __future__ import annotations

import sys

import numpy as np

from grainscale.config.rve import RVEParams
from grainscale.coupling.rve_material import RVEMaterial
from grainscale.dem import engine
from grainscale.dem.generate import generate
from grainscale.dem.state import from_packing

ORDER = ("rve", "hertz", "rolling")  # as the tests need them
VARIANTS = {"hertz": {"contact_law": "hertz_mindlin", "poisson": 0.22},
            "rolling": {"rolling_stiffness": 1.0, "rolling_friction": 0.2}}


def compile_rve() -> None:
    params = RVEParams(particles=150, preparation={"pressure": 100e3, "porosity": 0.38,
                                                   "porosity_tolerance": 0.005})
    pack = generate(params)
    dH = np.zeros((2, 3, 3))
    dH[:, 2, 2] = -1e-5
    for mode in ("quasi_static", "dynamic"):
        for tol in (0.0, 3e-6):
            rves = RVEMaterial("sand", params, [pack], n_points=2, mode=mode,
                               retile_width=0.0, update_tolerance=tol)
            rves.update(dH, 1e-5, rves.initial_stress())


def compile_variant(name: str) -> None:
    if name == "rve":
        return compile_rve()
    params = engine.ContactParams(young=70e9, stiffness_ratio=0.8, friction=0.5,
                                  damping=0.0, skin=0.2e-3, **VARIANTS[name])
    pair = from_packing(np.eye(3) * 10e-3, np.array([[3e-3, 5e-3, 5e-3], [5.6e-3, 5e-3, 5e-3]]),
                        np.array([1e-3, 1.5e-3]), 2500.0, capacity=4)
    engine.advance(pair, 1, 1e-8, params, engine.rate_control(1))


def main(names) -> None:
    for variant in ORDER:
        if variant in names:
            compile_variant(variant)


if __name__ == "__main__":
    main(sys.argv[1:])

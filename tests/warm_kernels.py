"""Compile the DEM kernel's Hertz-Mindlin and rolling-resistance variants into the test
session's numba cache, in a process of its own (tests/conftest.py starts it once the
session's tests are selected, when some of them need a variant).

Each variant is a separate specialisation of the step kernel (dem/kernel.py) that takes
seconds to compile; compiled here on the machine's other core while the first tests
run, the test that first needs it loads it from the cache instead. One step of two
spheres through engine.advance, the path every test and run takes, so the argument
types (and thus the cached signature) are theirs.

    python tests/warm_kernels.py [hertz] [rolling]
"""

from __future__ import annotations

import sys

import numpy as np

from grainscale.dem import engine
from grainscale.dem.state import from_packing

VARIANTS = {"hertz": {"contact_law": "hertz_mindlin", "poisson": 0.22},
            "rolling": {"rolling_stiffness": 1.0, "rolling_friction": 0.2}}


def compile_variant(name: str) -> None:
    params = engine.ContactParams(young=70e9, stiffness_ratio=0.8, friction=0.5,
                                  damping=0.0, skin=0.2e-3, **VARIANTS[name])
    pair = from_packing(np.eye(3) * 10e-3, np.array([[3e-3, 5e-3, 5e-3], [5.6e-3, 5e-3, 5e-3]]),
                        np.array([1e-3, 1.5e-3]), 2500.0, capacity=4)
    engine.advance(pair, 1, 1e-8, params, engine.rate_control(1))


if __name__ == "__main__":
    for variant in sys.argv[1:]:
        compile_variant(variant)

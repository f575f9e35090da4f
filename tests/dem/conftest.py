"""Fixtures of the DEM physics tests.

Fixtures that generate packings are session-scoped: a generation costs seconds, and
the tests that use them work on copies.
"""

from __future__ import annotations

import pytest
from dem_helpers import SMALL_PARAMS

from grainscale.dem.generate import generate
from grainscale.dem.state import RVEBatch


@pytest.fixture(scope="session")
def small_packing() -> RVEBatch:
    """A 150-sphere packing consolidated to p = 100 kPa, porosity 0.373 (seed unit
    element parameters, fewer spheres)."""
    return generate(SMALL_PARAMS)

"""GRAINSCALE_PACKING_STORE: a recipe's packing generated once, copied into every run
folder that asks for it (coupling/materials.cached_packing)."""

import numpy as np
import pytest

from grainscale.config.rve import RVEParams
from grainscale.coupling import materials

TINY = RVEParams(particles=60, radius_min=2e-3, radius_max=2.4e-3, seed=5,
                 preparation={"pressure": 10e3, "porosity": 0.42, "porosity_tolerance": 0.04})


def test_a_stored_recipe_is_copied_not_generated(tmp_path, monkeypatch):
    monkeypatch.setenv(materials.STORE_ENV, str(tmp_path / "store"))
    first = materials.cached_packing(TINY, 0, tmp_path / "a" / "sand_0.h5", False)
    assert len(list((tmp_path / "store").glob("packing_*.h5"))) == 1

    def refuse(*args, **kwargs):
        raise AssertionError("generated although the store holds the recipe")

    monkeypatch.setattr(materials, "generate", refuse)
    again = materials.cached_packing(TINY, 0, tmp_path / "b" / "sand_0.h5", False)
    assert np.array_equal(again.s, first.s) and np.array_equal(again.h, first.h)
    assert (tmp_path / "b" / "sand_0.h5").read_bytes() == (
        tmp_path / "a" / "sand_0.h5").read_bytes()
    # another packing of the recipe (seed + 1) is not in the store: generated
    with pytest.raises(AssertionError, match="generated"):
        materials.cached_packing(TINY, 1, tmp_path / "b" / "sand_1.h5", False)

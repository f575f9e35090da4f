"""Materials behind one batched interface (see `base.py`) and a factory by type name."""

from __future__ import annotations

from grainscale.mpm.materials.base import Material
from grainscale.mpm.materials.drucker_prager import DruckerPrager
from grainscale.mpm.materials.elastic import LinearElastic
from grainscale.mpm.materials.fluidity import NonlocalMuI
from grainscale.mpm.materials.mohr_coulomb import MohrCoulomb
from grainscale.mpm.materials.mu_i import MuI

KINDS = {
    "linear_elastic": LinearElastic,
    "mohr_coulomb": MohrCoulomb,
    "drucker_prager": DruckerPrager,
    "mu_i": MuI,
    "nonlocal_mu_i": NonlocalMuI,
}

__all__ = ["KINDS", "DruckerPrager", "LinearElastic", "Material", "MohrCoulomb", "MuI",
           "NonlocalMuI"]

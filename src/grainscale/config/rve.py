"""Case-file tables of the DEM side: `[rve]`, `[rve.preparation]` and the element tests.

```toml
[rve]
particles = 800
radius_min = 3e-3
radius_max = 7e-3
density = 2650.0
contact_law = "linear"     # or "hertz_mindlin" (with poisson_ratio, no stiffness_ratio)
young_modulus = 100e6
stiffness_ratio = 0.8      # kt/kn
friction = 0.5
damping = 0.2              # local non-viscous
seed = 1
[rve.preparation]
pressure = 100e3
porosity = 0.373
[triaxial]
confining_pressure = 100e3
axial_strain = 0.5
strain_rate = 0.1          # 1/s, quasi-static
```
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_serializer, model_validator

from grainscale.config.base import StrictModel

AXES = {"x": 0, "y": 1, "z": 2}


class Preparation(StrictModel):
    """Isotropic consolidation of a fresh packing (generation)."""

    pressure: float = Field(100e3, gt=0, description="target mean stress p [Pa]")
    porosity: float | None = Field(
        None, gt=0.26, lt=0.50,
        description="target porosity; a static packing of frictionless-to-frictional "
        "spheres without adhesion lies between ~0.26 (ordered) and ~0.50 (random loose)")
    porosity_tolerance: float = Field(0.003, gt=0, lt=0.05)
    initial_porosity: float = Field(
        0.70, ge=0.55, lt=0.95,
        description="porosity of the random non-overlapping insertion (gas state)")
    consolidation_pressure: float | None = Field(
        None, gt=0,
        description="pressure at which the porosity is set before unloading to `pressure` "
        "[Pa] (default: max(pressure, young_modulus / 2e4), hertz_mindlin: max(pressure, "
        "E* / 2e4^1.5), E* = E / (2 (1 - nu^2)))")
    compaction_friction: float | None = Field(
        None, ge=0, description="friction to start compaction with (default: friction)")
    damping: float = Field(0.5, ge=0, lt=1, description="local damping while preparing")
    max_strain_rate: float = Field(1.0, gt=0, description="servo rate limit [1/s]")
    unbalanced: float = Field(0.01, gt=0, lt=1,
                              description="equilibrium: unbalanced-force ratio below this")


class Numerics(StrictModel):
    timestep_safety: float = Field(0.3, gt=0, le=0.5,
                                   description="dt = safety x sqrt(m_min / k_max)")
    skin: float = Field(0.25, gt=0, le=2.0,
                        description="Verlet skin as a fraction of radius_min")
    servo_gain: float = Field(0.05, gt=0, le=0.5,
                              description="fraction of the stress error corrected a step")
    max_overlap: float = Field(
        0.01, gt=0, le=0.2, description="Hertz-Mindlin: the largest overlap delta/R* the "
        "time step is set for (k_max = 2 E* R* sqrt(max_overlap)); a larger one at the end "
        "of a call (an MPM step) stops the run with an error naming this key")


class ClumpShape(StrictModel):
    """`[rve.clump]`: the grains are rigid clumps of overlapping spheres (dem/clump.py),
    each a template scaled by a factor uniform in [radius_min, radius_max] (the radius
    of its member spheres); `particles` counts clumps."""

    template: Literal["sphere", "elongated", "tetrahedral"] = Field(
        description="'elongated': `spheres` equal spheres on a line, length/width = "
        "`aspect`; 'tetrahedral': four spheres on a regular tetrahedron of edge "
        "`overlap_edge` radii; 'sphere': one sphere (the clump path of a sphere)")
    aspect: float | None = Field(None, gt=1.0, le=4.0,
                                 description="length over width ('elongated')")
    spheres: int | None = Field(None, ge=2, le=8, description="members ('elongated')")
    overlap_edge: float | None = Field(
        None, gt=0.0, lt=2.0, description="tetrahedron edge in member radii ('tetrahedral')")

    @model_validator(mode="after")
    def _keys_of_template(self):
        used = {"sphere": set(), "elongated": {"aspect", "spheres"},
                "tetrahedral": {"overlap_edge"}}[self.template]
        for key in ("aspect", "spheres", "overlap_edge"):
            if key in self.model_fields_set and key not in used:
                raise ValueError(f"{key} = {getattr(self, key)!r} has no effect with "
                                 f"template = {self.template!r}; remove it")
        if self.template == "elongated" and self.aspect is None:
            raise ValueError("template = 'elongated' needs aspect (length over width); "
                             "valid range: (1, 4]")
        return self

    def shape(self):
        """The clump.Template (unit member radius) this table names."""
        from grainscale.dem import clump  # noqa: PLC0415 (numba import cost)

        kw = {k: v for k, v in (("aspect", self.aspect), ("spheres", self.spheres),
                                ("overlap_edge", self.overlap_edge)) if v is not None}
        try:
            return clump.template(self.template, **kw)
        except ValueError as err:
            raise ValueError(f"rve.clump: {err}") from None


class RVEParams(StrictModel):
    particles: int = Field(800, ge=20, le=10_000_000)
    radius_min: float = Field(3e-3, gt=0, description="smallest radius [m]")
    radius_max: float = Field(7e-3, gt=0, description="largest radius [m]")
    density: float = Field(2650.0, gt=0, description="grain density [kg/m^3]")
    contact_law: Literal["linear", "hertz_mindlin"] = Field(
        "linear", description="'linear': kn = E r*, kt = stiffness_ratio kn (seed Eq. 7-10); "
        "'hertz_mindlin': f_n = (4/3) E* sqrt(R*) delta^(3/2), kt = 8 G* a (docs/dem.md)")
    young_modulus: float = Field(100e6, gt=0, description="E [Pa]: kn = E r* (linear), the "
                                 "grains' Young's modulus (hertz_mindlin)")
    poisson_ratio: float | None = Field(
        None, ge=0, lt=0.5, description="the grains' Poisson's ratio nu (hertz_mindlin only)")
    stiffness_ratio: float = Field(0.8, gt=0, le=1.0, description="kt/kn (linear only)")
    friction: float = Field(0.5, ge=0, le=10, description="interparticle friction mu")
    restitution: float = Field(
        1.0, gt=0, le=1, description="normal coefficient of restitution e of a binary "
        "collision (linear spring-dashpot); 1: elastic, no collisional loss")
    damping: float = Field(0.2, ge=0, lt=1, description="local non-viscous damping")
    rolling_stiffness: float = Field(
        0.0, ge=0, le=100, description="alpha_r in the rolling stiffness k_r = alpha_r kt "
        "r_i r_j [N m/rad] (docs/dem.md: rolling resistance); 0: no rolling resistance")
    rolling_friction: float = Field(
        0.0, ge=0, le=10, description="eta_r in the cap of the rolling moment, |M_r| <= "
        "eta_r min(r_i, r_j) f_n (with rolling_stiffness > 0)")
    seed: int = Field(1, ge=0)
    clump: ClumpShape | None = Field(
        None, description="rigid clumps of spheres instead of spheres ([rve.clump])")
    preparation: Preparation = Preparation()
    numerics: Numerics = Numerics()

    @model_serializer(mode="wrap")
    def _no_stiffness_ratio_with_hertz(self, handler):
        # Hertz-Mindlin refuses stiffness_ratio: writing its default back would make
        # case.resolved.toml (and a checkpoint's case) a case that _contact_law refuses
        data = handler(self)
        if self.contact_law == "hertz_mindlin":
            data.pop("stiffness_ratio", None)
        return data

    def recipe(self) -> dict:
        """The table as the key of a generated packing (coupling/materials.py): the
        rolling keys only where rolling resistance is on, so that packings made before
        they existed (and without them) keep their keys."""
        key = self.model_dump(mode="json")
        if self.rolling_stiffness == 0.0:
            del key["rolling_stiffness"], key["rolling_friction"]
        if self.contact_law == "linear":
            del key["contact_law"], key["poisson_ratio"], key["numerics"]["max_overlap"]
        if self.clump is None:
            del key["clump"]
        return key

    @model_validator(mode="after")
    def _contact_law(self):
        if self.contact_law == "hertz_mindlin":
            if self.poisson_ratio is None:
                raise ValueError(
                    "contact_law = 'hertz_mindlin' needs poisson_ratio (the grains' "
                    "Poisson's ratio); valid range: [0, 0.5)")
            if "stiffness_ratio" in self.model_fields_set:
                raise ValueError(
                    f"stiffness_ratio = {self.stiffness_ratio!r} has no effect with "
                    "contact_law = 'hertz_mindlin' (kt/kn = 2 (1 - nu)/(2 - nu) follows from "
                    "poisson_ratio); remove it, or use contact_law = 'linear'")
        elif self.poisson_ratio is not None:
            raise ValueError(
                f"poisson_ratio = {self.poisson_ratio!r} has no effect with contact_law = "
                "'linear'; remove it, or use contact_law = 'hertz_mindlin'")
        elif self.numerics.max_overlap != Numerics().max_overlap:  # a round trip sets it
            raise ValueError(
                f"numerics.max_overlap = {self.numerics.max_overlap!r} has no effect with "
                "contact_law = 'linear' (its step is set by kn = E r*); remove it, or use "
                "contact_law = 'hertz_mindlin'")
        return self

    @model_validator(mode="after")
    def _rolling(self):
        if self.rolling_friction > 0.0 and self.rolling_stiffness == 0.0:
            raise ValueError(
                f"rolling_friction = {self.rolling_friction!r} has no effect with "
                "rolling_stiffness = 0 (rolling resistance off); valid: rolling_stiffness "
                "in (0, 100] with it, or rolling_friction = 0")
        if self.rolling_stiffness > 0.0 and self.rolling_friction == 0.0:
            raise ValueError(
                f"rolling_stiffness = {self.rolling_stiffness!r} with rolling_friction = 0 "
                "caps every rolling moment at zero; valid: rolling_friction in (0, 10] "
                "with it, or rolling_stiffness = 0")
        return self

    @model_validator(mode="after")
    def _clump_shape(self):
        if self.clump is not None:
            self.clump.shape()  # a template that cannot be built is refused here
        return self

    @model_validator(mode="after")
    def _radii(self):
        if self.radius_max < self.radius_min:
            raise ValueError(
                f"radius_max = {self.radius_max!r} is below radius_min = "
                f"{self.radius_min!r}; valid range: radius_max >= radius_min")
        return self


def check_particles(params: RVEParams, key: str = "rve.particles") -> None:
    """ConfigError, before any packing is generated from `params`, if its particle count
    cannot fill the insertion cell (min_particles at 3 standard deviations)."""
    from grainscale.config.base import ConfigError

    phi = params.preparation.initial_porosity
    least = min_particles(params.radius_min, params.radius_max, phi, spread=3.0)
    if params.particles < least:
        mean = min_particles(params.radius_min, params.radius_max, phi)
        raise ConfigError(
            f"{key} = {params.particles} is too few for radii {params.radius_min:g}-"
            f"{params.radius_max:g} m: the cell they are inserted in (at initial_porosity "
            f"{phi:g}) would be narrower than 8 radius_max even for radii 3 standard "
            f"deviations above their mean; valid: {key} >= {least} ({mean} or more to "
            "fill it on average, whatever the seed)")


def min_particles(radius_min: float, radius_max: float, initial_porosity: float,
                  spread: float = 0.0) -> int:
    """The fewest spheres whose insertion cell (dem/generate.insert_random: a cube at
    `initial_porosity`) is at least 8 radius_max wide, wider than twice the neighbour
    search's reach (4 diameters), when their summed r^3 is `spread` standard deviations
    above its mean [-]: (4/3) pi sum r^3 = (1 - phi_i) (8 r_max)^3, with radii uniform
    in [a, b]: mean r^3 <r^3> = (b^4 - a^4) / (4 (b - a)), variance <r^6> - <r^3>^2,
    <r^6> = (b^7 - a^7) / (7 (b - a)). spread 0: the count that fills it on average;
    3: below that count, generation fails whatever the seed (but 1 in ~700)."""
    a, b = radius_min, radius_max
    if b == a:
        m3, var = a ** 3, 0.0
    else:
        m3 = (b ** 4 - a ** 4) / (4.0 * (b - a))
        var = max((b ** 7 - a ** 7) / (7.0 * (b - a)) - m3 * m3, 0.0)
    need = (1.0 - initial_porosity) * (8.0 * b) ** 3 / (4.0 / 3.0 * math.pi)
    n = 1
    while n * m3 + spread * math.sqrt(n * var) < need * (1.0 - 1e-12):
        n += 1
    return n


class TriaxialTest(StrictModel):
    """Drained triaxial compression: axial strain rate given, lateral stresses servo-held."""

    confining_pressure: float = Field(100e3, gt=0, description="[Pa]")
    axial_strain: float = Field(0.5, gt=0, lt=0.9, description="final (L0-L)/L0")
    strain_rate: float = Field(0.1, gt=0, description="axial compression rate [1/s]")
    rate: Literal["engineering", "true"] = Field(
        "engineering", description="constant d((L0-L)/L0)/dt, or constant -dln(L)/dt (as an "
        "MPM velocity boundary over fixed nodes imposes)")
    axis: Literal["x", "y", "z"] = "z"
    output_interval: float = Field(0.002, gt=0, description="axial strain between rows")


class UndrainedTest(StrictModel):
    """Constant-volume triaxial compression (undrained analogue)."""

    axial_strain: float = Field(0.2, gt=0, lt=0.9)
    strain_rate: float = Field(0.1, gt=0)
    axis: Literal["x", "y", "z"] = "z"
    output_interval: float = Field(0.002, gt=0)


class IsotropicTest(StrictModel):
    """Isotropic compression from the prepared state to pressure_final."""

    pressure_final: float = Field(1e6, gt=0, description="[Pa]")
    strain_rate: float = Field(0.05, gt=0, description="servo rate limit [1/s]")
    output_interval: float = Field(0.0005, gt=0, description="volumetric strain between rows")


class ShearTest(StrictModel):
    """Simple shear: gamma = 2 eps_xz rate given, normal stress on z servo-held."""

    normal_stress: float = Field(100e3, gt=0, description="[Pa]")
    shear_strain: float = Field(0.5, gt=0, le=20.0)
    strain_rate: float = Field(0.1, gt=0, description="shear rate d gamma/dt [1/s]")
    output_interval: float = Field(0.002, gt=0)


class RVECase(StrictModel):
    """A file for `grainscale rve ...`: the [rve] table and the element-test tables."""

    rve: RVEParams = RVEParams()
    triaxial: TriaxialTest = TriaxialTest()
    undrained: UndrainedTest = UndrainedTest()
    isotropic: IsotropicTest = IsotropicTest()
    shear: ShearTest = ShearTest()

"""Pydantic models of an MPM case file (TOML). Every table rejects unknown keys.

See docs/case-files.md for the reference of every key, with units. Cross-table checks
that need more than one table (a body's material exists, history columns are available,
points inside the grid, dt below the CFL limit) are done by `check_case` and by the
solver set-up, which raise ConfigError naming the key, the value and the valid range.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Literal

import tomli_w
from pydantic import Field, PrivateAttr, field_validator, model_serializer, model_validator

from grainscale.config.base import ConfigError, StrictModel, load_toml, read_toml, validate
from grainscale.config.rve import (
    IsotropicTest,
    RVECase,
    RVEParams,
    ShearTest,
    TriaxialTest,
    UndrainedTest,
    check_particles,
)

Vec3 = tuple[float, float, float]
Pos = Annotated[float, Field(gt=0)]
NonNeg = Annotated[float, Field(ge=0)]
Axis = Literal["x", "y", "z"]
Face = Literal["x-", "x+", "y-", "y+", "z-", "z+"]
FLIP_DEFAULT = 0.99  # solver.flip when velocity_update = "flip" and no flip is given
STRAIN_PER_SUBSTEP = 3e-6  # quasi-static RVEs: strain per DEM step, undamped (validation §3.1)


SLEEP_TOLERANCE_MAX = 3e-5  # dynamic RVEs: the largest update_tolerance (docs/coupling.md)


def default_update_tolerance(time_integration: str, strain_per_substep: float) -> float:
    """A dem material's update_tolerance when none is given: one DEM step's strain for
    quasi-static RVEs (adaptive updates on), 0 for dynamic ones (no RVE sleeps)."""
    return strain_per_substep if time_integration == "quasi_static" else 0.0


class GradedAxisCfg(StrictModel):
    """One axis of a rectilinear grid written concisely (mpm/grid.graded_axis):
    cells of `cell` over `fine`, growing by `ratio` per cell away from it, up to
    `max_cell`, scaled to end exactly at lo and hi."""
    lo: float  # m, first node
    hi: float  # m, last node
    cell: Pos  # m, the cell size over `fine`
    fine: tuple[float, float] | None = None  # m, the interval of cells `cell` (default [lo, hi])
    ratio: Annotated[float, Field(ge=1)] = 1.0  # size ratio of neighbouring cells outside it
    max_cell: Pos | None = None  # m, the largest cell (default: no limit)

    def nodes(self):
        from grainscale.mpm.grid import graded_axis

        lo, hi = self.fine if self.fine is not None else (self.lo, self.hi)
        return graded_axis(self.lo, self.hi, lo, hi, self.cell, self.ratio, self.max_cell)


NODE_KEYS = ("nodes_x", "nodes_y", "nodes_z")


class GridCfg(StrictModel):
    """A uniform grid (origin, cell_size, cells) or a rectilinear one (nodes_x, nodes_y,
    nodes_z: node coordinates, or a graded axis each)."""
    origin: Vec3 = (0.0, 0.0, 0.0)  # m, position of the first node
    cell_size: Pos | tuple[Pos, Pos, Pos] | None = None  # m, one value or one per axis
    cells: tuple[Annotated[int, Field(ge=1)], Annotated[int, Field(ge=1)],
                 Annotated[int, Field(ge=1)]] | None = None  # cells per axis
    nodes_x: list[float] | GradedAxisCfg | None = None  # m, increasing node coordinates
    nodes_y: list[float] | GradedAxisCfg | None = None
    nodes_z: list[float] | GradedAxisCfg | None = None
    periodic: list[Axis] = []  # axes along which material leaving one end re-enters

    @field_validator(*NODE_KEYS)
    @classmethod
    def _nodes(cls, v, info):
        if v is None:
            return v
        from grainscale.mpm.grid import check_nodes

        key = f"grid.{info.field_name}"
        try:
            check_nodes(v.nodes() if isinstance(v, GradedAxisCfg) else v, key)
        except ValueError as err:  # graded_axis names its own argument: add the key
            msg = str(err)
            raise ValueError(msg if msg.startswith(key) else f"{key}: {msg}") from None
        return v

    @model_validator(mode="after")
    def _one_form(self):
        lists = [k for k in NODE_KEYS if getattr(self, k) is not None]
        if lists:
            uniform = [k for k in ("cell_size", "cells") if getattr(self, k) is not None]
            if "origin" in self.model_fields_set:
                uniform.insert(0, "origin")
            if len(lists) != 3:
                missing = [k for k in NODE_KEYS if k not in lists]
                raise ValueError(f"grid.{lists[0]} is given but not grid.{missing[0]}: a "
                                 "rectilinear grid needs nodes_x, nodes_y and nodes_z")
            if uniform:
                raise ValueError(f"grid.{uniform[0]} with grid.nodes_x/y/z: give either "
                                 "origin, cell_size and cells (a uniform grid) or the node "
                                 "coordinates of each axis, not both")
            if self.periodic:  # the cells that meet across a periodic axis' ends
                from grainscale.mpm.grid import Grid

                try:
                    Grid.rectilinear(self.axes(), [a in self.periodic for a in "xyz"])
                except ValueError as err:
                    raise ValueError(f"grid.{err}") from None
        elif self.cell_size is None or self.cells is None:
            missing = "cell_size" if self.cell_size is None else "cells"
            raise ValueError(f"grid.{missing} is missing: a uniform grid needs cell_size and "
                             "cells (or give nodes_x, nodes_y and nodes_z)")
        return self

    @model_serializer(mode="wrap")
    def _no_origin_with_nodes(self, handler):
        # a rectilinear grid's origin is its first nodes: writing the default back would
        # make case.resolved.toml a case that _one_form refuses
        data = handler(self)
        if self.nodes_x is not None:
            data.pop("origin", None)
        return data

    def axes(self):
        """The node coordinates of each axis (3 arrays, m), or None for a uniform grid."""
        if self.nodes_x is None:
            return None
        import numpy as np

        return [np.asarray(v.nodes() if isinstance(v, GradedAxisCfg) else v, dtype=float)
                for v in (self.nodes_x, self.nodes_y, self.nodes_z)]

    def node_axes(self):
        """The node coordinates of each axis (3 arrays, m), uniform grids included (as
        the solver's Grid.node_axes computes them, without a periodic axis' padding)."""
        axes = self.axes()
        if axes is not None:
            return axes
        import numpy as np

        size = self.cell_size if isinstance(self.cell_size, tuple) else (self.cell_size,) * 3
        return [self.origin[k] + np.arange(self.cells[k] + 1) * float(size[k])
                for k in range(3)]

    def extent(self) -> tuple[list[float], list[float], list[int]]:
        """(first node, last node, cells) per axis."""
        axes = self.axes()
        if axes is not None:
            return ([float(a[0]) for a in axes], [float(a[-1]) for a in axes],
                    [len(a) - 1 for a in axes])
        size = self.cell_size if isinstance(self.cell_size, tuple) else (self.cell_size,) * 3
        return (list(self.origin),
                [o + n * h for o, n, h in zip(self.origin, self.cells, size, strict=True)],
                list(self.cells))


class SolverCfg(StrictModel):
    scheme: Literal["USF", "USL", "MUSL"] = "USF"
    shape: Literal["GIMP", "linear"] = "GIMP"
    # point velocity update: "apic" (affine PIC), "flip" (the FLIP/PIC blend of `flip`,
    # whose PIC share dissipates once per step, so by an amount that depends on dt), or
    # "aflip" (APIC's affine transfer with FLIP's increment, blended by `flip`)
    velocity_update: Literal["apic", "flip", "aflip"] = "apic"
    # "flip" and "aflip" only; default FLIP_DEFAULT ("flip") or 1.0 ("aflip")
    flip: Annotated[float, Field(ge=0, le=1)] | None = None
    # "flip" and "aflip" only, instead of `flip`: the PIC (APIC) share set per unit time,
    # flip = exp(-dt / velocity_relaxation_time) each step, so that a point's velocity
    # relaxes toward the grid's field at a rate that does not depend on dt [s]
    velocity_relaxation_time: Pos | None = None
    cfl: Annotated[float, Field(gt=0, le=1)] = 0.5
    dt: Pos | None = None  # s; fixed step (checked against the CFL limit); default: CFL
    gravity: Vec3 = (0.0, 0.0, 0.0)  # m/s^2
    threads: Annotated[int, Field(ge=0)] = 0  # per rank; 0: the cores / ranks per node
    partition_seed: Annotated[int, Field(ge=0)] = 0  # random point-to-rank assignment (MPI)
    rebalance_every: Annotated[int, Field(ge=0)] = 0  # steps between cost rebalancing; 0: never
    # where the DEM RVEs of "dem" materials are stepped: "cpu" (numba threads) or "cuda"
    # (one NVIDIA GPU per process, dem/cuda_kernel.py; agrees with "cpu" at round-off)
    device: Literal["cpu", "cuda"] = "cpu"

    @model_validator(mode="after")
    def _flip(self):
        tau = self.velocity_relaxation_time
        if tau is not None and self.velocity_update == "apic":
            raise ValueError(
                f"velocity_relaxation_time = {tau} applies to velocity_update = 'flip' or "
                f"'aflip' only, and velocity_update = 'apic' (the default); add "
                "velocity_update = \"aflip\", or remove velocity_relaxation_time")
        if tau is not None and self.flip is not None:
            raise ValueError(
                f"flip = {self.flip} and velocity_relaxation_time = {tau}: give one, the "
                "FLIP share per step (flip) or the relaxation time that sets it per unit "
                "time (flip = exp(-dt / velocity_relaxation_time))")
        if tau is not None:
            return self
        if self.velocity_update != "apic" and self.flip is None:
            self.flip = FLIP_DEFAULT if self.velocity_update == "flip" else 1.0
        elif self.velocity_update == "apic" and self.flip is not None:
            raise ValueError(
                f"flip = {self.flip} applies to velocity_update = 'flip' or 'aflip' only, "
                f"and velocity_update = {self.velocity_update!r} (the default is 'apic'); "
                "add velocity_update = \"flip\" to keep the FLIP/PIC blend, or remove "
                "`flip`")
        return self


class TimeCfg(StrictModel):
    start: float = 0.0  # s; negative to run an initialisation stage before t = 0
    end: float  # s

    @model_validator(mode="after")
    def _order(self):
        if not self.end > self.start:
            raise ValueError(f"time.end = {self.end} must be > time.start = {self.start}")
        return self


class _Elastic(StrictModel):
    density: Pos  # kg/m^3
    youngs_modulus: Pos  # Pa
    poisson_ratio: Annotated[float, Field(ge=0, lt=0.5)]


class LinearElasticCfg(_Elastic):
    type: Literal["linear_elastic"]


class _Frictional(_Elastic):
    friction_angle: Annotated[float, Field(gt=0, lt=90)]  # deg
    dilation_angle: Annotated[float, Field(ge=0, lt=90)] = 0.0  # deg, <= friction angle
    cohesion: NonNeg = 0.0  # Pa
    tension_cutoff: NonNeg = 0.0  # Pa (capped at the apex tension)

    @field_validator("dilation_angle")
    @classmethod
    def _psi(cls, v, info):
        phi = info.data.get("friction_angle")
        if phi is not None and v > phi:
            raise ValueError(f"must be <= friction_angle ({phi})")
        return v


class MohrCoulombCfg(_Frictional):
    type: Literal["mohr_coulomb"]


class DruckerPragerCfg(_Frictional):
    type: Literal["drucker_prager"]


class MuICfg(_Elastic):
    """mu(I) rheology (Jop et al. 2006); `density` is the bulk density of the flowing
    material, E and nu those of the elastic predictor (mpm/materials/mu_i.py)."""

    type: Literal["mu_i"]
    mu_s: Pos  # -, friction coefficient of the onset of flow (I -> 0)
    mu_2: Pos  # -, limit friction coefficient at large I, > mu_s
    I_0: Pos  # -, inertial number where mu is halfway from mu_s to mu_2
    grain_diameter: Pos  # m
    grain_density: Pos  # kg/m^3, solid density of the grains, >= density
    # how separated grains (zero pressure) touch again: on the first compression, or once
    # the volume opened while separated is closed (mpm/materials/mu_i.py)
    separation: Literal["reset", "recompact"] = "reset"

    @field_validator("mu_2")
    @classmethod
    def _mu_2(cls, v, info):
        mu_s = info.data.get("mu_s")
        if mu_s is not None and not v > mu_s:
            raise ValueError(f"must be > mu_s = {mu_s}")
        return v

    @field_validator("grain_density")
    @classmethod
    def _rho_s(cls, v, info):
        rho = info.data.get("density")
        if rho is not None and v < rho:
            raise ValueError(f"must be >= density = {rho} (the bulk density, grains and "
                             "voids)")
        return v


class NonlocalMuICfg(MuICfg):
    """mu(I) with nonlocal granular fluidity (Henann & Kamrin 2013; mpm/materials/
    fluidity.py): the parameters of mu_i plus the cooperativity's amplitude and time."""

    type: Literal["nonlocal_mu_i"]
    nonlocal_amplitude: Pos  # -, A: cooperativity length A d / sqrt|mu - mu_s|
    fluidity_time: Pos  # s, t_0 of the fluidity's relaxation; short against the flow


class DEMMaterialCfg(StrictModel):
    """The multiscale material: one periodic DEM RVE per point, from the case's [rve]."""

    type: Literal["dem"]
    # packing files (.txt exchange format or .h5 full state), relative to the case file;
    # empty: `library` packings are generated from [rve] with seeds rve.seed + k
    packings: list[str] = []
    library: Annotated[int, Field(ge=1, le=256)] = 1
    assignment_seed: Annotated[int, Field(ge=0)] = 0  # random packing-to-point assignment
    # a geostatic library: `library` packings prepared at each of these mean stresses
    # (Pa, ascending) instead of [rve.preparation] pressure; a point takes a packing of
    # the level nearest (in log) to its lithostatic mean stress rho g depth (1 + 2 k0) / 3,
    # depth below the material's highest point (coupling/materials.py)
    geostatic_pressures: list[Pos] = []
    geostatic_k0: Annotated[float, Field(gt=0, le=2)] = 0.5  # sigma_h / sigma_v at rest
    time_integration: Literal["dynamic", "quasi_static"] = "dynamic"
    # dynamic RVEs live in real time, where [rve] damping is an artificial viscosity: it
    # defaults to 0 for them and a value above 0 is refused unless allowed here (a
    # slow load, like the unit element's, compared with a pure-DEM test of the same
    # damping; it still lends strength in proportion to the rate, docs/coupling.md)
    allow_rve_damping: bool = False
    min_substeps: Annotated[int, Field(ge=1)] = 1  # DEM steps per MPM step, at least
    # quasi_static only: the RVE's strain per DEM step (docs/validation.md §3.1: the
    # cheapest undamped loading whose triaxial response is the slow limit's)
    strain_per_substep: Annotated[float, Field(gt=0, le=1e-3)] = STRAIN_PER_SUBSTEP
    # adaptive updates: an RVE whose accumulated increment since its last DEM update
    # (max |H_acc|) is below this is not stepped, its stress predicted with its affine
    # stiffness and turned with the accumulated rotation (docs/coupling.md); quasi_static
    # RVEs: at most strain_per_substep; dynamic RVEs (sleeping RVEs): at most
    # SLEEP_TOLERANCE_MAX, and only an RVE whose grains are at rest sleeps. 0: every RVE
    # every step. Default (None): strain_per_substep for quasi_static RVEs, 0 for dynamic
    update_tolerance: Annotated[float, Field(ge=0)] | None = None
    # ... and is stepped at least every this many MPM steps whatever its increment
    max_deferred_steps: Annotated[int, Field(ge=1, le=10_000)] = 20
    # an RVE cell narrower than this many mean grain diameters across a face pair is
    # doubled along that direction, grains repeated (dem/retile.py); 0: never
    retile_width: Annotated[float, Field(ge=0, le=20)] = 4.0
    # no RVE grows beyond this multiple of its packing's spheres by retiling
    retile_max_factor: Annotated[int, Field(ge=1, le=64)] = 8
    density: Pos | None = None  # kg/m^3; the packings' bulk density (set by the run)

    @field_validator("geostatic_pressures")
    @classmethod
    def _ascending(cls, v):
        if any(b <= a for a, b in zip(v, v[1:], strict=False)):
            raise ValueError(f"{v}: must be strictly ascending (Pa)")
        return v


MaterialCfg = Annotated[LinearElasticCfg | MohrCoulombCfg | DruckerPragerCfg | MuICfg
                        | NonlocalMuICfg | DEMMaterialCfg, Field(discriminator="type")]


class _Body(StrictModel):
    material: str  # name of a [materials.NAME] table
    points_per_cell: Annotated[int, Field(ge=1, le=8)] = 2  # n: n^3 points per cell
    velocity: Vec3 = (0.0, 0.0, 0.0)  # m/s, initial
    clip_to_grid: bool = False  # keep only the part inside the grid (symmetry models)


class BoxBody(_Body):
    shape: Literal["box"]
    lo: Vec3  # m
    hi: Vec3  # m


class CylinderBody(_Body):
    shape: Literal["cylinder"]
    center: Vec3  # m, centre of the base disc
    radius: Pos  # m
    height: Pos  # m, along +axis
    axis: Axis = "z"


class FileBody(_Body):
    shape: Literal["file"]
    path: str  # text file, one `x y z volume` per line; relative to the case file


BodyCfg = Annotated[BoxBody | CylinderBody | FileBody, Field(discriminator="shape")]


class NodeBoxCfg(StrictModel):
    lo: Vec3
    hi: Vec3


class BoundaryCfg(StrictModel):
    # fixed: no-slip; roller: normal velocity zero (bilateral unless separable);
    # velocity: normal velocity prescribed; friction: one-sided Coulomb wall
    type: Literal["fixed", "roller", "velocity", "friction"]
    face: Face | None = None  # a grid face ...
    box: NodeBoxCfg | None = None  # ... or the nodes inside a box
    normal: Axis | None = None  # roller in a box: the constrained component
    end_time: float | None = None  # s; removed at this time (default: never)
    velocity: float | None = None  # m/s; type "velocity": the normal component's value
    friction: NonNeg | None = None  # type "friction": Coulomb coefficient mu of the wall
    separable: bool = False  # roller: the material may leave the wall (one-sided)

    @model_validator(mode="after")
    def _where(self):
        if (self.face is None) == (self.box is None):
            raise ValueError("give exactly one of `face` or `box`")
        if (self.type == "friction") != (self.friction is not None):
            raise ValueError("`friction` (the wall's Coulomb coefficient) is given with, and "
                             "only with, type = 'friction'")
        if self.separable and self.type != "roller":
            raise ValueError(f"separable = true applies to type = 'roller' (type = "
                             f"{self.type!r}; a 'friction' wall is always one-sided)")
        if (self.type == "friction" or self.separable) and self.face is None:
            raise ValueError("a one-sided wall (type = 'friction', or a separable roller) "
                             "needs `face`: the material lies on the grid's side of it")
        if self.type in ("roller", "velocity") and self.box is not None and self.normal is None:
            raise ValueError(f"a {self.type} on a box of nodes needs `normal` ('x', 'y' or 'z')")
        if (self.type == "velocity") != (self.velocity is not None):
            raise ValueError("`velocity` (m/s) is given with, and only with, type = 'velocity'")
        return self


class TractionCfg(StrictModel):
    lo: Vec3  # m, box selecting the loaded points (their centres)
    hi: Vec3
    traction: Vec3  # Pa
    surface: Face  # side of the points carrying the load (outward normal), e.g. "x+"
    ramp_time: NonNeg = 0.0  # s, linear ramp from start_time
    start_time: float | None = None  # s; default time.start
    end_time: float | None = None  # s; default never
    area: Literal["current", "initial"] = "current"  # Cauchy (deformed) or nominal


class DampingCfg(StrictModel):
    alpha: Annotated[float, Field(ge=0, lt=1)] = 0.0  # Cundall local damping coefficient
    end_time: float | None = None  # s; default never


class _Rigid(StrictModel):
    points_per_cell: Annotated[int, Field(ge=1, le=8)] = 2
    clip_to_grid: bool = False  # keep only the part inside the grid (symmetry models)
    velocity: Vec3  # m/s, reached after ramp_time
    ramp_time: NonNeg = 0.0  # s
    start_time: float | None = None  # s; default time.start
    # nodes: velocity imposed on covered nodes (no slip, never separating); penalty: a
    # spring-dashpot on every point reaching into the exact shape (one-sided, frictional)
    contact: Literal["nodes", "penalty"] = "nodes"
    penalty: Annotated[float, Field(gt=0, le=4)] = 1.0  # kappa: x the point's own stiffness
    damping_ratio: Annotated[float, Field(ge=0, le=1)] = 0.0  # zeta of the normal dashpot
    friction: NonNeg = 0.0  # Coulomb coefficient of the body's surface (penalty)

    @model_validator(mode="after")
    def _contact_keys(self):
        if self.contact == "nodes":
            for key, default in (("penalty", 1.0), ("damping_ratio", 0.0), ("friction", 0.0)):
                if getattr(self, key) != default:
                    raise ValueError(f"{key} = {getattr(self, key)} applies to contact = "
                                     "'penalty' only (contact = 'nodes' is no-slip)")
        return self


class RigidBoxCfg(_Rigid):
    shape: Literal["box"]
    lo: Vec3
    hi: Vec3


class RigidCylinderCfg(_Rigid):
    shape: Literal["cylinder"]
    center: Vec3
    radius: Pos
    height: Pos
    axis: Axis = "z"


RigidCfg = Annotated[RigidBoxCfg | RigidCylinderCfg, Field(discriminator="shape")]


class ColumnCfg(StrictModel):
    """Geometry of a column collapse, for the runout columns of history.csv."""
    length: Pos  # m, initial length L_i
    height: Pos  # m, initial height H_i
    wall: float = 0.0  # m, coordinate of the back wall along flow_axis
    base: float = 0.0  # m, coordinate of the floor along up_axis
    flow_axis: Axis = "x"
    up_axis: Axis = "z"
    front_quantile: Annotated[float, Field(gt=0, le=1)] = 1.0  # 1: outermost point edge
    # m; > 0 adds front_thick and runout_ratio_thick: the far end of the deposit where it
    # is at least this thick (a front that ignores a thinner tail)
    min_thickness: NonNeg = 0.0


HISTORY_ALWAYS = ("time", "dt", "kinetic_energy", "axial_strain", "volumetric_strain", "p",
                  "q", "q_over_p")
HISTORY_DEM = ("porosity", "coordination", "mean_rotation")
# the mean over a run's RVEs of the DEM steps and of the updates each has taken since the
# run began (cumulative: their differences between rows give the cost of that interval)
HISTORY_COST = ("dem_steps_per_rve", "updates_per_rve")
HISTORY_COLUMN = ("t_over_tc", "runout_ratio", "height_ratio", "front", "column_height",
                  "front_thick", "runout_ratio_thick")
HISTORY_RIGID = ("rigid_fx", "rigid_fy", "rigid_fz", "rigid_depth", "depth", "force",
                 "depth_over_R", "force_normalized", "bearing_pressure")
# with a rigid body and one periodic axis across its motion (plane strain)
HISTORY_PLANE = ("force_per_length",)


class ProbeCfg(StrictModel):
    """An RVE written in full (spheres, contacts, cell) at every frame time: that of the
    material point of a 'dem' material nearest `position` at the start, followed as it
    moves (coupling/probes.py)."""
    position: Vec3  # m, inside the grid
    # file names probe_NAME_...; default probe0, probe1, ... (the index in the list)
    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9_-]+$", max_length=64)] | None = None


class OutputCfg(StrictModel):
    interval: Pos  # s, between history rows (and frames)
    frame_interval: Pos | None = None  # s; default: interval
    frames: bool = True  # write VTK frames
    checkpoint_every: Annotated[int, Field(ge=0)] = 0  # steps; 0: no checkpoints
    history: list[str] = ["time", "kinetic_energy"]  # columns after `step`
    axial_axis: Axis = "z"  # axial_strain = 1 - mean F_aa along this axis
    column: ColumnCfg | None = None
    probes: list[ProbeCfg] = []  # [[output.probes]]: RVEs written at every frame time

    @model_validator(mode="after")
    def _probe_names(self):
        for i, p in enumerate(self.probes):
            if p.name is None:
                p.name = f"probe{i}"  # written so in case.resolved.toml
        return self


class Case(StrictModel):
    title: str = ""
    grid: GridCfg
    solver: SolverCfg = SolverCfg()
    time: TimeCfg
    materials: dict[str, MaterialCfg]
    bodies: Annotated[list[BodyCfg], Field(min_length=1)]
    boundaries: list[BoundaryCfg] = []
    tractions: list[TractionCfg] = []
    damping: DampingCfg = DampingCfg()
    rigid: RigidCfg | None = None
    output: OutputCfg
    # the DEM side (multiscale cases): the RVE of the "dem" materials, and element tests
    # of the same RVE for `grainscale rve triaxial CASE.toml` and friends
    rve: RVEParams | None = None
    triaxial: TriaxialTest | None = None
    undrained: UndrainedTest | None = None
    isotropic: IsotropicTest | None = None
    shear: ShearTest | None = None
    # the folder relative paths (packings, points files) resolve against: the case
    # file's, for a case loaded by grainscale.load_case
    _case_dir: Path | None = PrivateAttr(default=None)

    def check(self) -> Case:
        """A validated copy of this (edited) case.

        Every table is re-read as from a file, then the cross-table checks are done, as
        `grainscale run` does; `grainscale.run` checks a Case the same way before any
        computation.

        Returns
        -------
        Case
            The validated copy (relative paths still resolve against the case file's
            folder).

        Raises
        ------
        ConfigError
            Naming the key, the value and the valid range.

        Examples
        --------
        >>> import grainscale as gs
        >>> case = gs.load_case("examples/unit_element/case.toml")
        >>> case.materials["sand"].library = 4
        >>> case = case.check()
        """
        fresh = validate(Case, self.model_dump(mode="json", exclude_unset=True))
        check_case(fresh)
        fresh._case_dir = self._case_dir
        return fresh

    def edited(self, change: Callable[[dict], object]) -> Case:
        """A validated copy of this case after `change(tables)` edits its tables in place.

        For edits that replace or remove whole tables, which assignment cannot.

        Parameters
        ----------
        change : callable
            ``change(tables)`` edits, in place, the keys given or edited as nested dicts
            and lists, as in the TOML; what it returns is ignored.

        Returns
        -------
        Case
            The validated copy.

        Raises
        ------
        ConfigError
            As check(): naming the key, the value and the valid range.

        Examples
        --------
        >>> import grainscale as gs
        >>> case = gs.load_case("examples/unit_element/case.toml")
        >>> def no_probes(t):
        ...     t["output"].pop("probes", None)
        >>> case = case.edited(no_probes)
        """
        tables = self.model_dump(mode="json", exclude_unset=True, exclude_none=True)
        change(tables)
        fresh = validate(Case, tables)
        check_case(fresh)
        fresh._case_dir = self._case_dir
        return fresh

    def continuum_twin(self, material: dict, title: str | None = None) -> Case:
        """The same case with every material replaced by the continuum `material`.

        The twin of a multiscale run that a phenomenological law gives
        (docs/validation.md §2.3, §3): the same grid, bodies, boundaries, rigid body,
        solver and output, without the DEM side ([rve] and the element tests, the
        probes, the DEM-only history columns, checkpoints).

        Parameters
        ----------
        material : dict
            A [materials.X] table as a dict, e.g. type = "mohr_coulomb" or "mu_i"
            (docs/case-files.md); it takes the first material's name.
        title : str, optional
            The twin's title (default: this case's).

        Returns
        -------
        Case
            The validated twin.

        Raises
        ------
        ConfigError
            If `material` is of type "dem", or the twin is not a valid case (naming the
            key, the value and the valid range).

        Examples
        --------
        >>> import grainscale as gs
        >>> case = gs.load_case("examples/column_collapse/quick.toml")
        >>> twin = case.continuum_twin(
        ...     {"type": "mohr_coulomb", "density": 1600.0, "youngs_modulus": 10e6,
        ...      "poisson_ratio": 0.3, "friction_angle": 20.0}, title="Mohr-Coulomb twin")
        >>> result = gs.run(twin, "quick_mc")
        """
        if material.get("type") == "dem":
            raise ConfigError("continuum_twin: material.type = 'dem': give a continuum "
                              "(mohr_coulomb, mu_i, ...)")

        def change(t: dict) -> None:
            name = next(iter(t["materials"]))
            t["materials"] = {name: dict(material)}
            for key in ("rve", "triaxial", "undrained", "isotropic", "shear"):
                t.pop(key, None)
            out = t["output"]
            out.pop("probes", None)
            out["checkpoint_every"] = 0
            if "history" in out:
                out["history"] = [c for c in out["history"]
                                  if c not in HISTORY_DEM + HISTORY_COST]
            if title is not None:
                t["title"] = title

        return self.edited(change)

    def save(self, path) -> Path:
        """Write the case as TOML that load_case reads back to the same case.

        The keys given or edited are written, not the defaults (case.resolved.toml in a
        run's folder has those). Relative paths are written as they are: save beside the
        original file to keep them valid.

        Parameters
        ----------
        path : str or pathlib.Path
            The TOML file to write.

        Returns
        -------
        pathlib.Path
            `path`.

        Examples
        --------
        >>> import grainscale as gs
        >>> case = gs.load_case("examples/column_collapse/mohr_coulomb.toml")
        >>> case.time.end = 0.1
        >>> case.save("examples/column_collapse/mohr_coulomb_short.toml")
        """
        path = Path(path)
        path.write_text(tomli_w.dumps(self.model_dump(mode="json", exclude_unset=True,
                                                      exclude_none=True)))
        return path


def check_case(case: Case) -> None:
    """Cross-table checks; ConfigError names key, value and what is valid."""
    names = sorted(case.materials)
    for name, m in case.materials.items():
        if m.type == "dem" and case.rve is None:
            raise ConfigError(f"materials.{name}.type = 'dem' needs an [rve] table for the "
                              "contact parameters of its packings")
        if m.type == "dem" and m.density is not None:
            raise ConfigError(f"materials.{name}.density = {m.density}: a 'dem' material's "
                              "density is that of its packings; remove the key")
        if m.type == "dem" and m.geostatic_pressures:
            if m.packings:
                raise ConfigError(f"materials.{name}.geostatic_pressures = "
                                  f"{m.geostatic_pressures}: the geostatic library is "
                                  "generated from [rve]; valid with packings = [] only "
                                  f"(packings = {m.packings})")
            if not any(case.solver.gravity):
                raise ConfigError(f"materials.{name}.geostatic_pressures = "
                                  f"{m.geostatic_pressures}: needs gravity to give depth "
                                  f"a stress (solver.gravity = {list(case.solver.gravity)})")
    dynamic = [n for n, m in case.materials.items()
               if m.type == "dem" and m.time_integration == "dynamic"]
    quasi_static = [n for n, m in case.materials.items()
                    if m.type == "dem" and m.time_integration == "quasi_static"]
    if case.rve is not None and any(not case.materials[n].packings
                                    for n in dynamic + quasi_static):
        check_particles(case.rve)  # packings to generate: before any generation starts
    for name in dynamic + quasi_static:
        m = case.materials[name]
        if m.update_tolerance is None:  # written so in case.resolved.toml, but still a
            # default: a case written back without its defaults (exclude_unset) follows
            # the time integration and strain per DEM step it is given
            m.update_tolerance = default_update_tolerance(m.time_integration,
                                                          m.strain_per_substep)
            m.__pydantic_fields_set__.discard("update_tolerance")
    for name in quasi_static:
        m = case.materials[name]
        if m.update_tolerance > m.strain_per_substep:
            raise ConfigError(
                f"materials.{name}.update_tolerance = {m.update_tolerance}: above "
                f"strain_per_substep = {m.strain_per_substep}; valid: 0 to "
                "strain_per_substep (a composed increment owes as many DEM steps as its "
                "parts, so a larger tolerance saves nothing and adds error: "
                "docs/coupling.md)")
    for name in dynamic:
        if case.materials[name].update_tolerance > SLEEP_TOLERANCE_MAX:
            raise ConfigError(
                f"materials.{name}.update_tolerance = "
                f"{case.materials[name].update_tolerance}: above {SLEEP_TOLERANCE_MAX:g} for "
                f"dynamic RVEs; valid: 0 to {SLEEP_TOLERANCE_MAX:g} (a sleeping RVE's stress "
                "is predicted over the strain it owes; docs/coupling.md)")
    if (dynamic or quasi_static) and case.rve is not None:
        # local damping lends the RVE strength in proportion to its loading rate, in
        # real time and under the quasi-static loading alike (docs/validation.md §3.1)
        if "damping" not in case.rve.model_fields_set:
            case.rve.damping = 0.0  # written so in case.resolved.toml
        elif case.rve.damping > 0:
            for name in dynamic:
                if not case.materials[name].allow_rve_damping:
                    raise ConfigError(
                        f"rve.damping = {case.rve.damping} with materials.{name}."
                        "time_integration = 'dynamic': in a real-time RVE local damping "
                        "acts as an artificial viscosity (docs/coupling.md); valid: 0, or "
                        f"set materials.{name}.allow_rve_damping = true for a slow load "
                        "(it lends strength in proportion to the rate)")
    for i, b in enumerate(case.bodies):
        if b.material not in case.materials:
            raise ConfigError(f"bodies[{i}].material = {b.material!r}: no such material; "
                              f"defined: {names}")
    cells = case.grid.extent()[2]
    if case.solver.shape == "GIMP" and min(cells) < 2:
        raise ConfigError(f"grid.cells = {cells}: GIMP needs >= 2 cells per axis (or use "
                          "solver.shape = 'linear')")
    for i, bc in enumerate(case.boundaries):
        if bc.face is not None and bc.face[0] in case.grid.periodic:
            raise ConfigError(f"boundaries[{i}].face = {bc.face!r}: grid.periodic = "
                              f"{case.grid.periodic} has no {bc.face[0]} faces; valid faces: "
                              "those of the other axes")
    valid = list(HISTORY_ALWAYS)
    if case.output.column is not None:
        valid += HISTORY_COLUMN
    if case.rigid is not None:
        valid += HISTORY_RIGID
        if len(case.grid.periodic) == 1:
            valid += HISTORY_PLANE
    if any(m.type == "dem" for m in case.materials.values()):
        valid += HISTORY_DEM + HISTORY_COST
    sectioned = {"bearing_pressure", "force_per_length"} & set(case.output.history)
    if case.rigid is not None and sectioned:
        v = case.rigid.velocity
        along = [a for a, c in zip("xyz", v, strict=True) if c != 0.0]
        if len(along) != 1 or along[0] in case.grid.periodic:
            raise ConfigError(f"output.history has {sorted(sectioned)}, which refer to the "
                              "rigid body's section normal to its motion (and the model's "
                              f"thickness along grid.periodic = {case.grid.periodic}): "
                              f"rigid.velocity = {list(v)} must lie along one grid axis, "
                              "not a periodic one")
    normalised = {"depth_over_R", "force_normalized"} & set(case.output.history)
    if case.rigid is not None and normalised:
        v = case.rigid.velocity
        if sum(c != 0.0 for c in v) != 1 or not any(case.solver.gravity):
            raise ConfigError(f"output.history has {sorted(normalised)}, which refer to the "
                              f"rigid body's cross-section normal to its motion and to "
                              f"gravity: rigid.velocity = {list(v)} must lie along one grid "
                              f"axis and solver.gravity = {list(case.solver.gravity)} must "
                              "not be zero")
    for i, c in enumerate(case.output.history):
        if c not in valid:
            raise ConfigError(f"output.history[{i}] = {c!r}: not an available column; valid: "
                              f"{valid} (runout columns need [output.column], rigid_* need "
                              "[rigid], porosity/coordination/mean_rotation a 'dem' material)")
    thick = {"front_thick", "runout_ratio_thick"} & set(case.output.history)
    if thick and case.output.column.min_thickness <= 0.0:
        raise ConfigError(f"output.history has {sorted(thick)}, which need "
                          "output.column.min_thickness > 0 (m, the thickness the deposit "
                          f"must have at the front); it is {case.output.column.min_thickness}")
    if "t_over_tc" in case.output.history and not any(case.solver.gravity):
        raise ConfigError("output.history contains 't_over_tc' but solver.gravity = "
                          f"{list(case.solver.gravity)}: tau_c = sqrt(H/g) needs gravity")
    for k in ("start", "end"):
        if not math.isfinite(getattr(case.time, k)):
            raise ConfigError(f"time.{k} = {getattr(case.time, k)}: must be finite")
    _check_probes(case)


def _check_probes(case: Case) -> None:
    """[[output.probes]]: a 'dem' material exists, positions inside the grid, names
    unique. Which point each probe shows is resolved with the points (coupling/probes)."""
    probes = case.output.probes
    if not probes:
        return
    if not any(m.type == "dem" for m in case.materials.values()):
        kinds = {n: m.type for n, m in case.materials.items()}
        raise ConfigError(f"output.probes[0].position = {list(probes[0].position)}: a probe "
                          "shows the RVE of a material point of a 'dem' material, and this "
                          f"case has none (materials: {kinds}); valid: a case with a "
                          "material of type = 'dem', or no [[output.probes]]")
    lo, hi, _ = case.grid.extent()
    first: dict[str, int] = {}
    for i, p in enumerate(probes):
        if not all(a <= x <= b for a, x, b in zip(lo, p.position, hi, strict=True)):
            raise ConfigError(f"output.probes[{i}].position = {list(p.position)}: outside the "
                              f"grid; valid range {lo} .. {hi} (the grid's first and last "
                              "nodes)")
        if p.name in first:
            raise ConfigError(f"output.probes[{i}].name = {p.name!r}: already the name of "
                              f"output.probes[{first[p.name]}] (unnamed probes are called "
                              "probe0, probe1, ... by their index); valid: a name no other "
                              f"probe has, not one of {sorted(first)}")
        first[p.name] = i


def load_case(path) -> Case:
    """Read, validate and cross-check a case file.

    Relative paths in it (packings, points files) resolve against its folder, also when
    the case is edited and run from Python.

    Parameters
    ----------
    path : str or pathlib.Path
        The case file (TOML, docs/case-files.md).

    Returns
    -------
    Case
        The validated case.

    Raises
    ------
    ConfigError
        If the file is missing or not TOML, or a key is invalid (naming the key, the
        value and the valid range, as `grainscale run` reports it).

    Examples
    --------
    >>> import grainscale as gs
    >>> case = gs.load_case("examples/column_collapse/mohr_coulomb.toml")
    >>> case.materials["sand"].friction_angle = 25.0  # validated on assignment
    >>> case.time.end
    """
    case = load_toml(path, Case)
    check_case(case)
    case._case_dir = Path(path).resolve().parent
    return case


def load_rve_case(path) -> RVECase:
    """The [rve] and element-test tables of a file for `grainscale rve ...`.

    A full multiscale case file is accepted too (its other tables are validated as a
    case, so a typo anywhere is still reported), which lets the pure-DEM test of a case's
    RVE run from the very file of the multiscale run.
    """
    data = read_toml(path)
    mpm_tables = {"grid", "time", "materials", "bodies", "output"}
    if set(data) <= set(RVECase.model_fields) or not mpm_tables & set(data):
        return load_toml(path, RVECase)  # a pure RVE file: unknown tables named alone
    case = load_case(path)
    tables = {k: getattr(case, k) for k in RVECase.model_fields if getattr(case, k) is not None}
    return RVECase(**tables)

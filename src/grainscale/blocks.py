"""The solver's parts, for studies that a case file cannot express (docs/api.md:
grainscale.blocks): an MPM problem assembled by hand (a surcharge beside a footing, a
punch on a cube), one RVE driven through a deformation path as an MPM point drives it,
a run's checkpoint read back. Public and documented, but closer to the solver than
`grainscale.run`: their signatures follow the solver and may change between versions.

    from grainscale import blocks
    grid = blocks.Grid.make(origin=(0, 0, 0), cell_size=0.1, cells=(10, 1, 10))
    x, vol = blocks.fill_box(grid, (0, 0, 0), (1, 0.1, 0.5), 2)
    points = blocks.make_points(x, vol, 1600.0, 0)
    ...
    blocks.step(state, dt)
"""

from __future__ import annotations

from pathlib import Path

from grainscale.config.rve import RVEParams
from grainscale.coupling.checkpoints import MANIFEST
from grainscale.coupling.rve_material import RVEMaterial
from grainscale.dem.cell import perpendicular_widths
from grainscale.dem.state import (
    STATE_FIELDS,
    RVEBatch,
    concatenate,
    from_packing,
    from_state_arrays,
    state_arrays,
)
from grainscale.io.faults import ENV as FAULT_ENV
from grainscale.io.rve_h5 import read_rve_state
from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.materials import LinearElastic, MohrCoulomb
from grainscale.mpm.points import fill_box, make_points, sub_cell_half_widths
from grainscale.mpm.rigid import BOX, CYLINDER, RigidBody
from grainscale.mpm.step import MPMState, SimulationError, step


def latest_checkpoint(out: str | Path) -> tuple[dict, list[Path]]:
    """The newest valid checkpoint of a run's folder `out`.

    That is checkpoint.h5, else checkpoint.prev.h5 (docs/case-files.md, restart).

    Parameters
    ----------
    out : str or pathlib.Path
        The output folder of the run.

    Returns
    -------
    attrs : dict
        The checkpoint's attributes (step, time, parts, ...).
    parts : list of pathlib.Path
        Its per-rank part files, in rank order (HDF5: group `points` with x, F, ...;
        group `material_K` with the RVE states rve_h, rve_radius, rve_stress, ...).

    Raises
    ------
    ConfigError
        If no checkpoint in `out` is valid.
    """
    from grainscale.coupling import checkpoints
    from grainscale.distributed.comm import Comm

    out = Path(out)
    found = checkpoints.find(out, Comm(None))
    return dict(found.attrs), sorted((out / str(found.attrs["parts"])).glob("rank_*.h5"))


__all__ = [
    "BOX", "CYLINDER", "FAULT_ENV", "MANIFEST", "STATE_FIELDS", "Grid", "LinearElastic",
    "MPMState", "MohrCoulomb", "RVEBatch", "RVEMaterial", "RVEParams", "RigidBody",
    "SimulationError", "boundary", "concatenate", "fill_box", "from_packing",
    "from_state_arrays", "latest_checkpoint", "make_points", "perpendicular_widths",
    "read_rve_state", "state_arrays", "step", "sub_cell_half_widths",
]

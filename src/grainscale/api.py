"""The Python route to what `grainscale run` does: load and edit a case, run it, read
what it wrote (docs/api.md). The command line is built on the same functions, so a run
from Python and the same run from the command line write identical files.

    import grainscale as gs
    case = gs.load_case("examples/column_collapse/mohr_coulomb.toml")
    case.time.end = 0.2                      # validated on assignment; case.check() and
    result = gs.run(case, "out", max_steps=50)   # gs.run check the whole case
    result.history["kinetic_energy"][-1]
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grainscale.config.base import ConfigError
from grainscale.config.case import Case, load_case


class RunError(RuntimeError):
    """A run stopped by a simulation error (the CLI's exit code 1): its last checkpoint
    and everything written up to it stay in the output folder, for `resume=True`."""


@dataclass(frozen=True)
class Result:
    """What a run wrote into its folder `out`, read back."""

    out: Path

    @property
    def history(self) -> dict[str, np.ndarray]:
        """Each column of history.csv (docs/case-files.md) as an array, rows in order."""
        from grainscale.io.history import read_history

        return read_history(self.out / "history.csv")

    @property
    def cost(self) -> dict:
        """cost.json: steps, wall time, MPM/DEM split, particle-steps (docs/coupling.md);
        empty if the run took no step."""
        path = self.out / "cost.json"
        return json.loads(path.read_text()) if path.is_file() else {}

    @property
    def case(self) -> Case:
        """The case as run: case.resolved.toml, every default filled in."""
        from grainscale.config.base import read_toml, validate

        path = self.out / "case.resolved.toml"
        data = read_toml(path)
        data.pop("grainscale_version", None)
        return validate(Case, data, source=str(path))

    def frames(self) -> list[tuple[float, object]]:
        """The VTK frames of frames.pvd as (time [s], meshio.Mesh) with the point fields
        (stress, velocity, porosity, ... docs/case-files.md), in time order."""
        return self._series(self.out / "frames.pvd")

    def probe(self, name: str, kind: str = "spheres") -> list[tuple[float, object]]:
        """A probe RVE's series (`kind` "spheres", "contacts" or "cell") as (time [s],
        meshio.Mesh) pairs; the probes of the case are listed in probes.json."""
        kinds = ("spheres", "contacts", "cell")
        if kind not in kinds:
            raise ValueError(f"kind = {kind!r}: valid: {list(kinds)}")
        path = self.out / f"probe_{name}_{kind}.pvd"
        if not path.is_file():
            known = sorted(p.name for p in self.out.glob("probe_*_spheres.pvd"))
            raise ValueError(f"probe {name!r}: no {path.name} in {self.out} (found "
                             f"{[k[6:-12] for k in known]})")
        return self._series(path)

    @staticmethod
    def _series(pvd: Path) -> list[tuple[float, object]]:
        import meshio

        from grainscale.io.vtk import PVDSeries

        series = PVDSeries.load(pvd)
        return [(t, meshio.read(pvd.parent / f)) for t, f in series.entries]


def open_result(out: str | Path) -> Result:
    """The outputs of a finished or interrupted run in folder `out` (its history.csv is
    cut back to the rows of the last checkpoint only by a resume, so an interrupted run
    reads as far as it got)."""
    out = Path(out)
    if not (out / "history.csv").is_file():
        raise ValueError(f"{out}: no history.csv (not the output folder of a run)")
    return Result(out)


def run(case: Case | str | Path, out: str | Path, *, max_steps: int | None = None,
        steps_this_run: int | None = None, checkpoint_every: int | None = None,
        resume: bool = False, allow_changed: list[str] | None = None,
        threads: int | None = None, device: str | None = None,
        progress: bool = True, on_step: Callable[[object], None] | None = None) -> Result:
    """Run a case (a Case or a case file's path) into folder `out`, as `grainscale run`
    with the same options (README, docs/case-files.md) does; returns its Result.

    `on_step(state)`, if given, is called after every step with the solver's state
    (grainscale.blocks.MPMState), for studies that record what a run does not write; it
    must only read it.

    Raises ConfigError for an invalid case or option before any computation, RunError if
    a simulation error stops the run (the checkpoints stay: run again with resume=True).
    """
    from grainscale.coupling.driver import run_loaded_case

    if isinstance(case, (str, Path)):
        case = load_case(case)
    elif isinstance(case, Case):
        case = case.check()  # as a file is validated, edits included
    else:
        raise TypeError(f"case: a Case or a path, not {type(case).__name__}")
    out = Path(out)
    code = run_loaded_case(case, out, max_steps=max_steps,
                           steps_this_run=steps_this_run,
                           checkpoint_every=checkpoint_every, resume=resume,
                           allow_changed=allow_changed, progress=progress,
                           threads=threads, device=device, on_step=on_step)
    if code != 0:
        raise RunError(f"the run into {out} stopped with a simulation error (above); its "
                       "last checkpoint is kept: run again with resume=True")
    return Result(out)


__all__ = ["Case", "ConfigError", "Result", "RunError", "load_case", "open_result", "run"]

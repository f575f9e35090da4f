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
    """A run stopped by a simulation error (the CLI's exit code 1).

    Its last checkpoint and everything written up to it stay in the output folder, so the
    run can be continued with ``run(..., resume=True)``.

    See Also
    --------
    run : raises it.
    open_result : reads what the stopped run wrote, as far as it got.
    """


@dataclass(frozen=True)
class Result:
    """What a run wrote into its folder `out`, read back.

    Returned by `run` and `open_result`; every property and method reads the files anew.

    Attributes
    ----------
    out : pathlib.Path
        The output folder of the run.

    Examples
    --------
    >>> import grainscale as gs
    >>> r = gs.run("examples/column_collapse/mohr_coulomb.toml", "mc", max_steps=50,
    ...            progress=False)
    >>> r.history["kinetic_energy"][-1]
    >>> t, last = r.frames()[-1]
    >>> last.point_data["stress"].shape
    """

    out: Path

    @property
    def history(self) -> dict[str, np.ndarray]:
        """Each column of history.csv (docs/case-files.md) as an array, rows in order.

        Returns
        -------
        dict of str to numpy.ndarray
            Column name (``"time"``, ``"kinetic_energy"``, ``"runout_ratio"``, ...) to its
            values, one per history row.

        Raises
        ------
        ValueError
            If history.csv is missing or has a bad row (a last row cut short by a killed
            run is dropped, not an error).
        """
        from grainscale.io.history import read_history

        return read_history(self.out / "history.csv")

    @property
    def cost(self) -> dict:
        """cost.json: steps, wall time, MPM/DEM split, particle-steps (docs/coupling.md).

        Returns
        -------
        dict
            The contents of cost.json; empty if the run took no step (no cost.json).
        """
        path = self.out / "cost.json"
        return json.loads(path.read_text()) if path.is_file() else {}

    @property
    def case(self) -> Case:
        """The case as run: case.resolved.toml, every default filled in.

        Returns
        -------
        Case
            The validated case of case.resolved.toml.

        Raises
        ------
        ConfigError
            If case.resolved.toml is missing, not TOML or not a valid case.
        """
        from grainscale.config.base import read_toml, validate

        path = self.out / "case.resolved.toml"
        data = read_toml(path)
        data.pop("grainscale_version", None)
        return validate(Case, data, source=str(path))

    def frames(self) -> list[tuple[float, object]]:
        """The VTK frames of frames.pvd, in time order.

        Returns
        -------
        list of (float, meshio.Mesh)
            (time [s], frame) pairs; the point fields (stress, velocity, porosity, ...
            docs/case-files.md) are in ``mesh.point_data``. Empty if no frame was written.
        """
        return self._series(self.out / "frames.pvd")

    def probe(self, name: str, kind: str = "spheres") -> list[tuple[float, object]]:
        """A probe RVE's series of frames (probe_NAME_KIND.pvd).

        The probes of the case are listed in probes.json.

        Parameters
        ----------
        name : str
            The probe's name (``[[output.probes]]`` name; by default probe0, probe1, ...).
        kind : {"spheres", "contacts", "cell"}, default "spheres"
            Which of the probe's series to read.

        Returns
        -------
        list of (float, meshio.Mesh)
            (time [s], frame) pairs, in time order.

        Raises
        ------
        ValueError
            If `kind` is not one of the three, or the run wrote no such probe (the message
            lists the probes found).
        """
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
    """The outputs of a finished or interrupted run in folder `out`.

    A run's history.csv is cut back to the rows of the last checkpoint only by a resume,
    so an interrupted run reads as far as it got.

    Parameters
    ----------
    out : str or pathlib.Path
        The output folder of the run.

    Returns
    -------
    Result
        The run's outputs, read back.

    Raises
    ------
    ValueError
        If `out` holds no history.csv (it is not the output folder of a run).

    Examples
    --------
    >>> import grainscale as gs
    >>> r = gs.open_result("mc")
    >>> r.history["time"][-1]
    >>> t, last = r.frames()[-1]
    """
    out = Path(out)
    if not (out / "history.csv").is_file():
        raise ValueError(f"{out}: no history.csv (not the output folder of a run)")
    return Result(out)


def run(case: Case | str | Path, out: str | Path, *, max_steps: int | None = None,
        steps_this_run: int | None = None, checkpoint_every: int | None = None,
        resume: bool = False, allow_changed: list[str] | None = None,
        threads: int | None = None, device: str | None = None,
        progress: bool = True, on_step: Callable[[object], None] | None = None) -> Result:
    """Run a case into folder `out`, as `grainscale run` does.

    The options are those of `grainscale run` (README, docs/case-files.md): the command
    line calls this same code, so both write identical files. A Case is checked first as
    a file is (`Case.check`), edits included.

    Parameters
    ----------
    case : Case or str or pathlib.Path
        The case, or a case file's path (read with `load_case`).
    out : str or pathlib.Path
        The output folder.
    max_steps : int, optional
        End the run at this step, counted from time.start like time.end
        (``--max-steps``).
    steps_this_run : int, optional
        Take at most this many steps in this call, a per-job budget; continue later with
        ``resume=True`` (``--steps-this-run``).
    checkpoint_every : int, optional
        Write a checkpoint every this many steps, instead of the case's
        ``output.checkpoint_every`` (``--checkpoint-every``).
    resume : bool, default False
        Continue from the newest valid checkpoint in `out` (``--resume``).
    allow_changed : list of str, optional
        With `resume`: case keys (dotted, e.g. "solver.gravity", or a table such as
        "materials.soil") that may differ from the checkpoint's (``--allow-changed``).
    threads : int, optional
        Numba threads per process, instead of solver.threads (``--threads``).
    device : {"cpu", "cuda"}, optional
        Where the DEM RVEs of "dem" materials are stepped, instead of solver.device
        (``--device``).
    progress : bool, default True
        Show progress on stderr; False is the CLI's ``--quiet``.
    on_step : callable, optional
        ``on_step(state)`` is called after every step with the solver's state
        (grainscale.blocks.MPMState), for studies that record what a run does not write;
        it must only read it.

    Returns
    -------
    Result
        The outputs written into `out`.

    Raises
    ------
    ConfigError
        For an invalid case or option, before any computation.
    RunError
        If a simulation error stops the run (the checkpoints stay: run again with
        ``resume=True``). A signal (Ctrl-C, SIGTERM, SIGUSR1) is no error: the run stops
        at the next step with a checkpoint and returns what it wrote (continue with
        ``resume=True``); a second Ctrl-C raises KeyboardInterrupt at once.
    TypeError
        If `case` is neither a Case nor a path.

    Examples
    --------
    >>> import grainscale as gs
    >>> case = gs.load_case("examples/column_collapse/mohr_coulomb.toml")
    >>> case.time.end = 0.2
    >>> r = gs.run(case, "mc", max_steps=200, checkpoint_every=100)
    >>> r = gs.run(case, "mc", resume=True)  # on to the end
    >>> r.history["kinetic_energy"][-1]
    """
    from grainscale.coupling.driver import run_loaded_case
    from grainscale.coupling.stops import EXIT_STOPPED

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
    if code not in (0, EXIT_STOPPED):  # a stop by a signal returns what was written
        raise RunError(f"the run into {out} stopped with a simulation error (above); its "
                       "last checkpoint is kept: run again with resume=True")
    return Result(out)


def check(case: Case | str | Path, dem_steps: float | None = None) -> dict:
    """What a run of `case` would be, without running it (`grainscale check`): points and
    RVEs per material, MPM and DEM steps, RVE memory and an estimate of the DEM's wall
    time on this machine (coupling/dry_run.py; docs/case-files.md).

    Parameters
    ----------
    case : Case or str or pathlib.Path
        The case, or a case file's path.
    dem_steps : float, optional
        Assumed DEM steps per RVE and MPM step of quasi-static RVEs (default 4.6).

    Returns
    -------
    dict
        The figures `grainscale check` prints as JSON.

    Raises
    ------
    ConfigError
        For an invalid case, as `run` would.
    """
    from grainscale.coupling.dry_run import check as dry_run

    if isinstance(case, (str, Path)):
        case = load_case(case)
    elif not isinstance(case, Case):
        raise TypeError(f"case: a Case or a path, not {type(case).__name__}")
    return dry_run(case, dem_steps)


__all__ = ["Case", "ConfigError", "Result", "RunError", "check", "load_case", "open_result",
           "run"]

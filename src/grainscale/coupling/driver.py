"""`grainscale run`: load a case, build the solver, step it with progress, write outputs.

Outputs in --out: `case.resolved.toml` (every default filled in, package version),
`history.csv` (a row every output.interval, plus a final row when the run stops),
`grid.vtr` (the background grid, uniform or graded, for ParaView),
`frames/frame_NNNNN.vtu` + `frames.pvd` (and `frames/rigid_NNNNN.vtu` + `rigid.pvd`
for a rigid body), the probes' RVEs at the frame times (`probes.json`,
`frames/probe_NAME_NNNNN_*.vtu` + `probe_NAME_*.pvd`, coupling/probes.py), `cost.json`
(time per step split into MPM, DEM, communication, waiting and other), and a checkpoint
(coupling/checkpoints.py) every N steps and at the end of the run when checkpointing is
on (a new run first removes an earlier run's).
`--resume` continues from the newest valid one (a damaged one is skipped with a
warning) if the case still has its physics (checkpoints.check_case; --allow-changed
names keys that may differ): history rows and frames written after it are dropped, so
the continued run writes the same history.csv as an uninterrupted one, whatever moment
it was killed at (io/faults.py names those moments, for tests).

Under MPI (`mpiexec -n N grainscale run ...`) every rank runs this loop on the points it
owns; rank 0 writes the outputs from points gathered to it. A SimulationError on any
rank stops every rank cleanly in the same step (exit code 1); any other failure of a
rank aborts the whole job at once, so a job never hangs on a dead rank.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time as wallclock
import traceback
from collections.abc import Callable
from pathlib import Path

import numba
import numpy as np

from grainscale.config.base import ConfigError, resolved_toml
from grainscale.config.case import Case, load_case
from grainscale.coupling import checkpoints, cost
from grainscale.coupling import materials as dem_materials
from grainscale.coupling.outputs import gather, history_values, point_fields
from grainscale.coupling.probes import Probe, ProbeWriter, resolve
from grainscale.coupling.rebalance import rebalance
from grainscale.coupling.stops import EXIT_STOPPED, StopRequests
from grainscale.coupling.stops import name as signal_name
from grainscale.dem.engine import check_device
from grainscale.distributed.comm import Comm, world
from grainscale.io import faults
from grainscale.io.history import History, HistoryMismatch
from grainscale.io.progress import Progress
from grainscale.io.vtk import PVDSeries, write_grid_vtr, write_points_vtu
from grainscale.mpm.materials import KINDS
from grainscale.mpm.setup import build_state
from grainscale.mpm.step import MPMState, RemoteFailure, SimulationError, step


# --------------------------------------------------------------------------- run
def stand_in_state(case: Case, case_dir: Path) -> MPMState:
    """The solver's set-up of the case (grid, points, boundaries, probes' boxes: every
    check it makes) with stand-in materials, so no packing is generated."""
    probe = case.model_copy(deep=True)
    for m in probe.materials.values():
        if m.type == "dem":
            m.density = 1.0

    def stand_in(name, cfg, x, local=None):
        return KINDS["linear_elastic"](name, len(x), density=1.0, youngs_modulus=1.0,
                                       poisson_ratio=0.0)

    return build_state(probe, case_dir, material_factory=stand_in)


def check_geometry(case: Case, case_dir: Path) -> list[Probe]:
    """All checks of the solver set-up (points in the grid, boxes that select nodes, ...)
    before the packings of DEM materials are generated, which can take minutes; returns
    the points of the case's probes (coupling/probes.py)."""
    return resolve(case, stand_in_state(case, case_dir))


def set_threads(case: Case, threads: int | None, comm: Comm) -> None:
    """Numba threads per rank: --threads, else solver.threads, else (under MPI, unless
    NUMBA_NUM_THREADS is set) the cores of this node shared by its ranks."""
    n = threads or case.solver.threads
    if not n and comm.size > 1 and "NUMBA_NUM_THREADS" not in os.environ:
        n = max(1, len(os.sched_getaffinity(0)) // comm.node_ranks())
    if n:
        most = numba.config.NUMBA_NUM_THREADS  # fixed when numba started
        if n > most and comm.rank == 0:
            print(f"warning: {n} threads asked (--threads or solver.threads), but numba "
                  f"started with NUMBA_NUM_THREADS = {most}: running {most}; set "
                  f"NUMBA_NUM_THREADS={n} in the environment to use {n}", file=sys.stderr)
        numba.set_num_threads(min(n, most))


def prepare_materials(case: Case, case_dir: Path, out: Path, comm: Comm, progress: bool):
    """Packing libraries: rank 0 generates (or reads) and caches them, then the other
    ranks read the cache; a failure on rank 0 is raised on every rank."""
    factory = error = None
    if comm.root:
        try:
            out.mkdir(parents=True, exist_ok=True)
            factory = dem_materials.prepare(case, case_dir, out, progress)
        except ConfigError as err:
            error = str(err)
    error = comm.bcast(error)
    if error is not None:
        raise ConfigError(error)
    if not comm.root:
        factory = dem_materials.prepare(case, case_dir, out, progress=False)
    return factory


def run_case(case_path, out, **options) -> int:
    """Run a case file (`grainscale run`): run_loaded_case of the file's validated case,
    relative paths in it resolved against its folder."""
    return run_loaded_case(load_case(case_path), out, **options)


def run_loaded_case(case: Case, out, *, max_steps: int | None = None,
                    steps_this_run: int | None = None,
                    checkpoint_every: int | None = None, resume: bool = False,
                    allow_changed: list[str] | None = None,
                    progress: bool = True, threads: int | None = None,
                    device: str | None = None, comm: Comm | None = None,
                    on_step: Callable[[MPMState], None] | None = None) -> int:
    """Run a validated case (paths in it relative to the folder of the file it was loaded
    from, else the working folder); returns the exit code (0 done, 1 stopped by a
    simulation error, 3 stopped by a signal with a checkpoint: coupling/stops.py). The
    CLI and grainscale.run both end here.

    max_steps ends the run at that step of the whole run (counted from time.start, as
    time.end is a time of the whole run), so the same command given again with
    `resume` after any stop ends at the same step; steps_this_run caps the steps taken
    by this call alone (a per-job budget). `resume` continues from the newest valid
    checkpoint in `out` if its case matches, but for the keys named in allow_changed.
    `device` ("cpu" or "cuda") overrides solver.device, where the DEM RVEs are stepped;
    "cuda" without a usable GPU is a ConfigError (engine.DeviceError) before any work.
    `on_step(state)` is called on every rank after every step with the solver's state
    (grainscale.blocks.MPMState: time, step, points, the materials' RVEs, the last
    increment dH), to read, not to change.
    Input errors are raised as ConfigError, on every rank alike (the checks after the
    ranks start working are collective), so the job ends cleanly with one message."""
    comm = comm if comm is not None else world()
    case_dir = case._case_dir or Path.cwd()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: is a file; valid: a folder (new, or a run's to "
                          "--resume or replace)")
    created = not out.exists()  # removed again if an input error leaves it empty
    if device is not None:  # --device: recorded as the case's solver.device
        case.solver.device = device
    record = checkpoints.case_record(case)  # before the run fills in values
    set_threads(case, threads, comm)
    check_device(case.solver.device)
    if case.solver.device == "cuda" and comm.size > 1:
        from grainscale.dem.cuda_kernel import select_gpu

        select_gpu(comm.node_rank())  # the ranks of a node spread over its GPUs
    every = checkpoint_every if checkpoint_every is not None else case.output.checkpoint_every
    if allow_changed and not resume:
        raise ConfigError(f"--allow-changed {' '.join(allow_changed)}: applies only with "
                          "--resume (it names case keys that may differ from the checkpoint's)")
    found = None
    if resume:  # collective: every rank gets the same checkpoint, or the same error
        found = checkpoints.find(out, comm)
        checkpoints.check_case(found, record, list(allow_changed or []))
    probes = check_geometry(case, case_dir)  # every input check before long work
    try:
        return _run(case, record, case_dir, out, comm, max_steps, steps_this_run, every,
                    found, progress, probes, on_step)
    except ConfigError:
        if created and comm.root:
            _remove_if_empty(out)  # invalid input leaves no output folder behind
        raise  # raised by every rank (see above): printed once by rank 0
    except OSError as err:  # disk full, folder not writable: every file is written
        # atomically or cut back on resume, so the last checkpoint stays valid
        what = (f"the last checkpoint in {out} is intact: continue with --resume"
                if (out / checkpoints.MANIFEST).is_file() else
                f"no checkpoint in {out} yet: run again")
        print(f"grainscale: error: {err} (rank {comm.rank}); {what} once the cause is "
              "removed", file=sys.stderr)
        if comm.size > 1:  # the other ranks would wait for this one forever
            comm.abort(1)
            os._exit(1)
        return 1
    except BaseException:
        if comm.size > 1:  # the other ranks would wait for this one forever
            print(f"grainscale: rank {comm.rank} failed:", file=sys.stderr)
            traceback.print_exc()
            comm.abort(2)
            os._exit(2)  # if the MPI library returns from Abort
        raise


def _remove_if_empty(folder: Path) -> None:
    """Remove `folder` if it holds nothing but empty folders."""
    if any(p.is_file() for p in folder.rglob("*")):
        return
    shutil.rmtree(folder, ignore_errors=True)


# what a run writes besides history.csv and the checkpoints (module docstring); a new run
# removes an earlier run's, so that no frame of it is read as one of the new run's
EARLIER_OUTPUTS = ("frames/frame_*.vtu", "frames/rigid_*.vtu", "frames/probe_*.vtu",
                   "probe_*.pvd", "rigid.pvd", "probes.json", "cost.json")


def discard_outputs(out: Path) -> None:
    """Remove the frames, probe series and cost report an earlier run left in `out` (the
    patterns of EARLIER_OUTPUTS only: nothing else in the folder is touched)."""
    for pattern in EARLIER_OUTPUTS:
        for f in out.glob(pattern):
            f.unlink(missing_ok=True)


CHECKPOINT_SHARE = 0.8  # of the host memory available at the start a checkpoint may take


def host_memory() -> int:
    """Bytes of memory this machine has available now (MemAvailable; without
    /proc/meminfo, its physical memory)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _size(n: float) -> str:
    """Bytes for a message: '1.6 MB', '137.2 GB'."""
    return f"{n / 1e9:.1f} GB" if n >= 1e9 else f"{n / 1e6:.1f} MB"


def check_checkpoint_memory(s: MPMState, every: int, comm: Comm,
                            available: int | None = None) -> None:
    """Refuse, before the first step, a run whose checkpoints cannot be written: a
    checkpoint gathers each rank's RVE state on its host (for RVEs on a GPU, all of it,
    in chunks), and the ranks of a node write theirs at once, so a node's ranks (taken
    to hold alike) must fit CHECKPOINT_SHARE of the memory available (`available`,
    default host_memory()). ConfigError on every rank alike, with the sizes."""
    if not every:
        return
    need = sum(m.checkpoint_bytes() for m in s.materials if hasattr(m, "checkpoint_bytes"))
    node = need * comm.node_ranks()
    available = host_memory() if available is None else available
    worst = float(comm.max(np.array([node / max(available, 1)]))[0])
    if worst > CHECKPOINT_SHARE:
        raise ConfigError(
            f"output.checkpoint_every = {every} (--checkpoint-every): a checkpoint gathers "
            f"the RVEs' state on the host, {_size(need)} on this rank and "
            f"{_size(node)} on its node, which has {_size(available)} available "
            f"({worst:.0%} of it on the fullest node; at most {CHECKPOINT_SHARE:.0%} "
            "allowed); valid: 0 (no checkpoints), or the run spread over more nodes (MPI)")


def _run(case: Case, record: dict, case_dir: Path, out: Path, comm: Comm, max_steps,
         steps_this_run, every: int, found: checkpoints.Checkpoint | None,
         progress: bool, probes: list[Probe], on_step=None) -> int:
    root = comm.root
    progress = progress and root
    factory = prepare_materials(case, case_dir, out, comm, progress)
    s = build_state(case, case_dir, n_threads=numba.get_num_threads(),
                    material_factory=factory, comm=comm)
    for mat, ids in zip(s.materials, s.mat_points, strict=True):
        if hasattr(mat, "initial_stress") and getattr(mat, "n_rve", 0):
            s.points.stress[slice(None) if ids is None else ids] = mat.initial_stress()
    if found is None:  # before anything is written (a resume: once restored, below)
        check_checkpoint_memory(s, every, comm)
    if root:
        (out / "frames").mkdir(exist_ok=True)
        (out / "case.resolved.toml").write_text(resolved_toml(case))
        write_grid_vtr(out / "grid.vtr", s.grid.node_axes())

    columns = ["step", *case.output.history]
    o = case.output
    t0, t_end = case.time.start, case.time.end
    frame_dt = o.frame_interval or o.interval
    history = pvd = rigid_pvd = None
    resume = found is not None
    if resume:
        c = checkpoints.restore(found, s)
        check_checkpoint_memory(s, every, comm)  # the restored RVEs, before any write
        # output slots (a step can span several intervals) and what was actually written
        n_rows, n_frames = int(c["rows"]), int(c["frames"])
        last_row_step = int(c.get("last_row_step", -1))
        mismatch = None
        if root:
            try:
                history = History(out / "history.csv", columns, case.title,
                                  resume_rows=int(c["rows_written"]))
            except HistoryMismatch as err:
                mismatch = str(err)
        mismatch = comm.bcast(mismatch)  # every rank stops, none waits for rank 0
        if mismatch is not None:
            raise ConfigError(mismatch)
        if root:
            pvd = PVDSeries.load(out / "frames.pvd", keep=int(c["frames_written"]))
            rigid_pvd = PVDSeries.load(out / "rigid.pvd",
                                       keep=int(c["rigid_frames_written"]))
    else:
        n_rows = n_frames = 0
        last_row_step = -1
        if root:
            checkpoints.discard(out)  # an earlier run's: they do not match the new history
            discard_outputs(out)
            history = History(out / "history.csv", columns, case.title)
            pvd = PVDSeries(out / "frames.pvd")
            rigid_pvd = PVDSeries(out / "rigid.pvd")
    probe_writer = ProbeWriter(out, probes, comm, s.time if resume else None, progress)

    def write_row():
        view = gather(s)
        if view is not None:
            history.write(history_values(case, s, *view))

    def write_frame(k: int):
        probe_writer.write(s, k)  # collective, also without frames (output.frames)
        if not o.frames:
            return
        view = gather(s)
        if view is None:
            return
        f = out / "frames" / f"frame_{k:05d}.vtu"
        write_points_vtu(f, view[0].x, point_fields(*view))
        pvd.add(s.time, f)
        if s.rigid is not None:  # the body's points as their own series
            f = out / "frames" / f"rigid_{k:05d}.vtu"
            v = np.tile(s.rigid.velocity_at(s.time), (len(s.rigid.x), 1))
            write_points_vtu(f, s.rigid.x, {"velocity": v})
            rigid_pvd.add(s.time, f)
        faults.point("frame.written")

    def counters() -> dict[str, int]:
        written = {"rows_written": history.rows, "frames_written": len(pvd.entries),
                   "rigid_frames_written": len(rigid_pvd.entries)} if root else {}
        return {"rows": n_rows, "frames": n_frames, "last_row_step": last_row_step,
                **written}

    previous = found.manifest if resume else None  # this run's last valid checkpoint
    # the cost totals of the run up to the checkpoint resumed from (None: a checkpoint
    # written before they were kept)
    cost_before = None
    if resume and all(f"cost_{k}" in c for k in cost.KEYS):
        cost_before = {k: float(c[f"cost_{k}"]) for k in cost.KEYS}

    def cost_now() -> dict | None:
        """This invocation's cost totals so far (collective; rank 0 gets them)."""
        return cost.totals(s, steps_run + failed, step_seconds,
                           wallclock.perf_counter() - run_start, step_comm, step_wait)

    def save() -> None:
        nonlocal previous, saved_step
        if root:
            history.sync()  # on disk before the checkpoint counts its rows
        now = cost_now()  # the run's cost so far travels with the checkpoint
        totals = {} if now is None else {f"cost_{k}": v for k, v in
                                         cost.add(cost_before, now).items()}
        checkpoints.save(out, s, counters() | totals, record, previous)
        previous, saved_step = out / checkpoints.MANIFEST, s.step

    def due(n_done: int, interval: float) -> bool:
        return s.time >= t0 + n_done * interval - 1e-9 * interval

    fixed_dt = case.solver.dt
    balance_every = case.solver.rebalance_every if comm.size > 1 else 0
    balance = {"rebalances": 0}
    steps_run = 0
    saved_step = s.step if resume else -1
    code = 0
    bar = Progress(t0, t_end, s.time, s.step, progress)
    comm.bytes_reduced = 0
    step_comm = step_wait = 0.0  # inside the steps (not outputs', checkpoints')
    run_start = wallclock.perf_counter()
    step_seconds = 0.0
    stopped = 0  # the signal that stopped the run (coupling/stops.py), 0: none
    failed = 0  # 1: a step failed (its time and work count in the cost report)
    t_step = run_start
    stops = StopRequests().__enter__()
    faults.point("run.start")
    try:
        while True:
            faults.point("step.begin")
            # scheduled outputs at t0 + k * interval (the row of step 0 included)
            if due(n_rows, o.interval):
                write_row()
                faults.point("history.row")
                last_row_step = s.step
                while due(n_rows, o.interval):
                    n_rows += 1
            if (o.frames or probes) and due(n_frames, frame_dt):
                write_frame(n_frames)
                while due(n_frames, frame_dt):
                    n_frames += 1
            if every and s.step % every == 0 and s.step > 0 and steps_run > 0:
                save()
            if (s.time >= t_end - 1e-12 * (t_end - t0)
                    or (max_steps is not None and s.step >= max_steps)
                    or (steps_this_run is not None and steps_run >= steps_this_run)):
                break
            stopped = stops.requested(comm)  # collective: every rank stops here alike
            if stopped:
                break
            t_step = wallclock.perf_counter()
            c0, w0 = comm.comm_seconds, comm.wait_seconds
            limit = s.stable_dt()
            if fixed_dt is not None:
                if fixed_dt > limit:
                    raise SimulationError(f"step {s.step}: solver.dt = {fixed_dt} is above the "
                                          f"CFL limit {limit:.6g} s at t = {s.time:.6g} s")
                dt = fixed_dt
            else:
                dt = limit
            dt = min(dt, t_end - s.time)
            step(s, dt)
            if on_step is not None:
                on_step(s)
            faults.point("step.advanced")
            step_seconds += wallclock.perf_counter() - t_step
            step_comm += comm.comm_seconds - c0
            step_wait += comm.wait_seconds - w0
            steps_run += 1
            if balance_every and s.step % balance_every == 0:
                s, moved = rebalance(s, case, case_dir, factory, balance_every)
                balance = {"rebalances": balance["rebalances"] + 1,
                           "imbalance_before_last": moved["before"],
                           "imbalance_after_last": moved["after"]}
                faults.point("step.rebalanced")
            bar.update(dt, s.step)
        if (every or stopped) and saved_step != s.step:  # before the final row: a resume
            save()  # drops it
    except SimulationError as err:
        if not isinstance(err, RemoteFailure):  # the rank that failed reports the cause
            print(f"grainscale: error: {err}", file=sys.stderr)
        code = 1
        failed = 1
        step_seconds += wallclock.perf_counter() - t_step
    finally:
        stops.__exit__()
        bar.close()
    if code == 0 and last_row_step != s.step:
        write_row()  # final row (unscheduled)
    if root:
        history.close()
    faults.point("run.end")
    if steps_run + failed:
        now = cost_now()
        if root:
            extra = {**(balance if balance_every else {}), "resumed": resume}
            report = cost.cost_json(now, cost_before, bool(failed), extra)
            (out / "cost.json").write_text(json.dumps(report, indent=2) + "\n")
            if progress:
                print(cost.format_cost(report), file=sys.stderr)
    if stopped and code == 0:
        if root:
            print(f"grainscale: stopped at step {s.step} ({signal_name(stopped)}); the "
                  f"checkpoint in {out} holds it: continue with --resume", file=sys.stderr)
        return EXIT_STOPPED
    return code

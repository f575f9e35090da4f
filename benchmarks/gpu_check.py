"""The GPU check, one prepared script for a short lease of a GPU machine (issue: the GPU
path made real). Everything it measures goes to OUT/gpu_check.json, rewritten after each
section, so a run cut short still returns what it measured.

    python benchmarks/gpu_check.py --prepare gpu_inputs      # here, on the CPU: packings
    python benchmarks/gpu_check.py --inputs gpu_inputs --out OUT [--budget 420]

Sections, each timed and guarded (an error is recorded, the next section runs):
1. `env`: GPU, driver, numba and numba-cuda versions, CPU cores.
2. `tests`: tests/dem/test_cuda_kernel.py on the hardware (its "gpu" cases: the kernel
   against the CPU on tiny batches, the resident path against the per-call one bitwise,
   `grainscale run --device cuda` of the shrunk unit element and column against the CPU).
3. `throughput`: the resident kernel (dem/device_batch.py) as a run drives it, one MPM
   increment of axial strain per call, in ns per particle-step with transfers included,
   for RVEs of 150, 300 and 800 spheres at 1,000, 10,000 and 50,000 RVEs (as memory and
   the time budget allow) and block sizes 64, 128 and 256 on the 800-sphere RVE; per
   configuration also the bytes moved per RVE and call, the resident bytes per sphere,
   the time of a call of zero steps (launch and small copies: the per-MPM-step transfer
   cost), of a full pull (a checkpoint's), and the per-call path's time as a ratio.
4. `baseline` (with --baseline DIR, a copy of another version's src/): the throughput
   configurations --baseline-configs measured with that version's kernel in a subprocess,
   on the same GPU in the same lease, so that a change is judged as a ratio.
5. `profile` (with --profile SPHERESxRVESxTHREADS): Nsight Compute (ncu) on the batch
   kernel's second call of that configuration (the first compiles and builds lists):
   speed of light, occupancy, launch statistics, memory and compute workload, warp
   states; the report as text in OUT/ncu.txt.
6. `column`: examples/column_collapse/quick.toml for --steps MPM steps with --device cuda
   and on all CPU cores: wall time and DEM seconds per MPM step of each (cost.json).
7. `intrusion` (with --intrusion CASE...): each case (e.g. examples/intrusion/seed.toml,
   seed_quick.toml) run for --intrusion-steps MPM steps of its geostatic stage and, from
   time 0 with the geostatic stage left out (the intruder on the surface, the bed
   unsettled), of its intrusion, on each of --intrusion-devices; its library packings
   from INPUTS/<case name>/packings (--prepare-case). Per MPM step: wall, DEM and other
   seconds, DEM steps per RVE, bytes moved; the GPU's memory in use and the process's
   peak resident memory so far (earlier sections and stages included); the batch's list
   capacity and bytes per sphere; and the projected wall time of the whole run: each
   stage's span of simulated time over its last step's dt, times its median step after
   the first (which compiles). The intrusion's steps are measured at its start, in a bed
   that has not settled: a developed intrusion's DEM work per RVE differs (4.8 DEM
   steps per RVE and MPM step at d/R 2 on 150-sphere RVEs, docs/validation.md §3.4), so
   its projection is an estimate of unknown sign; the JSON says so.

On a machine without network (the lent GPU machines), the Python packages missing there
travel as wheels, with numpy 2.4: numba-cuda 0.30.4's compiler calls `np.row_stack`,
which numpy 2.5 removed. Figures of 2026-11-26 on an H100: docs/performance.md.

    python benchmarks/gpu_check.py --prepare-case examples/intrusion/seed.toml \
        --inputs gpu_inputs                                  # the case's library, on the CPU
    python benchmarks/gpu_check.py --inputs gpu_inputs --out OUT --skip tests throughput \
        column --intrusion examples/intrusion/seed.toml --intrusion-devices cuda

The packings (--prepare) are the unit element's recipe at 100 kPa (porosity 0.373),
sheared to 2 % axial strain so that contacts slide and lists churn, as in
dem_throughput.py; prepared on the CPU beforehand, since generating an 800-sphere RVE
takes minutes that a lease should not pay.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SIZES = (150, 300, 800)
COUNTS = (1_000, 10_000, 50_000)
BLOCKS = (64, 128, 256)


def prepare(folder: Path) -> None:
    """Generate the packings of SIZES and save their full state (npz) into folder; the
    quick column's packings are cached by `grainscale run ... --out folder/column
    --max-steps 1`."""
    from grainscale.config.rve import RVEParams
    from grainscale.dem import engine
    from grainscale.dem.generate import contact_params, generate
    from grainscale.dem.state import state_arrays

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from dem_throughput import shear_control

    folder.mkdir(parents=True, exist_ok=True)
    for n in SIZES:
        params = RVEParams(particles=n, preparation={"pressure": 100e3, "porosity": 0.373})
        t0 = time.perf_counter()
        base = generate(params)
        cp = contact_params(params)
        dt = engine.critical_dt(base, cp, params.numerics.timestep_safety)
        engine.advance(base, int(0.02 / (0.1 * dt) / 10), dt, cp, shear_control(base, 1.0))
        np.savez(folder / f"rve_{n}.npz", dt=dt, young=cp.young,
                 ratio=cp.stiffness_ratio, friction=cp.friction, damping=cp.damping,
                 skin=cp.skin, **state_arrays(base))
        print(f"{n} spheres: {time.perf_counter() - t0:.0f} s, capacity {base.capacity}, "
              f"longest row {int(base.nbr_count.max())}", flush=True)


def load(folder: Path, n: int):
    from grainscale.dem import engine
    from grainscale.dem.state import STATE_FIELDS, from_state_arrays

    z = np.load(folder / f"rve_{n}.npz")
    base = from_state_arrays({k: z[k] for k in STATE_FIELDS})
    cp = engine.ContactParams(float(z["young"]), float(z["ratio"]), float(z["friction"]),
                              float(z["damping"]), float(z["skin"]))
    return base, cp, float(z["dt"])


def tiled(base, count: int, rng):
    """count copies of a one-RVE batch, velocities perturbed by 1e-4 m/s (decorrelated)."""
    from dataclasses import fields

    from grainscale.dem.state import RVEBatch

    b = RVEBatch(**{f.name: np.repeat(getattr(base, f.name), count, axis=0)
                    for f in fields(RVEBatch)})
    b.v += rng.normal(0.0, 1e-4, b.v.shape)
    return b


class Report:
    def __init__(self, out: Path):
        self.out = out
        self.data: dict = {}
        out.mkdir(parents=True, exist_ok=True)

    def save(self) -> None:
        (self.out / "gpu_check.json").write_text(json.dumps(self.data, indent=1))

    def section(self, name, fn, *args):
        t0 = time.perf_counter()
        try:
            self.data[name] = fn(*args)
        except Exception as err:  # recorded; the next section still runs
            self.data[name] = {"error": f"{type(err).__name__}: {err}"}
        self.data.setdefault("seconds", {})[name] = round(time.perf_counter() - t0, 1)
        print(f"== {name}: {self.data['seconds'][name]} s", flush=True)
        self.save()


def env() -> dict:
    import numba
    from numba import cuda

    out = {"python": platform.python_version(), "numba": numba.__version__,
           "cpus": os.cpu_count()}
    try:
        import numba_cuda
        out["numba_cuda"] = getattr(numba_cuda, "__version__", "?")
    except ImportError:
        out["numba_cuda"] = None
    out["available"] = bool(cuda.is_available())
    dev = cuda.get_current_device()
    name = dev.name
    out["gpu"] = name.decode() if isinstance(name, bytes) else str(name)
    out["compute_capability"] = list(dev.compute_capability)
    out["sms"] = int(getattr(dev, "MULTIPROCESSOR_COUNT", 0))
    free, total = cuda.current_context().get_memory_info()
    out["memory_gb"] = [round(free / 1e9, 1), round(total / 1e9, 1)]
    smi = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version,clocks.max.sm",
                          "--format=csv,noheader"], capture_output=True, text=True)
    out["nvidia_smi"] = smi.stdout.strip()
    return out


def tests(budget: float) -> dict:
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "tests/dem/test_cuda_kernel.py", "-k", "not simulator",
                          "-o", "addopts="], cwd=ROOT, capture_output=True, text=True,
                         timeout=budget)
    tail = (run.stdout + run.stderr)[-4000:]
    return {"returncode": run.returncode, "tail": tail}


def measure(base, cp, dt, count: int, threads: int, steps: int, per_call: bool,
            regs: int | None = None) -> dict:
    """One configuration of the resident kernel (see the module docstring, 3.)."""
    from grainscale.dem import cuda_kernel, engine, kernel
    from grainscale.dem.device_batch import DeviceBatch

    cuda_kernel.THREADS = threads
    if regs is not None:
        cuda_kernel.MAX_REGISTERS = regs
    regs = getattr(cuda_kernel, "MAX_REGISTERS", None)  # a version without it: None
    batch = tiled(base, count, np.random.default_rng(0))
    dH = np.zeros((count, 3, 3))
    dH[:, 2, 2] = -0.1 * steps * dt  # one MPM increment of axial strain at 0.1 /s
    ctrl = engine.increment_control(batch, dH, steps, dt)
    host = batch.copy() if per_call else None
    t0 = time.perf_counter()
    dev = DeviceBatch(batch)
    push_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    engine.advance(dev, steps, dt, cp, ctrl)  # compiles (first time), builds the lists
    first_s = time.perf_counter() - t0
    best, moved = np.inf, 0
    for _ in range(2):
        before = dev.moved
        t0 = time.perf_counter()
        engine.advance(dev, steps, dt, cp, ctrl)
        best = min(best, time.perf_counter() - t0)
        moved = dev.moved - before
    status = np.zeros(count, np.int64)
    out = np.zeros((count, kernel.OUT_WIDTH))
    law = engine.contact_law(cp)
    kctl = engine.Controls(float(dt), ctrl.e_step, ctrl.l_mean, ctrl.hdot_fixed,
                           ctrl.l_ctrl, ctrl.servo_mask, ctrl.servo_target, 0.0,
                           ctrl.max_rate)
    t0 = time.perf_counter()
    dev.step(np.zeros(count, np.int64), law, kctl, status, out)
    zero_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    dev.pull()
    pull_s = time.perf_counter() - t0
    res = {"rves": count, "particles": base.n_particles, "threads": threads,
           "max_registers": regs, "steps_per_call": steps, "call_s": round(best, 5),
           "ns_per_particle_step": round(best / (count * base.n_particles * steps) * 1e9, 4),
           "first_call_s": round(first_s, 3), "zero_step_call_s": round(zero_s, 5),
           "push_s": round(push_s, 4), "pull_s": round(pull_s, 4),
           "bytes_per_rve_step": moved / count,
           "device_bytes_per_particle": round(dev.device_bytes() / (count * base.n_particles), 1),
           "capacity": batch.capacity, "longest_row": int(batch.nbr_count.max())}
    if per_call:
        engine.advance(host, steps, dt, cp, ctrl, device="cuda")
        t0 = time.perf_counter()
        engine.advance(host, steps, dt, cp, ctrl, device="cuda")
        res["per_call_over_resident"] = round((time.perf_counter() - t0) / best, 3)
    del dev
    return res


def throughput(inputs: Path, deadline: float, configs: list[str] | None = None,
               per_call: bool = True) -> list:
    """The grid of 3. (or `configs`, "SPHERESxRVESxTHREADS" each), cheapest first; a
    configuration predicted to overrun the deadline (from the last ns per
    particle-step, and ~0.3 us per sphere of tiling and copies) is skipped and marked."""
    rows = []
    ns_est = 1.5  # ns per particle-step (measured on an H100, 2026-11-26) until measured
    plan = [(n, c, 128) for n in SIZES for c in COUNTS]
    plan += [(800, 10_000, t) for t in BLOCKS if t != 128]
    if configs:  # SPHERESxRVESxTHREADS[xMAX_REGISTERS]
        plan = [tuple(int(v) for v in c.split("x")) for c in configs]
    plan.sort(key=lambda p: p[0] * p[1])
    for n, count, threads, *regs in plan:
        base, cp, dt = load(inputs, n)
        steps = int(np.clip(0.4 / (count * n * ns_est * 1e-9), 10, 50))
        predicted = 5 * count * n * steps * ns_est * 1e-9 + 3e-7 * count * n  # + copies
        if time.perf_counter() + predicted > deadline:
            rows.append({"rves": count, "particles": n, "threads": threads,
                         "skipped": f"predicted {predicted:.0f} s beyond the budget"})
            continue
        try:
            r = measure(base, cp, dt, count, threads, steps,
                        per_call=per_call and count == 10_000 and threads == 128,
                        regs=regs[0] if regs else None)
            ns_est = max(r["ns_per_particle_step"], 0.05)
        except Exception as err:
            r = {"rves": count, "particles": n, "threads": threads,
                 "error": f"{type(err).__name__}: {err}"}
        rows.append(r)
        print(json.dumps(r), flush=True)
    return rows


def baseline(src: Path, inputs: Path, configs: list[str], out: Path, budget: float) -> dict:
    """The throughput of `configs` with the grainscale of `src` (another version's src/),
    in a subprocess of this script: a ratio against this version's figures is then a
    comparison on one GPU in one lease."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(src.resolve())] + os.environ.get("PYTHONPATH", "").split(os.pathsep)[1:]))
    run = subprocess.run([sys.executable, __file__, "--inputs", str(inputs), "--out",
                          str(out), "--skip", "tests", "column", "--budget", str(budget),
                          "--no-per-call",
                          "--configs", *configs], env=env, capture_output=True, text=True,
                         timeout=budget + 60)
    res = {"returncode": run.returncode, "src": str(src)}
    report = out / "gpu_check.json"
    if report.exists():
        res["throughput"] = json.loads(report.read_text()).get("throughput")
    if run.returncode != 0:
        res["tail"] = (run.stdout + run.stderr)[-2000:]
    return res


def _profiled_call(inputs: Path, config: str) -> None:
    """Two calls of one configuration (the target of `profile`'s ncu)."""
    n, count, threads = (int(v) for v in config.split("x"))
    base, cp, dt = load(inputs, n)
    measure(base, cp, dt, count, threads, 10, per_call=False)


def profile(inputs: Path, config: str, out: Path, budget: float) -> dict:
    """ncu on the batch kernel's second launch of `config` (see the module docstring)."""
    ncu = shutil.which("ncu") or next(
        (str(p) for p in sorted(Path("/opt/nvidia").glob("nsight-compute/*/ncu"))), None)
    if ncu is None:
        return {"error": "ncu not found"}
    sections = ("SpeedOfLight", "Occupancy", "LaunchStats", "MemoryWorkloadAnalysis",
                "ComputeWorkloadAnalysis", "WarpStateStats", "SchedulerStats")
    cmd = [ncu, "--clock-control", "none", "--kernel-name", "regex:advance_kernel",
           "--launch-skip", "1", "--launch-count", "1"]
    for s in sections:
        cmd += ["--section", s]
    code = (f"import sys; sys.path.insert(0, {str(ROOT / 'benchmarks')!r}); "
            f"from gpu_check import _profiled_call; from pathlib import Path; "
            f"_profiled_call(Path({str(inputs)!r}), {config!r})")
    run = subprocess.run(cmd + [sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=budget)
    (out / "ncu.txt").write_text(run.stdout + run.stderr)
    return {"returncode": run.returncode, "config": config, "report": "ncu.txt"}


CLI = "import sys; from grainscale.cli import main; sys.exit(main(sys.argv[1:]))"


def column(inputs: Path, steps: list[int], budget: float,
           devices: tuple[str, ...] = ("cuda", "cpu")) -> dict:
    """The quick column for each of `steps` MPM steps on the GPU and on every CPU core,
    from the packings --prepare cached (inputs/column/packings). Two step counts give
    the steady cost per step by difference, free of start-up and kernel compilation."""
    res = {"warm_up": _column_run(inputs, 2, "cpu", budget / 4)}  # compiles the CPU code
    for n in steps:
        for device in devices:
            res[f"{device}_{n}"] = _column_run(inputs, n, device, budget / (2 * len(steps)))
    if len(steps) == 2:
        a, b = steps
        for device in devices:
            ra, rb = res.get(f"{device}_{a}", {}), res.get(f"{device}_{b}", {})
            if "cost" in ra and "cost" in rb:
                res[f"{device}_steady_s_per_step"] = round(
                    (rb["cost"]["wall_seconds"] - ra["cost"]["wall_seconds"]) / (b - a), 5)
    return res


def _column_run(inputs: Path, steps: int, device: str, timeout: float) -> dict:
    """One `grainscale run` of the quick column: wall time, cost.json, last history row."""
    case = ROOT / "examples" / "column_collapse" / "quick.toml"
    out = Path("/tmp") / f"column_{device}_{steps}"
    if (inputs / "column" / "packings").is_dir():
        shutil.copytree(inputs / "column" / "packings", out / "packings",
                        dirs_exist_ok=True)
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, "-c", CLI, "run", str(case),
                          "--out", str(out), "--quiet", "--max-steps", str(steps),
                          "--device", device, "--threads", str(os.cpu_count())],
                         cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    r = {"returncode": run.returncode, "wall_s": round(time.perf_counter() - t0, 1)}
    if run.returncode != 0:
        r["tail"] = (run.stdout + run.stderr)[-2000:]
    cost = out / "cost.json"
    if cost.exists():
        r["cost"] = json.loads(cost.read_text())
    hist = out / "history.csv"
    if hist.exists():
        lines = [ln for ln in hist.read_text().splitlines() if not ln.startswith("#")]
        r["history_last"] = dict(zip(lines[0].split(","), lines[-1].split(","),
                                     strict=False))
    return r


def prepare_case(case_path: Path, inputs: Path) -> None:
    """Generate (or copy from the packing store) the library of every "dem" material of
    a case into inputs/<case name>/packings, where `intrusion` finds them."""
    import grainscale as gs
    from grainscale.coupling.materials import packing_library

    case = gs.load_case(case_path)
    for name, cfg in case.materials.items():
        if cfg.type == "dem":
            t0 = time.perf_counter()
            lib = packing_library(case, name, case_path.parent, inputs / case_path.stem)
            print(f"{case_path.stem}: {len(lib)} packing(s) of material {name!r}, "
                  f"{time.perf_counter() - t0:.0f} s, longest rows "
                  f"{[int(b.nbr_count.max()) for b in lib]}", flush=True)


class StepRecorder:
    """on_step callback of grainscale.run: per MPM step its wall time, the DEM's share,
    the DEM steps per RVE (over all RVEs, those deferred by adaptive updates included),
    the share of RVEs stepped and the bytes moved to and from the GPU. The first row's wall
    time also holds what came before the first step (packings read, state built and
    uploaded, kernels compiled)."""

    def __init__(self, device: str):
        self.device = device
        self.rows: list[dict] = []
        self.last = time.perf_counter()
        self.dem = self.rve_steps = self.moved = self.updates = 0.0
        self.mats: list = []

    def __call__(self, s) -> None:
        now = time.perf_counter()
        mats = [m for m in s.materials if hasattr(m, "rve_steps")]
        dem = sum(m.seconds for m in mats)
        steps = sum(m.rve_steps for m in mats)
        moved = sum(m.bytes_moved() for m in mats)
        updates = sum(m.rve_updates for m in mats)
        rves = max(sum(m.n_rve for m in mats), 1)
        self.rows.append({"step": int(s.step), "time": float(s.time),
                          "dt": float(s.last_dt), "wall_s": round(now - self.last, 4),
                          "dem_s": round(dem - self.dem, 4),
                          "dem_steps_per_rve": round((steps - self.rve_steps) / rves, 3),
                          "fraction_stepped": round((updates - self.updates) / rves, 4),
                          "bytes_moved_per_rve": round((moved - self.moved) / rves, 1)})
        self.last, self.dem, self.rve_steps, self.moved = now, dem, steps, moved
        self.updates = updates
        self.mats = mats


def _memory(device: str) -> dict:
    import resource

    out = {"host_peak_gb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                                 * 1024 / 1e9, 2)}
    if device == "cuda":
        from numba import cuda

        free, total = cuda.current_context().get_memory_info()
        used = (total - free) / 1e9
        # numba's simulator has no device memory to report: None there
        out["gpu_used_gb"] = round(used, 2) if np.isfinite(used) else None
        out["gpu_total_gb"] = round(total / 1e9, 2) if np.isfinite(total) else None
    return out


def intrusion_stage(case_path: Path, inputs: Path, out: Path, steps: int, device: str,
                    start: float | None = None, threads: int | None = None) -> dict:
    """One stage of `intrusion` (module docstring, 7.): the case from its own start
    (the geostatic stage) or from `start` [s], `steps` MPM steps on `device`, without
    checkpoints or frames, in-process so that the run's state can be read."""
    import grainscale as gs

    case = gs.load_case(case_path)
    if start is not None:
        case.time.start = start
    case.output.checkpoint_every = 0
    case.output.frame_interval = 1e9
    packings = inputs / case_path.stem / "packings"
    if packings.is_dir():
        shutil.copytree(packings, out / "packings", dirs_exist_ok=True)
    rec = StepRecorder(device)
    t0 = time.perf_counter()
    gs.run(case, out, max_steps=steps, device=device, threads=threads, progress=False,
           on_step=rec)
    wall = time.perf_counter() - t0
    mats = rec.mats
    res = {"case": case_path.name, "device": device, "start": case.time.start,
           "steps": len(rec.rows), "wall_s": round(wall, 2), "rows": rec.rows,
           "rves": int(sum(m.n_rve for m in mats)),
           "particles": [int(b.n_particles) for m in mats for b in m.groups],
           "capacity": [int(b.capacity) for m in mats for b in m.groups],
           **_memory(device)}
    if device == "cuda" and mats:
        spheres = sum(b.n_rve * b.n_particles for m in mats for b in m.groups)
        res["device_bytes_per_sphere"] = round(sum(m.device_bytes() for m in mats)
                                               / max(spheres, 1), 1)
    steady = rec.rows[1:] or rec.rows
    if steady:
        res["median_step_s"] = float(np.median([r["wall_s"] for r in steady]))
        res["median_dem_s"] = float(np.median([r["dem_s"] for r in steady]))
        res["median_dem_steps_per_rve"] = float(np.median([r["dem_steps_per_rve"]
                                                           for r in steady]))
    return res


def intrusion(cases: list[Path], inputs: Path, out: Path, steps: int,
              devices: tuple[str, ...], threads: int | None = None) -> dict:
    """Section 7 (module docstring): each case's geostatic and intrusion stages on each
    device, and the projected wall time of its whole run."""
    import grainscale as gs

    res = {}
    for case_path in cases:
        if not (inputs / case_path.stem / "packings").is_dir():  # generated once for all
            prepare_case(case_path, inputs)
        case = gs.load_case(case_path)
        t_start, t_end = case.time.start, case.time.end
        for device in devices:
            key = f"{case_path.stem}_{device}"
            stages = {}
            for stage, start in (("geostatic", None), ("intrusion", 0.0)):
                if stage == "geostatic" and t_start >= 0.0:
                    continue
                try:
                    stages[stage] = intrusion_stage(case_path, inputs,
                                                    out / f"{key}_{stage}", steps, device,
                                                    start, threads)
                except Exception as err:  # recorded; the next stage still runs
                    stages[stage] = {"error": f"{type(err).__name__}: {err}"}
            res[key] = {"stages": stages, **projection(stages, t_start, t_end)}
    return res


def projection(stages: dict, t_start: float, t_end: float) -> dict:
    """The whole run's wall time [h] from the stages' median step and step size: each
    stage's simulated time (geostatic: start to 0; intrusion: 0 to end) over its last
    dt, times its median wall time a step."""
    hours, how = 0.0, []
    spans = {"geostatic": (t_start, min(0.0, t_end)), "intrusion": (max(0.0, t_start), t_end)}
    for stage, (a, b) in spans.items():
        st = stages.get(stage)
        if b <= a:
            continue
        if not st or "median_step_s" not in st or not st["rows"][-1]["dt"] > 0:
            return {"projected_h": None, "projection": f"no {stage} steps measured"}
        n = (b - a) / st["rows"][-1]["dt"]
        hours += n * st["median_step_s"] / 3600
        how.append(f"{stage}: {n:.0f} steps x {st['median_step_s']:.3g} s")
    return {"projected_h": round(hours, 2),
            "projection": "; ".join(how) + " (the median step after the first of each "
                          "stage; the intrusion's from its first steps in an unsettled "
                          "bed, not a developed intrusion's: an estimate of unknown "
                          "sign)"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--prepare", type=Path, help="generate the packings into this folder")
    ap.add_argument("--inputs", type=Path, default=ROOT / "gpu_inputs")
    ap.add_argument("--out", type=Path, default=Path(os.environ.get("OUT", "gpu_out")))
    ap.add_argument("--budget", type=float, default=420.0, help="seconds for all sections")
    ap.add_argument("--steps", type=int, nargs="+", default=[100, 600],
                    help="MPM steps of the column runs (two: the steady cost by difference)")
    ap.add_argument("--configs", nargs="*", help="throughput SPHERESxRVESxTHREADS only")
    ap.add_argument("--devices", nargs="+", default=["cuda", "cpu"],
                    help="devices of the column runs")
    ap.add_argument("--skip", nargs="*", default=[], help="sections to leave out")
    ap.add_argument("--baseline", type=Path, help="another version's src/ to compare with")
    ap.add_argument("--baseline-configs", nargs="*", default=["800x10000x128"],
                    help="throughput configurations of the baseline section")
    ap.add_argument("--profile", help="SPHERESxRVESxTHREADS to profile with ncu")
    ap.add_argument("--no-per-call", action="store_true",
                    help="leave out the per-call path's ratio at 10,000 RVEs")
    ap.add_argument("--prepare-case", type=Path,
                    help="generate this case's library packings into --inputs")
    ap.add_argument("--intrusion", type=Path, nargs="*", default=[],
                    help="cases of the intrusion section (7.)")
    ap.add_argument("--intrusion-steps", type=int, default=4,
                    help="MPM steps of each stage of the intrusion section")
    ap.add_argument("--intrusion-devices", nargs="+", default=["cuda"],
                    help="devices of the intrusion section")
    args = ap.parse_args()
    if args.intrusion_steps < 2:
        ap.error(f"--intrusion-steps {args.intrusion_steps}: must be at least 2 (the first "
                 "step compiles the kernels and is left out of the median)")
    if args.prepare:
        prepare(args.prepare)
        return
    if args.prepare_case:
        prepare_case(args.prepare_case, args.inputs)
        return
    start = time.perf_counter()
    rep = Report(args.out)
    rep.section("env", env)
    if "tests" not in args.skip:
        rep.section("tests", tests, 0.4 * args.budget)
    # the budget's shares: the later sections' are kept back from the throughput grid
    later = (0.5 if "column" not in args.skip else 0.05) \
        + 0.2 * (args.baseline is not None) + 0.2 * (args.profile is not None)
    if "throughput" not in args.skip:
        rep.section("throughput", throughput, args.inputs,
                    start + max(1.0 - later, 0.3) * args.budget, args.configs,
                    not args.no_per_call)
    if args.baseline:
        rep.section("baseline", baseline, args.baseline, args.inputs, args.baseline_configs,
                    args.out / "baseline", 0.2 * args.budget)
    if args.profile:
        rep.section("profile", profile, args.inputs, args.profile, args.out,
                    0.2 * args.budget)
    if "column" not in args.skip:
        left = args.budget - (time.perf_counter() - start)
        rep.section("column", column, args.inputs, args.steps, max(left, 30.0),
                    tuple(args.devices))
    if args.intrusion:
        rep.section("intrusion", intrusion, args.intrusion, args.inputs, args.out,
                    args.intrusion_steps, tuple(args.intrusion_devices))
    rep.data["total_s"] = round(time.perf_counter() - start, 1)
    rep.save()


if __name__ == "__main__":
    main()

"""DEM throughput: ns per particle-step of the 800-sphere unit-element RVE in triaxial
shear (one thread), Verlet-skin variants as ratios, and the parallel efficiency of a batch
of RVEs on all cores.

    python benchmarks/dem_throughput.py [--steps 20000] [--batch 8] [--big-batch 64] [--quick]
    python benchmarks/dem_throughput.py --device cuda [--rves 10000] [--gpu-steps 100]

Prints a table; the last line is one JSON object with at least `ns_per_particle_step`
(single thread, shear), `parallel_efficiency` and `ns_per_particle_step_batch`: core-ns
per particle-step of a batch of `--big-batch` RVEs (default 64) of 800 spheres in shear
on one thread, with the batch's parallel efficiency on all threads
(`parallel_efficiency_batch`).

`--device cuda` times the GPU kernel (dem/cuda_kernel.py) instead, as a run drives it:
a batch of `--rves` RVEs of `--particles` spheres (decorrelated copies) resident on the
device (dem/device_batch.py), each `engine.advance` call one MPM increment of
`--gpu-steps` DEM steps, best of 2. Its JSON line holds `ns_per_particle_step_cuda`
(wall time of a call, transfers included, per particle-step), `bytes_per_rve_step`
(bytes between host and device per RVE and call), `device_bytes_per_particle` (the
resident state), `pull_s` (the whole state to the host, as a checkpoint does) and
`per_call_over_resident` (the same call copying the state down and up, as a ratio).
Runs on numba's simulator too: NUMBA_ENABLE_CUDASIM=1 ... --device cuda --rves 1
--particles 90 --gpu-steps 2. The CPU figures are not taken in that mode.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import time

import numba
import numpy as np

from grainscale.config.rve import RVEParams
from grainscale.dem import engine, kernel
from grainscale.dem.generate import contact_params, generate
from grainscale.dem.state import RVEBatch, concatenate, state_arrays, with_history


def shear_control(batch: RVEBatch, rate: float = 0.1) -> engine.Control:
    """Drained triaxial: axis z shortened at `rate`, lateral stresses servo-held at 100 kPa."""
    ctrl = engine.rate_control(batch.n_rve, servo={0: -100e3, 1: -100e3}, max_rate=10 * rate)
    ctrl.hdot_fixed[:, 2, :] = -rate * batch.h[:, 2, :]
    return ctrl


def time_steps(batch: RVEBatch, cp: engine.ContactParams, ctrl: engine.Control, dt: float,
               steps: int, repeats: int = 3) -> float:
    """Best wall time [s] of `steps` steps over `repeats` runs from the same state."""
    best = np.inf
    for _ in range(repeats):
        b = batch.copy()
        t0 = time.perf_counter()
        engine.advance(b, steps, dt, cp, ctrl)
        best = min(best, time.perf_counter() - t0)
    return best


def decorrelated_batch(base: RVEBatch, count: int, rng: np.random.Generator) -> RVEBatch:
    """`count` copies of base with velocities perturbed by 1e-4 m/s, so they decorrelate."""
    copies = []
    for _ in range(count):
        c = base.copy()
        c.v += rng.normal(0.0, 1e-4, c.v.shape)
        copies.append(c)
    return concatenate(copies)


def thread_times(batch: RVEBatch, cp: engine.ContactParams, dt: float, steps: int,
                 cores: int) -> tuple[float, float]:
    """Best wall times [s] of `steps` sheared steps of a batch on 1 and on `cores` threads
    (after 10 steps that compile and build the lists)."""
    ctrl = shear_control(batch)
    engine.advance(batch, 10, dt, cp, ctrl)
    numba.set_num_threads(1)
    t1 = time_steps(batch, cp, ctrl, dt, steps, repeats=2)
    numba.set_num_threads(cores)
    return t1, time_steps(batch, cp, ctrl, dt, steps, repeats=2)


@numba.njit(parallel=True)
def _contiguous_batch(nsteps, law, st, ctl, status, out):
    """Scheduling variant: prange's equal blocks of RVEs per thread, whatever they cost."""
    for r in numba.prange(st.s.shape[0]):
        status[r] = kernel.advance_rve(nsteps[r], law, kernel.rve_state(st, r),
                                       kernel.rve_controls(ctl, r), out[r])


@numba.njit(parallel=True)
def _dealt_batch(nsteps, law, st, ctl, status, out, nthr):
    """Scheduling variant: RVEs dealt to the threads in turn, costliest first, so that
    neighbours in memory run on different threads."""
    order = np.argsort(-nsteps, kind="mergesort")
    for t in numba.prange(nthr):
        for k in range(t, st.s.shape[0], nthr):
            r = order[k]
            status[r] = kernel.advance_rve(nsteps[r], law, kernel.rve_state(st, r),
                                           kernel.rve_controls(ctl, r), out[r])


def schedule_times(batch: RVEBatch, cp: engine.ContactParams, dt: float, nsteps: np.ndarray,
                   cores: int) -> dict[str, float]:
    """Wall times [s] on `cores` threads of a batch advancing nsteps[r] steps per RVE:
    kernel.advance_batch (contiguous ranges of equal cost per thread) against the two
    variants above, and the ideal (1-thread time / cores). Best of 2, same state."""
    r = batch.n_rve
    ctrl = shear_control(batch)
    engine.advance(batch, 10, dt, cp, ctrl)
    law = engine.contact_law(cp)
    ctl = kernel.Controls(float(dt), np.broadcast_to(np.eye(3), (r, 3, 3)).copy(),
                          np.zeros((r, 3, 3)), ctrl.hdot_fixed, ctrl.l_ctrl, ctrl.servo_mask,
                          ctrl.servo_target, float(ctrl.servo_gain), ctrl.max_rate)

    def best(fn, *extra) -> float:
        t = np.inf
        for _ in range(2):
            b = batch.copy()
            status, out = np.zeros(r, np.int64), np.zeros((r, kernel.OUT_WIDTH))
            t0 = time.perf_counter()
            fn(nsteps, law, engine.rve_arrays(b), ctl, status, out, *extra)
            t = min(t, time.perf_counter() - t0)
        return t

    numba.set_num_threads(1)
    one = best(kernel.advance_batch)
    numba.set_num_threads(cores)
    return {"split": best(kernel.advance_batch), "dealt": best(_dealt_batch, cores),
            "blocks": best(_contiguous_batch), "ideal": one / cores}


def cuda_throughput(base: RVEBatch, cp: engine.ContactParams, dt: float, rves: int,
                    steps: int, threads: int) -> dict:
    """The GPU kernel on `rves` decorrelated copies of base, driven as a run drives it:
    calls of `steps` DEM steps, each applying an MPM increment (axial compression at
    0.1 /s) to state resident on the device (dem/device_batch.py). Returns the figures
    (also printed), with the per-call path (state copied down and up every call) as a
    ratio measured in the same run."""
    from numba import cuda

    from grainscale.dem import cuda_kernel
    from grainscale.dem.device_batch import DeviceBatch

    engine.check_device("cuda")
    cuda_kernel.THREADS = threads  # the block size of engine.advance(device="cuda")
    n = base.n_particles
    print(f"building a batch of {rves} RVEs x {n} spheres ...")
    batch = with_history(decorrelated_batch(base, rves, np.random.default_rng(0)),
                         cp.history)
    dH = np.zeros((rves, 3, 3))
    dH[:, 2, 2] = -0.1 * steps * dt  # one MPM increment of axial strain at 0.1 /s
    ctrl = engine.increment_control(batch, dH, steps, dt)
    host_copy = batch.copy()
    dev = DeviceBatch(batch)
    engine.advance(dev, steps, dt, cp, ctrl)  # compile, build the lists
    best, moved = np.inf, 0
    for _ in range(2):
        before = dev.moved
        t0 = time.perf_counter()
        engine.advance(dev, steps, dt, cp, ctrl)
        best = min(best, time.perf_counter() - t0)
        moved = dev.moved - before
    t0 = time.perf_counter()
    dev.pull()  # what a checkpoint or a retiling of every RVE costs
    pull_s = time.perf_counter() - t0
    # the per-call path: the whole state down and up around the same call
    engine.advance(host_copy, steps, dt, cp, ctrl, device="cuda")
    t0 = time.perf_counter()
    engine.advance(host_copy, steps, dt, cp, ctrl, device="cuda")
    per_call = time.perf_counter() - t0
    ns = best / (rves * n * steps) * 1e9
    try:
        name = cuda.get_current_device().name
        name = name.decode() if isinstance(name, bytes) else str(name)
    except AttributeError:  # numba's simulator has no device
        name = "simulator"
    res = {
        "device": "cuda", "gpu": name, "ns_per_particle_step_cuda": round(ns, 3),
        "rves": rves, "particles": n, "steps_per_call": steps, "threads_per_block": threads,
        "call_s": round(best, 5), "bytes_per_rve_step": moved / rves,
        "device_bytes_per_particle": round(dev.device_bytes() / (rves * n), 1),
        "capacity": batch.capacity, "longest_row": int(batch.nbr_count.max()),
        "pull_s": round(pull_s, 4),
        "per_call_over_resident": round(per_call / best, 3),
    }
    print(f"\nCUDA ({name}), {rves} RVEs x {n} spheres, {steps} DEM steps per call (one "
          f"MPM increment), {threads} threads per RVE, best of 2: {ns:.2f} ns/particle-step, "
          f"transfers included; {res['bytes_per_rve_step']:.0f} B moved per RVE and call; "
          f"{res['device_bytes_per_particle']:.0f} B resident per sphere; copying the state "
          f"down and up every call instead takes {res['per_call_over_resident']:.2f}x as long")
    print(json.dumps(res))
    return res


def clump_packing(params: RVEParams) -> RVEBatch:
    """The 400 two-sphere clumps of tests/data/triaxial_clumps/elongated.txt, at rest."""
    from pathlib import Path

    from grainscale.io.packing import load_packing

    path = Path(__file__).resolve().parents[1] / "tests" / "data" / "triaxial_clumps"
    return load_packing(path / "elongated.txt", params)


def ns_clumps(base: RVEBatch, cp: engine.ContactParams, dt: float, steps: int,
              one_sphere: bool = False) -> float:
    """ns per member-step of `base` in shear as clumps: with one_sphere, each sphere of a
    sphere packing made a clump of its own (mass and inertia the sphere's)."""
    from grainscale.dem import clump
    from grainscale.dem.state import from_clumps

    b = base.copy()
    if one_sphere:
        x = b.s[0] @ b.h[0].T
        one = clump.template("sphere")
        grains = [clump.scaled(one, r) for r in b.radius[0]]
        q = np.tile([1.0, 0.0, 0.0, 0.0], (b.n_particles, 1))
        c = from_clumps(b.h[0], x, q, grains, 1.0)
        c.bm[0] = c.mass[0] = b.mass[0]
        c.bj[0] = b.inertia[0][:, None]
        c.inertia[0] = b.inertia[0]
        b = c
    engine.advance(b, 10, dt, cp, shear_control(b))
    return time_steps(b, cp, shear_control(b), dt, steps) / (steps * b.n_particles) * 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--batch", type=int, default=8, help="RVEs in the parallel batch")
    ap.add_argument("--big-batch", type=int, default=64,
                    help="RVEs in the batch of ns_per_particle_step_batch")
    ap.add_argument("--quick", action="store_true", help="fewer steps (smoke test)")
    ap.add_argument("--device", choices=("cpu", "cuda"), default="cpu",
                    help="cuda: time the GPU kernel on --rves RVEs instead (needs a GPU)")
    ap.add_argument("--rves", type=int, default=10000, help="RVEs of the --device cuda batch")
    ap.add_argument("--gpu-steps", type=int, default=100,
                    help="DEM steps per engine.advance call with --device cuda")
    ap.add_argument("--gpu-threads", type=int, default=128,
                    help="threads per RVE (block size) with --device cuda")
    ap.add_argument("--particles", type=int, default=800,
                    help="spheres of the RVE (fewer for a smoke test on the simulator)")
    ap.add_argument("--rolling", type=float, nargs=2, metavar=("ALPHA_R", "ETA_R"),
                    help="with --device cuda: rolling resistance on (the resident bytes "
                         "per sphere with its moment history)")
    args = ap.parse_args()
    if args.device == "cuda":
        engine.check_device("cuda")  # before the minutes of generation
    steps = 2000 if args.quick else args.steps
    params = RVEParams(particles=args.particles,
                       preparation={"pressure": 100e3, "porosity": 0.373})
    print(f"generating the unit-element RVE ({args.particles} spheres, n = 0.373, "
          "p = 100 kPa) ...")
    base = generate(params)
    cp = contact_params(params)
    dt = engine.critical_dt(base, cp, params.numerics.timestep_safety)
    # move into the shear regime first (2 % axial strain) so contacts slide and lists churn
    engine.advance(base, int(0.02 / (0.1 * dt) / 10), dt, cp, shear_control(base, 1.0))
    n = base.n_particles
    if args.device == "cuda":
        if args.rolling:
            cp = dataclasses.replace(cp, rolling_stiffness=args.rolling[0],
                                     rolling_friction=args.rolling[1])
            dt = engine.critical_dt(base, cp, params.numerics.timestep_safety)
        cuda_throughput(base, cp, dt, args.rves, args.gpu_steps, args.gpu_threads)
        return

    numba.set_num_threads(1)
    rows = []
    ref = None
    for skin_ratio in (0.1, 0.25, 0.5, 1.0):
        cpv = engine.ContactParams(cp.young, cp.stiffness_ratio, cp.friction, cp.damping,
                                   skin_ratio * params.radius_min)
        b = base.copy()
        b.need_rebuild[:] = 1
        engine.advance(b, 10, dt, cpv, shear_control(b))  # compile / build lists
        t = time_steps(b, cpv, shear_control(b), dt, steps)
        ns = t / (steps * n) * 1e9
        ref = ns if skin_ratio == 0.25 else ref
        rows.append((skin_ratio, ns, float(b.nbr_count.mean())))
    print(f"\nsingle thread, 800 spheres, triaxial shear, {steps} steps, best of 3")
    print(f"{'skin/r_min':>10} {'ns/particle-step':>17} {'ratio to 0.25':>14} "
          f"{'list/particle':>14}")
    for skin_ratio, ns, per in rows:
        print(f"{skin_ratio:>10.2f} {ns:>17.1f} {ns / ref:>14.2f} {per:>14.2f}")
    ns_default = ref
    # the normal dashpot (restitution < 1) costs a square root per contact
    cpe = engine.ContactParams(cp.young, cp.stiffness_ratio, cp.friction, cp.damping,
                               cp.skin, restitution=0.9)
    b = base.copy()
    engine.advance(b, 10, dt, cpe, shear_control(b))
    ns_e = time_steps(b, cpe, shear_control(b), dt, steps) / (steps * n) * 1e9
    print(f"restitution 0.9 (default skin): {ns_e:.1f} ns/particle-step, "
          f"{ns_e / ns_default:.2f} x elastic")
    # rolling resistance: a moment per contact, 6 history components a slot (the step
    # count it adds through the smaller time step, sqrt(1 + alpha_r r_max/r_min), is
    # not in this per-step figure)
    cpr = dataclasses.replace(cp, rolling_stiffness=1.0, rolling_friction=0.1)
    b = with_history(base.copy(), cpr.history)
    engine.advance(b, 10, dt, cpr, shear_control(b))
    ns_r = time_steps(b, cpr, shear_control(b), dt, steps) / (steps * n) * 1e9
    print(f"rolling resistance alpha_r 1, eta_r 0.1 (same dt): {ns_r:.1f} ns/particle-step, "
          f"{ns_r / ns_default:.2f} x without; the time step is "
          f"{engine.critical_dt(base, cp) / engine.critical_dt(base, cpr):.2f} x shorter")

    # Hertz-Mindlin on the same packing and step (E 20 x the linear law's, nu 0.25): a
    # square root per contact more, and the largest overlap tracked
    cph = dataclasses.replace(cp, young=20 * cp.young, contact_law="hertz_mindlin",
                              poisson=0.25, max_overlap=0.2)
    b = base.copy()
    engine.advance(b, 10, dt, cph, shear_control(b))
    ns_h = time_steps(b, cph, shear_control(b), dt, steps) / (steps * n) * 1e9
    print(f"Hertz-Mindlin (same packing and dt): {ns_h:.1f} ns/particle-step, "
          f"{ns_h / ns_default:.2f} x the linear law")

    # clumps: the same packing as one-sphere clumps (the body step, member placement and
    # the branch between centres in place of the spheres' integration), and the 400
    # two-sphere clumps of tests/data/triaxial_clumps (800 members, its own contacts)
    ns_c1 = ns_clumps(base, cp, dt, steps, one_sphere=True)
    print(f"one-sphere clumps (same packing and dt): {ns_c1:.1f} ns/particle-step, "
          f"{ns_c1 / ns_default:.2f} x spheres")
    elongated = clump_packing(params)
    ns_c2 = ns_clumps(elongated, cp, engine.critical_dt(elongated, cp), steps)
    print(f"400 two-sphere clumps (800 members): {ns_c2:.1f} ns/member-step, "
          f"{ns_c2 / ns_default:.2f} x spheres, {2 * ns_c2:.1f} ns/clump-step")

    # batch of RVEs: copies with different velocities so they decorrelate
    rng = np.random.default_rng(0)
    batch = decorrelated_batch(base, args.batch, rng)
    bsteps = max(steps // 4, 500)
    cores = numba.config.NUMBA_NUM_THREADS
    t1, tp = thread_times(batch, cp, dt, bsteps, cores)
    eff = t1 / (cores * tp)
    ps1 = args.batch * n * bsteps / t1
    psp = args.batch * n * bsteps / tp
    mem = sum(a.nbytes for a in state_arrays(batch).values()) + sum(
        getattr(batch, k).nbytes for k in ("force", "torque", "x", "link", "wrapv"))
    print(f"\nbatch of {args.batch} RVEs x {n} spheres, {bsteps} steps")
    print(f"{'threads':>8} {'particle-steps/s':>18}")
    print(f"{1:>8} {ps1:>18.3e}")
    print(f"{cores:>8} {psp:>18.3e}")
    print(f"parallel efficiency on {cores} threads: {eff:.3f}")
    print(f"memory per particle (state + scratch, capacity {batch.capacity}): "
          f"{mem / (args.batch * n):.0f} B")

    # a large batch (the MPM's use): core-ns per particle-step on one thread, and the
    # parallel efficiency of the same batch on all threads
    big = decorrelated_batch(base, args.big_batch, rng)
    gsteps = 40 if args.quick else max(steps // 50, 100)
    g1, gp = thread_times(big, cp, dt, gsteps, cores)
    ns_batch = g1 / (args.big_batch * n * gsteps) * 1e9
    eff_batch = g1 / (cores * gp)
    print(f"\nbatch of {args.big_batch} RVEs x {n} spheres, {gsteps} steps: "
          f"{ns_batch:.1f} core-ns/particle-step on 1 thread, parallel efficiency "
          f"{eff_batch:.3f} on {cores} threads")
    # scheduling of kernel.advance_batch: equal work per RVE (dynamic RVEs), and uneven
    # work (quasi-static RVEs near an intruder: a quarter of the batch, side by side,
    # taking 8 x the steps); calls of 11 steps, as an MPM step makes of a dynamic RVE
    sched, nr = {}, big.n_rve
    for name, mult in (("equal", np.ones(nr, np.int64)),
                       ("skewed", np.r_[np.full(nr // 4, 8), np.ones(nr - nr // 4, np.int64)])):
        sched[name] = schedule_times(big, cp, dt, 11 * mult, cores)
    print(f"\nscheduling, batch of {big.n_rve} RVEs on {cores} threads, parallel "
          f"efficiency (ideal / time):")
    print(f"{'work per RVE':>24} {'ranges of equal cost':>21} {'dealt in turn':>14} "
          f"{'equal blocks':>13}")
    for name, label in (("equal", "equal"), ("skewed", f"first {nr // 4} take 8 x")):
        t = sched[name]
        print(f"{label:>24} {t['ideal'] / t['split']:>21.3f} {t['ideal'] / t['dealt']:>14.3f} "
              f"{t['ideal'] / t['blocks']:>13.3f}")
    print(json.dumps({
        "ns_per_particle_step": round(ns_default, 2), "parallel_efficiency": round(eff, 3),
        "ns_per_particle_step_batch": round(ns_batch, 2), "batch_rves": args.big_batch,
        "parallel_efficiency_batch": round(eff_batch, 3),
        "threads": cores, "particle_steps_per_s_all_threads": round(psp),
        "bytes_per_particle": round(mem / (args.batch * n)),
        "skin_variants_ns": {str(s): round(v, 2) for s, v, _ in rows},
        "restitution_0.9_ns": round(ns_e, 2), "rolling_ns": round(ns_r, 2),
        "hertz_mindlin_ns": round(ns_h, 2), "one_sphere_clumps_ns": round(ns_c1, 2),
        "two_sphere_clumps_ns_per_member": round(ns_c2, 2),
        "scheduling_efficiency": {
            name: {v: round(t["ideal"] / t[v], 3) for v in ("split", "dealt", "blocks")}
            for name, t in sched.items()},
        "machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
    }))


if __name__ == "__main__":
    main()

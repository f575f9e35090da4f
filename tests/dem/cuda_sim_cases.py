"""Scenarios of the CUDA DEM kernel against the CPU path, run by test_cuda_kernel.py:
the kernel on tiny batches, then `grainscale run --device cuda` of a shrunk unit element
and column.

Run as a script in a subprocess whose environment has NUMBA_ENABLE_CUDASIM=1 (numba's
CUDA simulator: it must be set before numba is imported, and must not reach the other
tests' process). Prints one JSON object of measured differences on its last line; the
test module asserts on them. Kept tiny: the simulator runs every GPU thread as a Python
thread.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import meshio
import numpy as np
import tomli_w

sys.path.insert(0, str(Path(__file__).parent))
from dem_helpers import agitated_dense_state, brute_pairs  # noqa: E402

from grainscale.analysis import read_columns  # noqa: E402
from grainscale.cli import main as grainscale  # noqa: E402
from grainscale.dem import clump, cuda_kernel, device_batch, engine, generate  # noqa: E402
from grainscale.dem.device_batch import DeviceBatch  # noqa: E402
from grainscale.dem.retile import double_cell, widths  # noqa: E402
from grainscale.dem.state import (  # noqa: E402
    STATE_FIELDS,
    RVEBatch,
    concatenate,
    from_clumps,
    from_packing,
    grow_capacity,
    longest_row,
    remove_rves,
    rve_constants,
    with_capacity,
)

THREADS = 8  # block size: smaller than the RVEs, so threads stride over particles
MAX_BLOCKS = cuda_kernel.MAX_BLOCKS  # restored after section 10
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
# The coupled runs' RVE: the fewest spheres a cell of 8 r_max holds at porosity 0.38
SHEAR_STEPS = np.array([30, 40])  # per RVE: both rebuild their lists on the way
SMALL_RVE = {"particles": 90, "radius_min": 2.0e-3, "radius_max": 2.2e-3}


def block_size(threads: int) -> None:
    """Make engine.advance(device="cuda") run blocks of `threads` threads, and the
    device batch's row copies too (the simulator runs each thread as a Python thread)."""
    cuda_kernel.THREADS = threads
    device_batch._COPY = threads


def rel(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| / max |a| (0 for two zero arrays)."""
    scale = float(np.abs(a).max())
    return float(np.abs(a - b).max()) / scale if scale > 0 else float(np.abs(b).max())


def rows(b: RVEBatch) -> list[dict]:
    """Per RVE and particle, {(j, image code): ft}: a list's content, whatever its order
    (a device build orders rows by j, the CPU's cell list otherwise)."""
    out = []
    for r in range(b.n_rve):
        for i in range(b.n_particles):
            out.append({(int(b.nbr_j[r, i, k]), int(b.nbr_shift[r, i, k])): b.ft[r, i, k]
                        for k in range(b.nbr_count[r, i])})
    return out


def ft_diff(cpu: RVEBatch, gpu: RVEBatch) -> tuple[bool, float]:
    """(the lists hold the same pairs, max |ft difference| / max |ft|) over matched pairs."""
    a, b = rows(cpu), rows(gpu)
    same = all(x.keys() == y.keys() for x, y in zip(a, b, strict=True))
    scale = float(np.abs(cpu.ft).max())
    worst = 0.0
    for x, y in zip(a, b, strict=True):
        for key in x.keys() & y.keys():
            worst = max(worst, float(np.abs(x[key] - y[key]).max()))
    return same, worst / scale


def compare(cpu: RVEBatch, gpu: RVEBatch) -> dict:
    same_pairs, ft_rel = ft_diff(cpu, gpu)
    out = {name: rel(getattr(cpu, name), getattr(gpu, name))
           for name in ("s", "v", "w", "rot", "stress", "stress_servo", "stiffness", "force",
                        "torque", "h", "L", "unbalanced", "kinetic")}
    out.update(ft=ft_rel, same_pairs=same_pairs,
               same_counts=bool(np.array_equal(cpu.ncontact, gpu.ncontact)
                                and np.array_equal(cpu.step_count, gpu.step_count)
                                and np.array_equal(cpu.nbr_count, gpu.nbr_count)
                                and np.array_equal(cpu.need_rebuild, gpu.need_rebuild)),
               capacity=[cpu.capacity, gpu.capacity])
    return out


def unit_element(folder: Path) -> Path:
    """examples/unit_element/case.toml shrunk to one material point: a 10 mm cube in a
    20 mm cell (the same strain rate, 0.1 /s, and lateral tractions of 100 kPa on its
    point), 5 MPM steps of ~11 DEM steps each."""
    case = tomllib.loads((EXAMPLES / "unit_element" / "case.toml").read_text())
    case["grid"]["cell_size"] = 0.02
    case["bodies"][0].update(hi=[0.01] * 3, points_per_cell=2)
    for bc in case["boundaries"]:
        if bc["type"] == "velocity":
            bc["velocity"] = -0.002
    for traction in case["tractions"]:
        traction.update(lo=[0.0] * 3, hi=[0.01] * 3)
    case["time"]["end"] = 3e-4
    case["output"].update(interval=6e-5, frame_interval=3e-4)
    case["rve"].update(SMALL_RVE)
    case["rve"]["preparation"].update(porosity=0.38, porosity_tolerance=0.01)
    path = folder / "unit_element.toml"
    path.write_text(tomli_w.dumps(case))
    return path


def adaptive_unit_element(folder: Path) -> Path:
    """`unit_element` with quasi-static RVEs and adaptive updates (tolerance 4e-5, at
    most 2 deferred steps): some MPM steps leave the RVE unstepped on the device."""
    case = tomllib.loads(unit_element(folder).read_text())
    case["materials"]["sand"].update(time_integration="quasi_static",
                                     allow_rve_damping=True, strain_per_substep=4e-5,
                                     update_tolerance=4e-5, max_deferred_steps=2)
    path = folder / "adaptive_unit_element.toml"
    path.write_text(tomli_w.dumps(case))
    return path


def clumped_unit_element(folder: Path) -> Path:
    """`unit_element` with RVEs of 140 rigid two-sphere clumps (aspect 1.6, consolidated
    at 100 kPa) whose cell is doubled at its first update (retile_width 20 grain
    diameters): the clumps' kernel, their rows on the device and their retiling."""
    case = tomllib.loads(unit_element(folder).read_text())
    case["rve"].update(particles=140, radius_min=1.0e-3, radius_max=1.4e-3,
                       clump={"template": "elongated", "aspect": 1.6, "spheres": 2})
    for key in ("porosity", "porosity_tolerance"):
        del case["rve"]["preparation"][key]
    case["materials"]["sand"].update(retile_width=20.0, retile_max_factor=2)
    path = folder / "clumped_unit_element.toml"
    path.write_text(tomli_w.dumps(case))
    return path


def column(folder: Path) -> Path:
    """examples/column_collapse/quick.toml shrunk to two material points (a 20 x 10 x
    10 mm column, one point a cell): 5 MPM steps of the geostatic stage with its gate
    and damping, then 5 after release, RVEs in real time with restitution 0.9."""
    case = tomllib.loads((EXAMPLES / "column_collapse" / "quick.toml").read_text())
    case["grid"]["cells"] = [4, 2, 3]
    case["bodies"][0].update(hi=[0.02, 0.01, 0.01], points_per_cell=1)
    for bc in case["boundaries"]:
        if "box" in bc and bc["normal"] == "x":  # the gate, at the column's face
            bc["box"] = {"lo": [0.02, 0.0, 0.0], "hi": [0.02, 0.01, 0.03]}
        elif "box" in bc:  # the far channel wall
            bc["box"] = {"lo": [0.0, 0.01, 0.0], "hi": [0.04, 0.01, 0.03]}
    case["time"].update(start=-3e-4, end=3e-4)
    case["materials"]["sand"]["library"] = 1
    case["output"].update(interval=1e-4, frame_interval=3e-4)
    case["output"]["column"].update(length=0.02, height=0.01)
    case["rve"].update(SMALL_RVE)
    case["rve"]["preparation"]["porosity_tolerance"] = 0.01
    path = folder / "column.toml"
    path.write_text(tomli_w.dumps(case))
    return path


def sleeping_column(folder: Path) -> Path:
    """`column` with sleeping RVEs (tolerance 1e-5, at most 2 steps asleep): an RVE at
    rest is left unstepped on the device, and wakes with what it owes."""
    case = tomllib.loads(column(folder).read_text())
    case["materials"]["sand"].update(update_tolerance=1e-5, max_deferred_steps=2)
    path = folder / "sleeping_column.toml"
    path.write_text(tomli_w.dumps(case))
    return path


def retiled_column(folder: Path) -> Path:
    """`column` with every cell doubled at its first update (retile_width 20 grain
    diameters, at most twice the spheres) and a probe RVE in its first cell: the resident
    state pulled for the retiling, the probe frames and the checkpoints."""
    case = tomllib.loads(column(folder).read_text())
    case["materials"]["sand"].update(retile_width=20.0, retile_max_factor=2)
    case["time"]["end"] = 0.0  # the geostatic stage: the simulator's cost halved
    case["output"]["probes"] = [{"position": [0.005, 0.005, 0.005], "name": "p"}]
    path = folder / "retiled.toml"
    path.write_text(tomli_w.dumps(case))
    return path


def resumed_on_device(folder: Path) -> dict:
    """The retiled column's geostatic stage on the device (7 MPM steps), run through and
    in two legs (stopped by --max-steps 3 with a checkpoint every 2 steps, then
    --resume): whether the histories and the probe's last frame agree bitwise, and the
    difference to the CPU's history."""
    path = retiled_column(folder)
    runs = {}
    for name, legs in (("through", [[]]), ("legs", [["--max-steps", "3"], ["--resume"]]),
                       ("cpu", [[]])):
        out = folder / f"retiled_{name}"
        device = "cpu" if name == "cpu" else "cuda"
        for extra in legs:
            code = grainscale(["run", str(path), "--out", str(out), "--quiet", "--threads",
                               "1", "--device", device, "--checkpoint-every", "2", *extra])
            assert code == 0, (name, extra, code)
        runs[name] = out
    text = {k: (v / "history.csv").read_text() for k, v in runs.items()}
    probes = sorted((runs["through"] / "frames").glob("probe_p_*"))
    last = {k: (runs[k] / "frames" / probes[-1].name).read_bytes() if probes else b""
            for k in ("through", "legs")}
    cpu, gpu = read_columns(runs["cpu"] / "history.csv"), read_columns(
        runs["through"] / "history.csv")
    frames = sorted((runs["through"] / "frames").glob("frame_*.vtu"))
    particles = meshio.read(frames[-1]).point_data["rve_particles"] if frames else [0]
    return {"same_history": text["through"] == text["legs"],
            "same_probe": bool(probes) and last["through"] == last["legs"],
            "probe_files": len(probes), "rows": text["through"].count("\n"),
            "cpu_rel": max(rel(np.asarray(cpu[c]), np.asarray(gpu[c])) for c in cpu),
            "particles": float(np.min(particles))}


def coupled_runs() -> dict:
    """`grainscale run` of the shrunk unit element and column on both devices:
    per history column, max |cpu - cuda| / max |cpu| over the rows; and the rows."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for make in (unit_element, column, adaptive_unit_element, sleeping_column,
                     clumped_unit_element):
            path = make(folder)
            hist = {}
            for device in ("cpu", "cuda"):
                run = folder / f"{path.stem}_{device}"
                code = grainscale(["run", str(path), "--out", str(run), "--quiet",
                                   "--threads", "1", "--device", device])
                assert code == 0, (path.stem, device, code)
                hist[device] = read_columns(run / "history.csv")
            cost = json.loads((folder / f"{path.stem}_cuda" / "cost.json").read_text())
            res = {"rows": len(hist["cpu"]["step"]), "last": {},
                   "stepped": cost["fraction_of_rves_stepped"],
                   "particles": sorted({float(x) for x in meshio.read(sorted(
                       (folder / f"{path.stem}_cuda" / "frames").glob("frame_*.vtu"))[-1]
                   ).point_data["rve_particles"]})}
            for name, a in hist["cpu"].items():
                a, b = np.asarray(a), np.asarray(hist["cuda"][name])
                res[name] = rel(a, b)
                res["last"][name] = float(a[-1])
            out[path.stem] = res
        out["retiled"] = resumed_on_device(folder)
    return out


def resident_against_per_call(base: RVEBatch, p: engine.ContactParams, dt: float) -> dict:
    """Two MPM-like increments (a shear dH, 3 and 5 DEM steps) on a DeviceBatch and on
    host batches copied to the device and back per call: whether every state array and
    every per-call result agrees bitwise, the capacities, and the bytes moved per RVE in
    the last call (steady running) and resident per particle."""
    dH = np.zeros((base.n_rve, 3, 3))
    dH[:, 0, 1] = 2e-4
    dH[:, 2, 2] = -1e-4
    nsteps = np.array([3, 5])[: base.n_rve]
    per_call, dev = base.copy(), DeviceBatch(base.copy())
    same_results = True
    moved = 0
    for _ in range(2):  # the second is steady running: nothing but the increment moves
        ctrl = engine.increment_control(per_call, dH, nsteps, dt)
        engine.advance(per_call, nsteps, dt, p, ctrl, device="cuda")
        before = dev.moved
        engine.advance(dev, nsteps, dt, p, ctrl)
        moved = dev.moved - before
        same_results &= all(np.array_equal(getattr(per_call, f), getattr(dev.host, f))
                            for f in ("h", "stress", "stiffness", "ncontact", "unbalanced",
                                      "kinetic"))
    stale = not np.array_equal(per_call.s, dev.host.s)  # the host's s awaits a pull
    before = dev.moved
    counter = dev.pull_field("step_count").copy()  # one array, as frames take it
    field = {"same": bool(np.array_equal(counter, per_call.step_count)),
             "bytes": dev.moved - before, "nbytes": int(counter.nbytes)}
    host = dev.pull()
    return {"same_results": bool(same_results), "stale_before_pull": bool(stale),
            "pull_field": field,
            "same_state": {f: bool(np.array_equal(getattr(per_call, f), getattr(host, f)))
                           for f in STATE_FIELDS},
            "capacity": [base.capacity, per_call.capacity, host.capacity],
            "bytes_per_rve_call": moved / base.n_rve,
            "device_bytes_per_particle": dev.device_bytes() / (base.n_rve * base.n_particles)}


def alternating_shapes(base: RVEBatch, p: engine.ContactParams, dt: float) -> dict:
    """Two groups as a retiled material holds them, base's 2 RVEs of 24 spheres and RVE
    0 doubled (48 spheres), resident and updated in turn (2 DEM steps, twice each): the
    scratch shapes launched in order, how many scratch allocations they made, and whether
    the states equal bitwise those of the same updates with the scratch freed before
    every launch (fresh arrays, as a single cached shape gave)."""
    big = double_cell(base, 0, int(np.argmin(widths(base.h[:1])[0])))
    real = cuda_kernel.launch
    runs = {}
    for fresh in (False, True):
        groups = [DeviceBatch(base.copy()), DeviceBatch(big.copy())]
        launched = []

        def recording(*args, fresh=fresh, launched=launched, **kw):
            if fresh:
                cuda_kernel._SCRATCH.clear()
            launched.append(real(*args, **kw))
            return launched[-1]

        cuda_kernel.launch = recording
        try:
            for _ in range(2):
                for dev in groups:
                    engine.advance(dev, 2, dt, p, engine.rate_control(dev.n_rve))
        finally:
            cuda_kernel.launch = real
        runs[fresh] = [dev.pull() for dev in groups], launched
    (kept, launched), (freed, _) = runs[False], runs[True]
    return {"shapes": [list(a[0].shape[:3]) for a in launched],
            "allocations": len({id(x) for a in launched for x in a}) // 9,
            "same_state": all(np.array_equal(getattr(x, f), getattr(y, f))
                              for x, y in zip(kept, freed, strict=True) for f in STATE_FIELDS)}


def more_rves_than_blocks(base: RVEBatch, p: engine.ContactParams, dt: float) -> dict:
    """Three RVEs of different states (base's two and a third packing) with lists up to
    date, sheared under a servo by 6, 4 and 5 steps on 1 and on 2 blocks (block g runs
    RVEs g, g + B, ...: one block's scratch serves several RVEs): compared with the CPU,
    and whether the state equals bitwise that of 3 blocks (one RVE each)."""
    third, _, _ = agitated_dense_state(n=24, seed=7)
    start = concatenate([base, third])
    ctrl = engine.rate_control(3, l_ctrl=[[0.0, 400.0, 0.0], [0.0, 0.0, 0.0],
                                          [0.0, 0.0, -20.0]], servo={0: -50e3},
                               max_rate=50.0)
    nsteps = np.array([6, 4, 5])
    cpu = start.copy()
    engine.advance(cpu, nsteps, dt, p, ctrl)
    res = {"lists_up_to_date": bool(not start.need_rebuild.any())}
    gpu = {}
    for blocks in (3, 1, 2):
        gpu[blocks] = start.copy()
        cuda_kernel.MAX_BLOCKS = blocks
        try:
            engine.advance(gpu[blocks], nsteps, dt, p, ctrl, device="cuda")
        finally:
            cuda_kernel.MAX_BLOCKS = MAX_BLOCKS
        res[str(blocks)] = compare(cpu, gpu[blocks])
        # STATE_FIELDS leave out force and torque (advance_batch copies them back only
        # where every RVE has a block of its own)
        res[str(blocks)]["same_as_3"] = all(
            np.array_equal(getattr(gpu[3], f), getattr(gpu[blocks], f))
            for f in STATE_FIELDS)
    return res


def _same(a: RVEBatch, b: RVEBatch, names=STATE_FIELDS) -> dict:
    """Per state array, whether a and b hold it bitwise equal (shapes included)."""
    return {f: bool(np.array_equal(getattr(a, f), getattr(b, f))) for f in names}


def device_built(base: RVEBatch, p: engine.ContactParams, dt: float) -> dict:
    """A batch built on the device from a library of two packings (base's RVEs) by an
    assignment, against the same batch concatenated on the host and uploaded: bitwise
    after the build, after a shear increment, after rows are taken and put back
    swapped, removed, and the lists widened, and after a second increment; the lean
    host's memory and the constants it keeps."""
    lib = [base.take([0]), base.take([1])]
    asg = np.array([1, 0, 1, 1, 0])
    k = longest_row(lib) + 1
    ref = concatenate([with_capacity(lib[i].copy(), k) for i in asg])
    built = DeviceBatch.from_library(lib, asg, k)
    up = DeviceBatch(ref.copy())
    everything = np.arange(len(asg))
    res = {"capacity": [base.capacity, k, built.host.capacity],
           "build": _same(built.take(everything), ref)}
    real = [f for f in RVEBatch.__dataclass_fields__
            if any(getattr(built.host, f).strides)]  # placeholders have zero strides
    res["host_bytes_per_rve"] = sum(getattr(built.host, f).nbytes for f in real) / len(asg)
    res["state_bytes_per_rve"] = sum(getattr(ref, f).nbytes for f in STATE_FIELDS) / len(asg)
    res["radius_placeholder_nan"] = bool(np.isnan(built.host.radius).all())
    try:
        built.host.s[0, 0, 0] = 0.0
        res["placeholder_read_only"] = False
    except ValueError:
        res["placeholder_read_only"] = True
    ref_c = rve_constants(ref)
    res["constants"] = {key: bool(np.array_equal(v, ref_c[key]))
                        for key, v in built.constants.items()}

    def step(n):
        dH = np.zeros((built.n_rve, 3, 3))
        dH[:, 0, 1] = 3e-4
        dH[:, 1, 1] = -2e-4
        ctrl = engine.increment_control(up.host, dH, n, dt)
        engine.advance(built, n, dt, p, ctrl)
        engine.advance(up, n, dt, p, ctrl)
        return _same(built.take(np.arange(built.n_rve)), up.pull())

    res["stepped"] = step(np.array([2, 1, 3, 2, 1]))
    res["per_rve_current"] = _same(built.host, up.host, ("h", "stress", "stiffness",
                                                         "ncontact", "unbalanced"))
    # rows out and back, swapped (what a cell reduction does, with a change)
    part = built.take([3, 0])
    built.put([0, 3], part)
    host = up.pull()
    host_part = host.take([3, 0])
    for f in STATE_FIELDS:
        getattr(host, f)[[0, 3]] = getattr(host_part, f)
    up.push()
    res["put"] = _same(built.take(np.arange(built.n_rve)), up.pull())
    # rows removed (what retiling does to the RVEs that stay)
    order = built.remove([1, 4])
    kept, order_host = remove_rves(up.pull().copy(), [1, 4])
    up = DeviceBatch(kept.copy())
    res["removed"] = {"order": bool(np.array_equal(order, order_host)),
                      **_same(built.take(np.arange(built.n_rve)), kept)}
    res["constants_after_remove"] = bool(np.array_equal(
        built.constants["grain_mass"], rve_constants(kept)["grain_mass"]))
    # the lists widened on the device, against grow_capacity on the host
    built.grow(k + 5)
    grown = grow_capacity(up.pull().copy(), k + 5)
    up = DeviceBatch(grown)
    res["grown"] = _same(built.take(np.arange(built.n_rve)), up.pull())
    res["grown_capacity"] = [built.host.capacity, int(built.arrays["ft"].shape[2])]
    res["stepped_again"] = step(np.array([1, 2, 1]))
    # a list overflow inside engine.advance: packings cut to 3 slots, lists to rebuild
    small = []
    for b in lib:
        b = with_capacity(b.copy(), longest_row([b]))
        b.nbr_j = np.ascontiguousarray(b.nbr_j[:, :, :3])
        b.nbr_shift = np.ascontiguousarray(b.nbr_shift[:, :, :3])
        b.ft = np.ascontiguousarray(b.ft[:, :, :3])
        b.nbr_count = np.minimum(b.nbr_count, 3).astype(np.int32)
        b.need_rebuild[:] = 1
        small.append(b)
    built = DeviceBatch.from_library(small, asg, 3)
    up = DeviceBatch(concatenate([small[i] for i in asg]))
    mirror = built.host
    still = engine.rate_control(len(asg))
    engine.advance(built, 2, dt, p, still)
    engine.advance(up, 2, dt, p, still)
    res["overflow"] = {"same": _same(built.take(np.arange(len(asg))), up.pull()),
                       "capacity": [3, built.host.capacity, up.host.capacity],
                       "same_host_object": built.host is mirror,
                       "counts": bool(np.array_equal(built.host.ncontact, up.host.ncontact))}
    return res


def lean_material(base: RVEBatch, p: engine.ContactParams) -> dict:
    """An RVEMaterial on "cuda" (its batch built on the device) against one on the
    CPU, same library and assignment: the state a checkpoint gathers (in chunks of one
    RVE), the point fields, after two quasi-static updates in which point 0's cell is
    squeezed below the retiling width (doubled out of the device-built group, the rest
    staying there). CPU and GPU agree to round-off, not bitwise (module tolerance)."""
    from grainscale.config.rve import RVEParams
    from grainscale.coupling import rve_material

    params = RVEParams(particles=24, radius_min=1.0e-3, radius_max=1.3e-3, density=2500.0,
                       young_modulus=p.young, stiffness_ratio=p.stiffness_ratio,
                       friction=p.friction, damping=0.0)
    lib = [base.take([0]), base.take([1])]
    width = float(widths(base.h).min(axis=1).min() / (2 * base.radius.mean()))
    kw = {"mode": "quasi_static", "strain_per_substep": 0.02, "update_tolerance": 0.0,
          "assignment": np.array([0, 1, 1, 0]), "retile_width": 0.97 * width,
          "retile_max_factor": 2}
    mats = {dev: rve_material.RVEMaterial("sand", params, lib, 4, device=dev, **kw)
            for dev in ("cpu", "cuda")}
    res = {"lean": mats["cuda"]._lean(mats["cuda"].groups[0]) is not None}
    dH = np.zeros((4, 3, 3))
    dH[0, 0, 0] = -0.06  # point 0: its cell narrower than the retiling width
    dH[1:, 0, 1] = 0.01
    stress = {dev: m.initial_stress() for dev, m in mats.items()}
    res["initial_stress"] = rel(stress["cpu"], stress["cuda"])
    chunk = rve_material.CHUNK_BYTES
    for _ in range(2):
        for dev, m in mats.items():
            m.update(dH, 1e-3, stress[dev])
    rve_material.CHUNK_BYTES = 1  # one RVE per chunk
    try:
        states = {dev: m.state() for dev, m in mats.items()}
    finally:
        rve_material.CHUNK_BYTES = chunk
    res["groups"] = [[b.n_particles for b in m.groups] for m in mats.values()]
    res["retiled"] = [m.retiled for m in mats.values()]
    res["stress"] = rel(stress["cpu"], stress["cuda"])
    res["state"] = {key: rel(np.asarray(states["cpu"][key], float),
                             np.asarray(states["cuda"][key], float))
                    for key in ("rve_s", "rve_v", "rve_h", "rve_stress", "rve_nbr_count",
                                "rve_particles")}
    # the lists' content, whatever the rows' order (the device orders them by j)
    res["ft"] = [ft_diff(mats["cpu"].rve(i), mats["cuda"].rve(i)) for i in range(4)]
    fields = {dev: m.point_fields() for dev, m in mats.items()}
    res["fields"] = {key: rel(fields["cpu"][key], fields["cuda"][key])
                     for key in fields["cpu"]}
    res["wave_speed"] = rel(np.array([mats["cpu"].wave_speed()]),
                            np.array([mats["cuda"].wave_speed()]))
    res["rve"] = rel(mats["cpu"].rve(2).s, mats["cuda"].rve(2).s)
    return res


def main(parts: list[str]) -> None:
    """parts: "kernel" (sections 1, 2, 7, 9 and 10: shear through rebuilds, capacity
    overflow, the resident path, scratch kept per shape, more RVEs than blocks; tiny
    batches, the fast tier), "kernel_more" (sections 3-6, 12 and 13: momentum, damping
    and idle threads, reverse-list overflow, spread radii, a batch and a material built
    on the device; the validation tier) and/or
    "coupled" (section 8, the `grainscale run` cases, minutes on the simulator)."""
    t0 = time.perf_counter()
    res: dict = {"available": cuda_kernel.is_available()}
    if "kernel" in parts or "kernel_more" in parts:
        kernel_cases(parts, res)
    if "coupled" in parts:
        res["coupled"] = coupled_runs()
    res["seconds"] = time.perf_counter() - t0
    print(json.dumps(res))


def kernel_cases(parts: list[str], res: dict) -> None:
    """Sections 1-7, 9 and 10 (those of `parts`) into res."""
    block_size(THREADS)
    a, p, dt = agitated_dense_state(n=24, seed=3)
    b, _, _ = agitated_dense_state(n=24, seed=5)
    base = concatenate([a, b])
    ctrl = engine.rate_control(2, l_ctrl=[[0.0, 400.0, 0.0], [0.0, 0.0, 0.0],
                                          [0.0, 0.0, -20.0]], servo={0: -50e3},
                               max_rate=50.0)
    still = engine.rate_control(2)
    small = base.copy()
    k = 3
    small.nbr_j = np.ascontiguousarray(small.nbr_j[:, :, :k])
    small.nbr_shift = np.ascontiguousarray(small.nbr_shift[:, :, :k])
    small.ft = np.ascontiguousarray(small.ft[:, :, :k])
    small.nbr_count = np.minimum(small.nbr_count, k).astype(np.int32)
    small.need_rebuild[:] = 1
    if "kernel" in parts:
        fast_cases(base, small, p, dt, ctrl, still, res)
    if "kernel_more" in parts:
        more_cases(base, p, dt, ctrl, still, res)


def fast_cases(base, small, p, dt, ctrl, still, res) -> None:
    """Sections 1, 2, 7, 9, 10, 11, 14 and 15."""
    # 1. shear with a normal-stress servo through list rebuilds, per-RVE step counts
    cpu, gpu = base.copy(), base.copy()
    engine.advance(cpu, SHEAR_STEPS, dt, p, ctrl)
    engine.advance(gpu, SHEAR_STEPS, dt, p, ctrl, device="cuda")
    res["shear"] = compare(cpu, gpu)
    res["shear"]["rebuilt"] = [bool(not np.array_equal(base.h_ref[r], gpu.h_ref[r]))
                               for r in range(2)]
    res["shear"]["rebuilt_cpu"] = [bool(not np.array_equal(base.h_ref[r], cpu.h_ref[r]))
                                   for r in range(2)]

    # 2. a list capacity too small for the next build: engine.advance regrows, retries
    cpu, gpu = small.copy(), small.copy()
    engine.advance(cpu, 10, dt, p, still)
    engine.advance(gpu, 10, dt, p, still, device="cuda")
    res["overflow"] = compare(cpu, gpu)

    # 11. rolling resistance (a 6-component history) through the same shear: the
    # moments carried through list rebuilds, capped and turned with the contact frames
    pr = dataclasses.replace(p, rolling_stiffness=1.0, rolling_friction=0.3)
    cpu, gpu = base.copy(), base.copy()
    engine.advance(cpu, SHEAR_STEPS, dt, pr, ctrl)
    engine.advance(gpu, SHEAR_STEPS, dt, pr, ctrl, device="cuda")
    res["rolling"] = compare(cpu, gpu)
    res["rolling"]["moment_max"] = float(np.abs(cpu.ft[..., 3:]).max())
    res["rolling"]["history"] = [cpu.ft.shape[3], gpu.ft.shape[3]]

    # 15. Hertz-Mindlin with its dashpot (restitution 0.5) through the same shear, and
    # the largest overlap both report (an overlap bound below it stops either path)
    ph = dataclasses.replace(p, contact_law="hertz_mindlin", poisson=0.25, restitution=0.5,
                             max_overlap=0.5)
    cpu, gpu = base.copy(), base.copy()
    engine.advance(cpu, SHEAR_STEPS, dt, ph, ctrl)
    engine.advance(gpu, SHEAR_STEPS, dt, ph, ctrl, device="cuda")
    res["hertz"] = compare(cpu, gpu)
    overlaps = []
    for device in ("cpu", "cuda"):
        try:
            engine.advance(cpu.copy(), 1, dt, dataclasses.replace(ph, max_overlap=1e-6),
                           still, device=device)
            overlaps.append(None)
        except engine.RVEError as err:
            overlaps.append(float(str(err).split("delta/R* = ")[1].split(",")[0]))
    res["hertz"]["overlaps"] = overlaps

    # 7. the resident path (device_batch.py) against the per-call one: the same kernel
    # on the same data, so bitwise; then the same with a capacity overflow to regrow
    res["resident"] = resident_against_per_call(base, p, dt)
    res["resident_overflow"] = resident_against_per_call(small, p, dt)

    # 9. groups of two sphere counts updated in turn keep one scratch each
    t0 = time.perf_counter()
    res["alternating"] = alternating_shapes(base, p, dt)
    res["alternating"]["seconds"] = time.perf_counter() - t0

    # 10. a block's scratch reused by the RVEs it runs one after another
    t0 = time.perf_counter()
    res["blocks"] = more_rves_than_blocks(base, p, dt)
    res["blocks"]["seconds"] = time.perf_counter() - t0

    # 14. the device batch's bookkeeping: build, constants, remove, means, NaN flags
    res["units"] = device_units(base)


def device_units(base: RVEBatch) -> dict:
    """Section 14 (fast): the device batch's bookkeeping without stepping. A batch built
    on the device from a library of two packings by an unsorted assignment (its lean
    host rows, device arrays and per-RVE constants against the batch concatenated on
    the host), rows removed (against state.remove_rves: the order, the moved rows and
    their constants), the mean accumulated rotation (against the host's mean over each
    row, rot made distinct per sphere), and the not-finite flags with a NaN in one RVE's
    stress and an infinity in another's spins."""
    lib = [base.take([0]), base.take([1])]
    rng = np.random.default_rng(7)
    for b in lib:
        b.rot[:] = rng.uniform(0.0, 2.0, b.rot.shape)
    asg = np.array([1, 0, 1, 1, 0])
    k = longest_row(lib) + 1
    ref = concatenate([with_capacity(lib[i].copy(), k) for i in asg])
    built = DeviceBatch.from_library(lib, asg, k)
    everything = np.arange(len(asg))
    res = {"build": _same(built.take(everything), ref),
           "host_rows": _same(built.host, ref, ("h", "stress", "stiffness", "ncontact",
                                                "unbalanced", "kinetic", "n_particles")),
           "constants_differ": bool(any(not np.array_equal(v[0], v[1]) for v in
                                        rve_constants(concatenate(lib)).values()))}
    ref_c = rve_constants(ref)
    res["constants"] = {key: bool(np.array_equal(v, ref_c[key]))
                        for key, v in built.constants.items()}
    mean = built.mean_rotation()
    res["mean_rotation"] = rel(ref.rot.mean(axis=1), mean)
    order = built.remove([0, 2])
    kept, order_host = remove_rves(ref.copy(), [0, 2])
    res["removed"] = {"order": bool(np.array_equal(order, order_host)),
                      **_same(built.take(np.arange(built.n_rve)), kept),
                      "host_rows": all(_same(built.host, kept, ("h", "stress",
                                                                "n_particles")).values())}
    kept_c = rve_constants(kept)
    res["constants_after_remove"] = {key: bool(np.array_equal(v, kept_c[key]))
                                     for key, v in built.constants.items()}
    clean = built.not_finite().tolist()
    bad = DeviceBatch(ref.copy())
    bad.host.stress[1, 2, 0] = np.nan
    bad.host.w[3, 5, 1] = np.inf
    bad.push()
    res["not_finite"] = [clean, bad.not_finite().tolist()]
    return res


def more_cases(base, p, dt, ctrl, still, res) -> None:
    """Sections 3-6, 12 and 13, and section 1's shear run twice on the device: bitwise
    the same."""
    first, again = base.copy(), base.copy()
    engine.advance(first, SHEAR_STEPS, dt, p, ctrl, device="cuda")
    engine.advance(again, SHEAR_STEPS, dt, p, ctrl, device="cuda")
    res["bitwise_rerun"] = all(
        np.array_equal(getattr(first, f), getattr(again, f))
        for f in ("s", "v", "w", "ft", "stress", "force", "torque", "nbr_j", "unbalanced"))

    # 3. momentum in a fixed periodic cell without damping: contact forces are pairwise
    # opposite, so sum m v stays at its initial value up to round-off
    gpu = base.copy()
    p0 = np.einsum("rn,rnk->rk", gpu.mass, gpu.v)
    engine.advance(gpu, 15, dt, p, still, device="cuda")
    p1 = np.einsum("rn,rnk->rk", gpu.mass, gpu.v)
    scale = np.einsum("rn,rnk->r", gpu.mass, np.abs(gpu.v)).max()
    res["momentum_rel"] = float(np.abs(p1 - p0).max() / scale)
    res["force_sum_rel"] = float(np.abs(gpu.force.sum(axis=1)).max()
                                 / np.abs(gpu.force).max())

    # 4. damping and a normal dashpot (restitution 0.7), one RVE taking no step, a block
    # larger than the RVE (idle threads)
    pd = engine.ContactParams(p.young, p.stiffness_ratio, p.friction, 0.1, p.skin,
                              restitution=0.7)
    cpu, gpu = base.copy(), base.copy()
    engine.advance(cpu, [0, 15], dt, pd, ctrl)
    block_size(32)
    engine.advance(gpu, [0, 15], dt, pd, ctrl, device="cuda")
    block_size(THREADS)
    res["damped"] = compare(cpu, gpu)
    res["damped"]["untouched"] = all(
        np.array_equal(getattr(base, f)[0], getattr(gpu, f)[0])
        for f in ("s", "v", "w", "ft", "stress", "step_count", "ncontact", "kinetic"))
    # 5. a particle named by more half-list entries than the reverse list holds (2 K):
    # 12 spheres on an icosahedron 2.25 mm around a 13th, last by index. All are 1 mm
    # spheres, so the list cutoff is 2.3 mm: each outer sphere lists the centre one
    # (no contact, 0.25 mm apart) but not its icosahedral neighbours (2.37 mm apart).
    # Every row holds at most one entry and fits K = 3, while the centre sphere is named
    # 12 > 6 times; engine.advance regrows K to at least 6 and retries. A touching pair
    # elsewhere in the cell gives a tangential history to compare.
    gold = (1.0 + 5.0 ** 0.5) / 2.0
    ico = np.array([(0.0, a, b * gold) for a in (-1, 1) for b in (-1, 1)]
                   + [(a, b * gold, 0.0) for a in (-1, 1) for b in (-1, 1)]
                   + [(b * gold, 0.0, a) for a in (-1, 1) for b in (-1, 1)])
    ico /= np.linalg.norm(ico, axis=1)[:, None]
    centre = np.full(3, 6.0e-3)
    pos = np.array([[0.5e-3, 0.5e-3, 0.5e-3], [2.48e-3, 0.5e-3, 0.5e-3]]
                   + [centre + 2.25e-3 * d for d in ico] + [centre])
    star = from_packing(np.eye(3) * 12.0e-3, pos, np.full(len(pos), 1.0e-3), 2500.0,
                        capacity=3)
    rng = np.random.default_rng(7)
    star.v[0] = rng.normal(0.0, 0.01, star.v[0].shape)
    star.w[0] = rng.normal(0.0, 10.0, star.w[0].shape)
    star.need_rebuild[:] = 1
    cpu, gpu = star.copy(), star.copy()
    engine.advance(cpu, 8, dt, p, engine.rate_control(1))
    engine.advance(gpu, 8, dt, p, engine.rate_control(1), device="cuda")
    res["reverse_overflow"] = compare(cpu, gpu)
    res["reverse_overflow"]["named"] = int(np.count_nonzero(gpu.nbr_j[0] == len(pos) - 1))
    res["reverse_overflow"]["longest_row"] = int(cpu.nbr_count.max())

    # 6. radii spread 2.5x (0.6-1.5 mm): each pair's own cutoff r_i + r_j + skin lists
    # far fewer pairs than the common 2 r_max + skin; both builds must list the same
    # ones. One RVE of 48 spheres, rebuilt at the start and sheared through 12 steps
    wide, pw, dtw = agitated_dense_state(n=48, seed=11, radii=(0.6e-3, 1.5e-3),
                                         compress_steps=1400)
    wide.need_rebuild[:] = 1
    cpu, gpu = wide.copy(), wide.copy()
    shear = engine.rate_control(1, l_ctrl=[[0.0, 400.0, 0.0], [0.0, 0.0, 0.0],
                                           [0.0, 0.0, -20.0]], max_rate=50.0)
    engine.advance(cpu, 12, dtw, pw, shear)
    engine.advance(gpu, 12, dtw, pw, shear, device="cuda")
    res["wide"] = compare(cpu, gpu)
    res["wide"]["listed"] = int(gpu.nbr_count.sum())
    common = 2.0 * gpu.radius.max() + pw.skin
    res["wide"]["common"] = len(brute_pairs(gpu.h[0], gpu.s[0] - np.floor(gpu.s[0]),
                                            gpu.radius[0], lambda i, j: np.full(len(i), common)))

    # 12. a batch built on the device from a library, kept there (device_batch.py)
    res["device_built"] = device_built(base, p, dt)

    # 13. an RVEMaterial whose batch is built on the device, against one on the CPU
    res["lean_material"] = lean_material(base, p)

    # 16. clumps (cuda_rigid.py): rigid bodies of two spheres sheared through rebuilds
    res["clumps"] = clumps_sheared()


def clumps_sheared() -> dict:
    """Section 16: 120 two-sphere clumps (aspect 1.6) consolidated to 100 kPa on the CPU,
    then 40 steps of a shear of 10 % under a normal-stress servo on both devices: the
    rigid-body step, the pairs dropped inside clumps, the members' images and the
    branch between centres in the stress, through list rebuilds."""
    rng = np.random.default_rng(3)
    shape = clump.template("elongated", aspect=1.6, spheres=2)
    h, pos, q, grains = generate.insert_clumps(120, 1e-3, 1.4e-3, shape, 0.75, rng)
    base = from_clumps(h, pos, q, grains, 2650.0)
    p = engine.ContactParams(young=1e8, stiffness_ratio=0.5, friction=0.3, damping=0.3,
                             skin=2e-4)
    dt = engine.critical_dt(base, p)
    generate.consolidate(base, p, 1e5, dt, 5.0, 0.05, 1e-4)
    rate = 0.1 / (40 * dt)
    ctrl = engine.rate_control(1, l_ctrl=[[0.0, rate, 0.0], [0.0, 0.0, 0.0],
                                          [0.0, 0.0, 0.0]], servo={2: -1e5},
                               max_rate=0.1 * rate)
    cpu, gpu = base.copy(), base.copy()
    engine.advance(cpu, 40, dt, p, ctrl)
    engine.advance(gpu, 40, dt, p, ctrl, device="cuda")
    out = compare(cpu, gpu)
    out.update({name: rel(getattr(cpu, name), getattr(gpu, name))
                for name in ("bs", "bv", "bw", "bq", "bl")})
    out["same_images"] = bool(np.array_equal(cpu.image, gpu.image))
    out["no_inner_pairs"] = all(
        bool(np.all(b.body[0, b.nbr_j[0, i, :b.nbr_count[0, i]]] != b.body[0, i]))
        for b in (cpu, gpu) for i in range(b.n_particles))
    out["rebuilt"] = [bool(not np.array_equal(base.h_ref[0], x.h_ref[0])) for x in (cpu, gpu)]
    return out


if __name__ == "__main__":
    args = sys.argv[1:]
    if args and args[0].startswith("--compile-first="):  # for the tests that run before these
        sys.path.insert(0, str(Path(__file__).parents[1]))
        import warm_kernels
        warm_kernels.main(args.pop(0).split("=", 1)[1].split(","))
    main(args or ["kernel", "kernel_more", "coupled"])

"""The CUDA DEM kernel (dem/cuda_kernel.py) against the CPU path, on numba's simulator
(and on a real GPU where one is usable), and the errors of an unknown or unavailable
device.

The kernel runs in a subprocess with NUMBA_ENABLE_CUDASIM=1 (cuda_sim_cases.py): the
variable is read when numba is imported, and must not leak into this process, whose
other tests use the compiled CPU kernels. Tiny batches (2-3 RVEs of 24 spheres, 4-40
steps): shear through list rebuilds, capacity overflow, the resident path, scratch kept
per shape and blocks running several RVEs in the fast tier, the other kernel cases with
shrunk coupled runs (one or two RVEs of 90 spheres, 5-10 MPM steps) in the validation
tier (minutes: the simulator runs each GPU thread as a Python thread). The same cases
run once more without the simulator when a subprocess can launch a CUDA kernel (skipped
otherwise, as on machines without a GPU; on an H100 all pass, docs/performance.md); the
simulator itself runs anywhere, so a simulator that cannot run a kernel fails them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import numpy as np
import pytest

from grainscale.cli import main
from grainscale.config.base import ConfigError
from grainscale.config.case import SolverCfg
from grainscale.dem import engine
from grainscale.dem.state import allocate

HERE = Path(__file__).parent

# Relative tolerance of CPU-vs-GPU agreement, max |cpu - gpu| / max |cpu| per array,
# after up to 40 steps. Both are float64 (eps 1.1e-16) and evaluate the same formulas,
# but not the same sequence of roundings: the CPU kernels are LLVM fast-math (FMA
# contraction, reassociation), NVVM contracts multiply-adds its own way (the simulator
# none), rows rebuilt on the device are ordered by j (the CPU's cell list orders them
# otherwise) and the stress and energy sums are split over threads. Such differences of
# a few ulps per operation grow through the contact dynamics; observed <= 6e-14 here.
# 1e-11 leaves two orders of margin and still sits far below a physical error: dropping
# the pseudo-force of one velocity component, or one term of the kinetic stress, from
# the device kernel showed here as 5e-4 to 3e-2 in these arrays.
RTOL = 1e-11


# a subprocess that exits 0 only if numba.cuda imports and runs a kernel
PROBE = """
import numpy as np
from numba import cuda
@cuda.jit
def one(a):
    a[cuda.threadIdx.x] = 1.0
a = cuda.to_device(np.zeros(4))
one[1, 4](a)
assert a.copy_to_host().sum() == 4.0
"""


def _env(simulator: bool) -> dict:
    env = dict(os.environ)
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    if simulator:
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    env["NUMBA_NUM_THREADS"] = "1"
    src = str(Path(engine.__file__).parents[2])
    env["PYTHONPATH"] = os.pathsep.join([src, env.get("PYTHONPATH", "")])
    return env


# the cuda_sim_cases.py parts of each fixture, and the simulator runs started ahead
FIXTURE_PARTS = {"sim": ("kernel",), "sim_long": ("kernel_more", "coupled")}
_AHEAD: dict[tuple[str, ...], subprocess.Popen] = {}


def _start(parts: tuple[str, ...], simulator: bool, compile_first=()) -> subprocess.Popen:
    first = [f"--compile-first={','.join(compile_first)}"] if compile_first else []
    return subprocess.Popen([sys.executable, str(HERE / "cuda_sim_cases.py"), *first, *parts],
                            env=_env(simulator), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=HERE)


def start_simulator_ahead(fixtures: set[str], compile_first=()) -> None:
    """Start the simulator's runs of `fixtures` (names in FIXTURE_PARTS) in the
    background, the first of them after compiling tests/warm_kernels.py's
    `compile_first` kernels, which it needs too. tests/conftest.py calls this once the
    session's tests are selected and moves this module's tests last: the simulator is
    single-threaded Python, so its minutes overlap the other tests instead of adding to
    them."""
    for name in sorted(fixtures, key=lambda n: n != "sim"):  # the fast tier's first
        parts = FIXTURE_PARTS[name]
        if parts not in _AHEAD:
            _AHEAD[parts] = _start(parts, simulator=True, compile_first=compile_first)
            compile_first = ()


def stop_simulator_ahead() -> None:
    """Kill the runs started ahead that no test waited for (an interrupted session)."""
    for proc in _AHEAD.values():
        proc.kill()
        proc.wait()
    _AHEAD.clear()


def _cases(mode: str, *parts: str) -> dict:
    """The measured differences of cuda_sim_cases.py's `parts` (one subprocess for all
    the tests of a fixture), on numba's simulator or on a real GPU if one can run a
    kernel here."""
    env = _env(mode == "simulator")
    probe = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                           text=True, cwd=HERE, timeout=300)
    if probe.returncode != 0:
        why = [ln for ln in probe.stderr.splitlines() if "Error" in ln][-1:] or ["?"]
        if mode == "simulator":  # numba's simulator runs anywhere: its failure is ours
            pytest.fail(f"numba's CUDA simulator cannot run a kernel ({why[0]}): "
                        f"{probe.stderr[-2000:]}")
        pytest.skip(f"{mode}: numba.cuda cannot run a kernel here ({why[0]})")
    proc = _AHEAD.pop(parts, None) if mode == "simulator" else None
    proc = proc or _start(parts, simulator=mode == "simulator")
    try:
        stdout, stderr = proc.communicate(timeout=900)
    finally:
        proc.kill()  # a no-op once it has exited
    assert proc.returncode == 0, stderr[-3000:]
    res = json.loads(stdout.strip().splitlines()[-1])
    res["mode"] = mode
    return res


@pytest.fixture(scope="module", params=["simulator", "gpu"])
def sim(request) -> dict:
    """The kernel's core cases: shear through list rebuilds, capacity overflow, the
    resident path; tiny batches against the CPU (under a minute on the simulator)."""
    return _cases(request.param, *FIXTURE_PARTS["sim"])


@pytest.fixture(scope="module", params=["simulator", "gpu"])
def sim_long(request) -> dict:
    """The kernel's further cases (momentum, damping and idle threads, reverse-list
    overflow, spread radii) and `grainscale run --device cuda` against the CPU (minutes
    on the simulator): the validation tier."""
    return _cases(request.param, *FIXTURE_PARTS["sim_long"])


ARRAYS = ("s", "v", "w", "rot", "ft", "stress", "stress_servo", "stiffness", "force",
          "torque", "h", "L", "unbalanced", "kinetic")


def test_sheared_batch_agrees_with_cpu_through_list_rebuilds(sim):
    res = sim["shear"]
    assert sim["available"]
    assert all(res["rebuilt"]) and all(res["rebuilt_cpu"]), "the shear must rebuild lists"
    for name in ARRAYS:
        assert res[name] < RTOL, (name, res[name])
    # integers and list contents exactly: contacts, steps, row lengths, (j, image) pairs
    assert res["same_counts"] and res["same_pairs"]


def test_rolling_resistance_agrees_with_cpu(sim):
    """The rolling moment (kernel.contact_pass; 6 history components a slot) on the
    device: the same shear as above with alpha_r = 1, eta_r = 0.3, moments built from
    zero, turned, capped and carried through the list rebuilds."""
    res = sim["rolling"]
    assert res["history"] == [6, 6]
    assert res["moment_max"] > 0.0
    for name in ARRAYS:
        assert res[name] < RTOL, (name, res[name])
    assert res["same_counts"] and res["same_pairs"]


def test_hertz_mindlin_agrees_with_cpu(sim):
    """The Hertz-Mindlin law with its dashpot on the device (kernel.contact_pass's
    branch): the same shear, and the largest overlap delta/R* each path reports (which
    the overlap bound reads) equal to 3 significant digits (the error prints them so)."""
    res = sim["hertz"]
    for name in ARRAYS:
        assert res[name] < RTOL, (name, res[name])
    assert res["same_counts"] and res["same_pairs"]
    assert res["overlaps"][0] is not None and res["overlaps"][0] == res["overlaps"][1]


@pytest.mark.validation
def test_clumps_agree_with_cpu_through_list_rebuilds(sim_long):
    """Rigid clumps on the device (cuda_rigid.py; issue 58): a packing of two-sphere
    clumps sheared 10 % through list rebuilds agrees with the CPU kernel in the members'
    state and forces and in the bodies' centres, velocities, orientations and angular
    momenta (1e-11, the spheres' tolerance), with the same pairs, images and counts and
    no pair inside a clump listed."""
    res = sim_long["clumps"]
    assert all(res["rebuilt"]), "the shear must rebuild the lists"
    for name in (*ARRAYS, "bs", "bv", "bw", "bq", "bl"):
        assert res[name] < RTOL, (name, res[name])
    assert res["same_counts"] and res["same_pairs"] and res["same_images"]
    assert res["no_inner_pairs"]


@pytest.mark.validation
def test_damping_dashpot_idle_threads_and_an_rve_without_steps(sim_long):
    res = sim_long["damped"]
    for name in ARRAYS:
        assert res[name] < RTOL, (name, res[name])
    assert res["same_counts"] and res["same_pairs"]
    assert res["untouched"]  # the RVE given 0 steps keeps its state and reports


@pytest.mark.validation
def test_pair_cutoffs_of_widely_spread_radii_list_the_same_pairs(sim_long):
    """Radii 0.6-1.5 mm: the device's brute-force build and the CPU's cell list keep the
    pairs within r_i + r_j + skin, the same ones, through 12 sheared steps."""
    res = sim_long["wide"]
    assert res["same_counts"] and res["same_pairs"]
    for name in ARRAYS:
        assert res[name] < RTOL, (name, res[name])
    # the common cutoff 2 r_max + skin would list well over a third more: the case
    # tells pair cutoffs from it
    assert res["common"] > 1.33 * res["listed"], (res["common"], res["listed"])


@pytest.mark.validation
def test_device_runs_are_bitwise_reproducible(sim_long):
    # the simulator interleaves its threads freely, so this also covers the order of
    # the integer atomics of the reverse list (sorted before use)
    assert sim_long["bitwise_rerun"]


def test_device_batch_bookkeeping(sim):
    """device_batch.DeviceBatch without stepping (cuda_sim_cases.device_units): built
    from a library by an unsorted assignment, bitwise the host's concatenation (device
    arrays, lean host rows, per-RVE constants of two packings that differ); rows
    removed as state.remove_rves removes them (order, rows, constants); the mean
    rotation the host's mean over each row to round-off (another summation order; a
    mean over n - 1 is off by 1/n = 4 %); the not-finite flags on exactly the RVEs with
    a NaN in the stress and an infinity in the spins."""
    res = sim["units"]
    assert res["constants_differ"]  # else an indexing mistake could not show
    assert all(res["build"].values()), res["build"]
    assert all(res["host_rows"].values()), res["host_rows"]
    assert all(res["constants"].values()), res["constants"]
    assert res["mean_rotation"] < 1e-14
    assert all(res["removed"].values()), res["removed"]
    assert all(res["constants_after_remove"].values()), res["constants_after_remove"]
    assert res["not_finite"] == [[False] * 3, [False, True, False, True, False]]


def test_capacity_overflow_is_regrown_by_engine(sim):
    res = sim["overflow"]
    assert res["capacity"][0] == res["capacity"][1] > 3
    assert res["same_counts"] and res["same_pairs"]
    for name in ARRAYS:
        assert res[name] < RTOL, (name, res[name])


@pytest.mark.validation
def test_reverse_list_overflow_is_regrown_by_engine(sim_long):
    """One sphere named by 12 half-list entries, rows of K = 3 (2 K reverse slots): the
    device stops with OVERFLOW, engine.advance regrows K, and the retried steps agree
    with the CPU, whose rows (one entry at most) never overflowed: it keeps K = 3."""
    res = sim_long["reverse_overflow"]
    assert res["named"] == 12 and res["longest_row"] == 1
    assert res["capacity"][0] == 3 and res["capacity"][1] >= 6
    assert res["same_counts"] and res["same_pairs"]
    for name in ARRAYS:
        assert res[name] < RTOL, (name, res[name])


@pytest.mark.validation
def test_momentum_is_conserved_in_a_fixed_periodic_cell(sim_long):
    # no damping, no cell motion: pairwise-opposite contact forces leave sum m v fixed
    assert sim_long["momentum_rel"] < 1e-13
    assert sim_long["force_sum_rel"] < 1e-13


@pytest.mark.validation
def test_a_material_built_on_the_device_agrees_with_the_cpu(sim_long):
    """RVEMaterial with device "cuda" builds its batch on the device (lean host) and
    still does all a run needs: two quasi-static updates of 4 points in which point 0's
    cell is squeezed below the retiling width (taken from the device, doubled, the rest
    staying there), the state a checkpoint gathers in chunks (one RVE each here), the
    point fields from the per-RVE constants, the wave speed and one RVE for a probe:
    equal to the CPU material's to the module's round-off tolerance."""
    res = sim_long["lean_material"]
    assert res["lean"]
    assert res["groups"] == [[24, 48], [24, 48]] and res["retiled"] == [1, 1]
    for key in ("initial_stress", "stress", "wave_speed", "rve"):
        assert res[key] < RTOL, (key, res[key])
    for key, value in {**res["state"], **res["fields"]}.items():
        assert value < RTOL, (key, value)
    for same_pairs, diff in res["ft"]:
        assert same_pairs and diff < RTOL


@pytest.mark.parametrize("case", ["resident", "resident_overflow"])
def test_resident_state_equals_the_per_call_path_bitwise(sim, case):
    """State kept on the device across two increments (device_batch.py) against the
    same calls copying the state down and up each time: the same kernel on the same
    data, so every array agrees bitwise; the second case starts with a capacity of 3,
    widened on the device (DeviceBatch.grow) and on the host alike. Only the small
    per-RVE results crossed each call: at most the issue's 1 KB per RVE and MPM step
    (measured 468 B, 2 RVEs)."""
    res = sim[case]
    assert res["same_results"]
    assert res["stale_before_pull"]  # positions really stayed on the device
    # one field pulled alone (the frames' step_count) is the device's, and counted
    assert res["pull_field"]["same"]
    assert res["pull_field"]["bytes"] == res["pull_field"]["nbytes"] > 0
    assert all(res["same_state"].values()), res["same_state"]
    start, per_call, resident = res["capacity"]
    assert per_call == resident
    if case == "resident_overflow":
        assert start == 3 and resident > start
    assert res["bytes_per_rve_call"] <= 1024


@pytest.mark.validation  # ~15 s of simulator: the fast tier's budget is spent
def test_a_batch_built_on_the_device_equals_the_uploaded_one_bitwise(sim_long):
    """DeviceBatch.from_library (two 24-sphere packings copied on the device by an
    assignment of 5 RVEs) against the same batch concatenated on the host and uploaded:
    every state array bitwise equal after the build, after a shear increment, after
    rows are taken and put back swapped, after two rows are removed (the order of
    state.remove_rves), after the lists are widened on the device (grow_capacity's
    result) and after a second increment: the device copies, gathers, scatters and
    moves rows exactly. The host keeps only the per-RVE arrays (~540 B an RVE, against
    ~10 kB of state for these 24 spheres): its per-sphere arrays are read-only NaN
    placeholders, so a read that forgets the device cannot pass for data."""
    res = sim_long["device_built"]
    for stage in ("build", "stepped", "per_rve_current", "put", "removed", "grown",
                  "stepped_again"):
        assert all(res[stage].values()), (stage, res[stage])
    assert all(res["constants"].values()) and res["constants_after_remove"]
    start, capacity, built = res["capacity"]
    assert capacity == built < start  # the longest row plus one slot, not the 16
    assert res["grown_capacity"] == [capacity + 5] * 2
    # an overflow inside engine.advance widens a lean batch's lists on the device, in
    # its own host object (which a material's groups hold), as the uploaded batch's
    over = res["overflow"]
    assert all(over["same"].values()), over["same"]
    assert over["capacity"][1] == over["capacity"][2] > 3
    assert over["same_host_object"] and over["counts"]
    # per RVE: 7 (3,3) float64 arrays (504 B) and 5 counters of 8 B (step_count,
    # unbalanced, kinetic) or 4 B (need_rebuild, ncontact): 536 B
    assert res["host_bytes_per_rve"] == 536
    assert res["state_bytes_per_rve"] > 15 * res["host_bytes_per_rve"]
    assert res["radius_placeholder_nan"] and res["placeholder_read_only"]


def test_groups_of_two_sizes_updated_in_turn_keep_their_scratch(sim):
    """A retiled material's groups (24 and 48 spheres here) are launched in turn every
    update: each shape's scratch is allocated once and reused, and the states equal
    bitwise those of the same updates with fresh scratch at every launch."""
    res = sim["alternating"]
    assert res["shapes"] == [[2, 24, 16], [1, 48, 16]] * 2
    assert res["allocations"] == 2
    assert res["same_state"]


def test_scratch_keeps_the_shapes_used_last(monkeypatch):
    """_scratch holds SCRATCH_SHAPES shapes and frees the least recently used first
    (host arrays stand in for the device's: no GPU needed)."""
    cuda_kernel = pytest.importorskip("grainscale.dem.cuda_kernel")
    made = []
    monkeypatch.setattr(cuda_kernel, "cuda", types.SimpleNamespace(
        device_array=lambda shape, dtype: made.append(shape) or np.empty(shape, dtype)))
    monkeypatch.setattr(cuda_kernel, "_SCRATCH", {})
    monkeypatch.setattr(cuda_kernel, "SCRATCH_SHAPES", 2)
    a = cuda_kernel._scratch(2, 24, 16)
    b = cuda_kernel._scratch(1, 48, 16)
    assert cuda_kernel._scratch(2, 24, 16) is a and len(made) == 18  # nine arrays a shape
    c = cuda_kernel._scratch(1, 48, 20)  # frees (1, 48, 16), used longest ago
    assert list(cuda_kernel._SCRATCH) == [(2, 24, 16), (1, 48, 20)]
    assert cuda_kernel._scratch(2, 24, 16) is a and cuda_kernel._scratch(1, 48, 20) is c
    assert cuda_kernel._scratch(1, 48, 16) is not b and len(made) == 36
    assert a[0].shape == (2, 24, 16, 6) and a[1].shape == (2, 24, 32)


@pytest.mark.parametrize("blocks", ["1", "2"])
def test_a_block_running_several_rves_agrees_with_cpu(sim, blocks):
    """3 RVEs of different packings on 1 or 2 blocks: a block's scratch (the reverse
    list kept between steps, above all) serves RVE g, then g + B. Lists are up to date
    at the start, so an RVE that took over its predecessor's reverse list instead of
    making its own would show here. Force and torque, the scratch of the block's last
    RVE, are not copied back when RVEs outnumber blocks (advance_batch)."""
    res = sim["blocks"]
    assert res["lists_up_to_date"]
    res = res[blocks]
    assert res["same_as_3"]  # bitwise the state of one block per RVE
    assert res["same_counts"] and res["same_pairs"]
    for name in ARRAYS:
        if name not in ("force", "torque"):
            assert res[name] < RTOL, (name, res[name])


@pytest.mark.validation
def test_resident_run_retiles_writes_probes_and_resumes_bitwise(sim_long):
    """`grainscale run --device cuda` of the shrunk column with every cell doubled at its
    first update, a probe RVE and a checkpoint every 2 steps, its geostatic stage (7
    steps): stopped after 3 and resumed, it writes the uninterrupted run's history and
    probe frames to the byte, and its history is the CPU's within RUN_RTOL (below)."""
    res = sim_long["coupled"]["retiled"]
    assert res["rows"] >= 4 and res["probe_files"] > 0
    assert res["particles"] == 180  # every 90-sphere cell was doubled on the device path
    assert res["same_history"] and res["same_probe"]
    assert res["cpu_rel"] < RUN_RTOL, res["cpu_rel"]


# Relative tolerance of the coupled runs' histories (`grainscale run --device cuda`
# against the CPU, max |cpu - cuda| / max |cpu| per column). The kernels' round-off
# differences (RTOL above) grow through 55-110 DEM steps of contact dynamics: observed
# <= 2e-10 on an H100 machine, but 1.4e-8 for the retiled column on an H200 machine,
# with the same digits from the kernel before and after its step scratch moved per
# block: the round-off of that machine's CPU and GPU code, not a change of physics.
# 1e-7 leaves room for other CPUs' code generation, and still catches a device that
# differs in physics: without the kinetic stress the column's runout differed by 1e-4
# and its kinetic energy by 3e-5.
RUN_RTOL = 1e-7


@pytest.mark.parametrize("name", ["unit_element", "column", "adaptive_unit_element",
                                  "sleeping_column", "clumped_unit_element"])
@pytest.mark.validation
def test_coupled_runs_agree_with_cpu(sim_long, name):
    """The MPM on the CPU with the RVEs on the device, dH and stress exchanged once per
    MPM step: the shrunk unit element (lateral tractions), the same with quasi-static
    RVEs and adaptive updates (the RVE waits some steps: its deferred increment and
    predicted stress on the device's path), the column (geostatic stage, release,
    real-time RVEs), the same with sleeping RVEs (some sleep, then wake owing several
    steps' increments) and the unit element of clumped RVEs, each cell doubled on the
    device path at its first update, give the CPU's history."""
    res = sim_long["coupled"][name]
    if name == "clumped_unit_element":
        assert res["particles"] == [560.0]  # 140 clumps of 2 spheres, doubled
    assert res["rows"] >= 4
    if name in ("adaptive_unit_element", "sleeping_column"):
        assert 0.0 < res["stepped"] < 1.0
    else:
        assert res["stepped"] == 1.0
    if "column" not in name:  # the run loaded its point: strain and confinement
        assert res["last"]["axial_strain"] > 2e-5 and res["last"]["p"] > 9e4
    else:  # released and moving
        assert res["last"]["t_over_tc"] > 0 and res["last"]["kinetic_energy"] > 0
    for column, diff in res.items():
        if column not in ("rows", "last", "stepped", "particles"):
            assert diff < RUN_RTOL, (column, diff)


# ----------------------------------------------------------- unknown / missing device
def _no_gpu(monkeypatch):
    from grainscale.dem import cuda_kernel

    monkeypatch.setattr(cuda_kernel, "is_available", lambda: False)


def test_unknown_device_is_refused():
    with pytest.raises(engine.DeviceError, match=r"solver\.device = 'gpu'.*'cpu', 'cuda'"):
        engine.check_device("gpu")
    b = allocate(1, 4)
    with pytest.raises(ConfigError, match="solver.device"):
        engine.advance(b, 1, 1e-6, engine.ContactParams(1e6, 0.5, 0.5, 0.0),
                       engine.rate_control(1), device="gpu")


def test_cuda_without_gpu_names_the_key_and_the_values(monkeypatch):
    _no_gpu(monkeypatch)
    b = allocate(1, 4)
    before = b.copy()
    with pytest.raises(engine.DeviceError, match=r"solver\.device = 'cuda'.*'cpu'"):
        engine.advance(b, 1, 1e-6, engine.ContactParams(1e6, 0.5, 0.5, 0.0),
                       engine.rate_control(1), device="cuda")
    assert np.array_equal(b.s, before.s)


def test_case_file_device_key():
    assert SolverCfg().device == "cpu"
    assert SolverCfg(device="cuda").device == "cuda"
    with pytest.raises(ValueError, match="device"):
        SolverCfg(device="gpu")


def test_cli_device_cuda_without_gpu_exits_2(tmp_path, monkeypatch, capsys):
    _no_gpu(monkeypatch)
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent("""
        [grid]
        cell_size = 0.1
        cells = [2, 2, 2]
        [time]
        end = 0.01
        [materials.soil]
        type = "linear_elastic"
        density = 1000.0
        youngs_modulus = 1e6
        poisson_ratio = 0.3
        [[bodies]]
        shape = "box"
        material = "soil"
        lo = [0.0, 0.0, 0.0]
        hi = [0.1, 0.1, 0.1]
        [output]
        interval = 0.005
        """))
    code = main(["run", str(case), "--out", str(tmp_path / "out"), "--device", "cuda",
                 "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "solver.device = 'cuda'" in err and "'cpu'" in err
    assert not (tmp_path / "out" / "frames").exists()  # refused before any work


def test_ranks_of_a_node_share_its_gpus_round_robin(monkeypatch):
    """Under MPI each rank selects GPU node_rank % (visible GPUs) before any kernel; one
    visible GPU per rank (CUDA_VISIBLE_DEVICES set per rank) gives device 0 to all."""
    cuda_kernel = pytest.importorskip("grainscale.dem.cuda_kernel")
    chosen = []
    monkeypatch.setattr(cuda_kernel, "cuda", types.SimpleNamespace(
        gpus=[object()] * 4, select_device=chosen.append))
    assert [cuda_kernel.select_gpu(r) for r in range(6)] == [0, 1, 2, 3, 0, 1]
    assert chosen == [0, 1, 2, 3, 0, 1]
    monkeypatch.setattr(cuda_kernel.cuda, "gpus", [object()])
    assert [cuda_kernel.select_gpu(r) for r in range(3)] == [0, 0, 0]

"""Distributed runs under `mpiexec` (the mpich wheel installed with the package).

Each test starts a real MPI job from pytest with a timeout, so a hang fails the test
instead of blocking CI. The reference is always the serial run of the same case: the
fixed-point nodal sums and the gathered outputs make the history independent of the
number of ranks and threads, digit for digit.
"""

import json
import os
import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
import tomli_w

from example_scripts import STUDIES, load_example
from grainscale.cli import main
from grainscale.dem.retile import widths
from grainscale.io.rve_h5 import read_rve_state

sys.path.insert(0, str(Path(__file__).parent))
from test_multiscale_run import small_unit_element  # noqa: E402

MPIEXEC = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which(
    "mpiexec")
pytestmark = pytest.mark.skipif(MPIEXEC is None, reason="no mpiexec (install the mpich wheel)")

MOHR_COULOMB = """
title = "Mohr-Coulomb block slumping under gravity, with a lateral traction"
[grid]
cell_size = 0.05
cells = [6, 4, 5]
[solver]
gravity = [0.0, 0.0, -9.81]
scheme = "MUSL"
[time]
end = 0.05
[materials.soil]
type = "mohr_coulomb"
density = 1500.0
youngs_modulus = 2e6
poisson_ratio = 0.3
friction_angle = 25.0
[[bodies]]
shape = "box"
material = "soil"
lo = [0.0, 0.0, 0.0]
hi = [0.15, 0.2, 0.2]
[[boundaries]]
type = "fixed"
face = "z-"
[[boundaries]]
type = "roller"
face = "x-"
[[tractions]]
lo = [0.0, 0.0, 0.175]
hi = [0.15, 0.2, 0.2]
traction = [0.0, 0.0, -2000.0]
surface = "z+"
[output]
interval = 0.005
history = ["time", "kinetic_energy", "p", "q", "volumetric_strain"]
"""


def mpirun(n: int, args: list[str], timeout: float = 300, script: Path | None = None,
           env: dict[str, str] | None = None):
    """`mpiexec -n n python -m grainscale ARGS` (or python SCRIPT ARGS), with `env` added
    to the environment; CompletedProcess."""
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", **(env or {})}
    target = [str(script)] if script else ["-m", "grainscale"]
    return subprocess.run([MPIEXEC, "-n", str(n), sys.executable, *target, *args], env=env,
                          capture_output=True, text=True, timeout=timeout)


def interrupted_history(case: Path, out: Path, first: int, steps: int, then: int) -> str:
    """history.csv of CASE run on `first` ranks for `steps` steps (checkpoints every 4),
    then resumed to the end on `then` ranks."""
    common = ["run", str(case), "--out", str(out), "--quiet", "--checkpoint-every", "4"]
    r = mpirun(first, [*common, "--max-steps", str(steps)])
    assert r.returncode == 0, r.stderr
    r = mpirun(then, [*common, "--resume"])
    assert r.returncode == 0, r.stderr
    return (out / "history.csv").read_text()


def same_history_everywhere(path: Path, ref: Path, tmp: Path, stop_at: int) -> None:
    """CASE's history.csv is the serial run's in `ref` to the byte on 1 rank with 2
    threads, on 2 ranks, and on 3 ranks stopped at step `stop_at` and resumed on 2 (each
    from the serial run's packings, so no run regenerates them)."""
    history = (ref / "history.csv").read_text()

    def fresh(name):
        out = tmp / name
        shutil.copytree(ref / "packings", out / "packings")
        return out

    out = fresh("threads2")
    # in a process of its own: numba cannot exceed the NUMBA_NUM_THREADS it started
    # with, and a CI that exports 1 would otherwise compare 1 thread with 1
    r = subprocess.run([sys.executable, "-m", "grainscale", "run", str(path), "--out",
                        str(out), "--quiet", "--threads", "2"], capture_output=True, text=True,
                       env={**os.environ, "NUMBA_NUM_THREADS": "2"}, timeout=600)
    assert r.returncode == 0, r.stderr
    assert (out / "history.csv").read_text() == history, "2 threads differ"
    out = fresh("ranks2")
    r = mpirun(2, ["run", str(path), "--out", str(out), "--quiet"])
    assert r.returncode == 0, r.stderr
    assert (out / "history.csv").read_text() == history, "2 ranks differ"
    out = fresh("ranks3")
    assert interrupted_history(path, out, first=3, steps=stop_at, then=2) == history, \
        "3 ranks resumed on 2 differ"


COLUMN = Path(__file__).resolve().parents[2] / "examples" / "column_collapse" / "quick.toml"


def small_column(tmp: Path) -> Path:
    """The quick column collapse with every feature it uses, shrunk to run in seconds: a
    geostatic stage with nodal damping and a gate released at t = 0, dynamic RVEs (real
    time, restitution 0.9, kinetic stress) from a library of 2, AFLIP, a Coulomb floor,
    a one-sided back wall, roller side walls, and every cell doubled (retiled) at its
    first update; 96 points, RVEs of 80 spheres, ~140 steps."""
    case = tomllib.loads(COLUMN.read_text())
    case["grid"]["cells"] = [8, 2, 4]
    case["time"].update(start=-0.0015, end=0.003)
    case["bodies"][0]["hi"] = [0.04, 0.01, 0.03]
    case["boundaries"][-1]["box"] = {"lo": [0.04, 0.0, 0.0], "hi": [0.04, 0.01, 0.04]}
    case["boundaries"][-2]["box"]["hi"] = [0.08, 0.01, 0.04]
    case["output"].update(interval=1e-4, frame_interval=1e-3)
    case["output"]["column"].update(length=0.04, height=0.03)
    case["materials"]["sand"].update(retile_width=20.0, retile_max_factor=2)
    case["rve"].update(particles=80, radius_max=2.4e-3)
    case["rve"]["preparation"].update(porosity=0.41, porosity_tolerance=0.01)
    case["solver"]["rebalance_every"] = 7
    path = tmp / "column.toml"
    path.write_text(tomli_w.dumps(case))
    return path


@pytest.mark.validation
def test_column_features_are_rank_and_thread_independent(tmp_path):
    """The reduced column (small_column) gives one history.csv, to the byte, on 1 rank
    with 1 and 2 threads, on 2 ranks, and on 3 ranks stopped and resumed on 2 (with
    measured-cost rebalancing every 7 steps moving points and RVEs between ranks).
    This one case replaces the unit element's separate rank, thread and rebalancing jobs.
    The split-dependent P2G scale that parted the quick column's 1- and 2-rank runs at
    step 19 struck where a bound crossed a power of two, rarely in 140 steps, so it has a
    test of its own (test_transfer.py::test_p2g_does_not_depend_on_how_the_points_are_split)."""
    case = small_column(tmp_path)
    ref = tmp_path / "serial"
    assert main(["run", str(case), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    history = (ref / "history.csv").read_text()
    rows = [r for r in history.splitlines() if r[:1].isdigit()]
    assert len(rows) > 40
    last = meshio.read(sorted((ref / "frames").glob("frame_*.vtu"))[-1]).point_data
    assert set(np.unique(last["rve_particles"])) == {160.0}  # every cell doubled
    # studies/column_spread.py reads such a run: the last frame's points, 4 cm of column
    spread = load_example("column_spread.py", STUDIES).measures(ref, 0.04)
    assert spread["mass95"] <= spread["mass99"] <= spread["front"] + 0.5 / 4  # 1/4 cell
    assert spread["steps"] == int(rows[-1].split(",")[0])

    same_history_everywhere(case, ref, tmp_path, stop_at=60)
    assert json.loads((tmp_path / "threads2" / "cost.json").read_text())["threads"] == 2
    # rebalancing rebuilt the materials: the cost report's sums went with them
    cost = json.loads((tmp_path / "ranks2" / "cost.json").read_text())
    assert cost["fraction_of_rves_stepped"] == 1.0
    serial = json.loads((ref / "cost.json").read_text())
    assert cost["particle_steps"] == serial["particle_steps"] > 0
    assert 0 < cost["core_ns_per_particle_step"]["dem"] < cost["core_ns_per_particle_step"][
        "all_in"]
    assert json.loads((tmp_path / "ranks3" / "cost.json").read_text())["rebalances"] >= 2


@pytest.fixture(scope="module")
def rve_case(tmp_path_factory):
    """The small unit element with a library of 4 packings, so that RVEs differ (the
    CFL wave speed once depended on which RVEs shared a rank)."""
    path = small_unit_element(tmp_path_factory.mktemp("ue"), end=0.012, interval=0.0004)
    case = tomllib.loads(path.read_text())
    case["materials"]["sand"]["library"] = 4
    path.write_text(tomli_w.dumps(case))
    return path


@pytest.fixture(scope="module")
def serial_out(rve_case, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    assert main(["run", str(rve_case), "--out", str(out), "--quiet", "--threads", "1"]) == 0
    return out


@pytest.fixture(scope="module")
def serial(serial_out):
    return (serial_out / "history.csv").read_text()


@pytest.mark.validation  # 15 s of MPI jobs; the graded grid's below stays in the fast tier
def test_ranks_give_identical_history_with_tractions(tmp_path):
    """Phenomenological material, MUSL, gravity and a traction shared by the ranks."""
    case = tmp_path / "mc.toml"
    case.write_text(textwrap.dedent(MOHR_COULOMB))
    assert main(["run", str(case), "--out", str(tmp_path / "n1"), "--quiet"]) == 0
    ref = (tmp_path / "n1" / "history.csv").read_text()
    for n in (2, 3):
        r = mpirun(n, ["run", str(case), "--out", str(tmp_path / f"n{n}"), "--quiet"])
        assert r.returncode == 0, r.stderr
        assert (tmp_path / f"n{n}" / "history.csv").read_text() == ref


GRADED_CROSSING = """
title = "a block slides across a 2:1 step of cell size"
[grid]
nodes_x = [0.0, 0.025, 0.05, 0.075, 0.1, 0.15, 0.2, 0.25, 0.3]
nodes_y = [0.0, 0.05, 0.1]
nodes_z = {lo = 0.0, hi = 0.15, cell = 0.025, fine = [0.0, 0.05], ratio = 2.0}
[solver]
gravity = [0.0, 0.0, -9.81]
scheme = "MUSL"
[time]
end = 0.03
[materials.soil]
type = "mohr_coulomb"
density = 1500.0
youngs_modulus = 2e6
poisson_ratio = 0.3
friction_angle = 25.0
[[bodies]]
shape = "box"
material = "soil"
lo = [0.0, 0.0, 0.0]
hi = [0.1, 0.1, 0.1]
velocity = [2.5, 0.0, 0.0]
[[boundaries]]
type = "roller"
face = "z-"
[[tractions]]
lo = [0.0, 0.0, 0.08]
hi = [0.1, 0.1, 0.1]
traction = [0.0, 0.0, -2000.0]
surface = "z+"
[output]
interval = 0.003
frame_interval = 0.03
history = ["time", "kinetic_energy", "p", "q", "volumetric_strain"]
"""


def test_ranks_give_identical_history_on_a_graded_grid(tmp_path):
    """A block of 0.025 m cells (z graded 2 per cell above it, so points of several sizes
    and per-axis stencils) slides at 2.5 m/s on a roller floor across a 2:1 step of cell
    size in x at 0.1 m, under gravity and a traction: on 1, 2 and 3 ranks the same
    history to the last digit, and the points did cross the step (from x <= 0.1 m to
    as far as 0.17 m; the last frame's positions are checked)."""
    case = tmp_path / "graded.toml"
    case.write_text(textwrap.dedent(GRADED_CROSSING))
    assert main(["run", str(case), "--out", str(tmp_path / "n1"), "--quiet"]) == 0
    ref = (tmp_path / "n1" / "history.csv").read_text()
    assert ref.count("\n") > 5
    x = meshio.read(sorted((tmp_path / "n1" / "frames").glob("frame_*.vtu"))[-1]).points
    # 2.5 m/s for 0.03 s, slowed by the floor's reaction to the slumping: 0.05-0.075 m
    assert 0.15 < x[:, 0].max() < 0.1 + 0.075 and (x[:, 0] > 0.1).mean() > 0.3
    for n in (2, 3):
        r = mpirun(n, ["run", str(case), "--out", str(tmp_path / f"n{n}"), "--quiet"])
        assert r.returncode == 0, r.stderr
        assert (tmp_path / f"n{n}" / "history.csv").read_text() == ref


INJECT = """
import sys
from mpi4py import MPI
from grainscale.coupling import rve_material
from grainscale.mpm.step import SimulationError
KIND = {"bug": RuntimeError, "simulation": SimulationError}[sys.argv.pop(1)]
original = rve_material.RVEMaterial.update
calls = [0]

def update(self, dH, dt, stress):
    calls[0] += 1
    if MPI.COMM_WORLD.rank == 1 and calls[0] == 7:
        raise KIND("injected failure of rank 1")
    original(self, dH, dt, stress)

rve_material.RVEMaterial.update = update
from grainscale.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.validation
@pytest.mark.parametrize("kind,code", [("bug", None), ("simulation", 1)])
def test_failing_rank_ends_the_job(kind, code, rve_case, serial, tmp_path):
    """An unexpected exception on one rank aborts the job; a simulation error stops all
    ranks cleanly with exit code 1. Neither hangs, and the last checkpoint resumes."""
    script = tmp_path / "inject.py"
    script.write_text(INJECT)
    out = tmp_path / "out"
    args = [kind, "run", str(rve_case), "--out", str(out), "--quiet", "--checkpoint-every",
            "3"]
    r = mpirun(2, args, timeout=120, script=script)  # a hang is a TimeoutExpired error
    assert r.returncode != 0
    if code is not None:
        assert r.returncode == code
    assert "injected failure of rank 1" in r.stderr
    assert main(["run", str(rve_case), "--out", str(out), "--quiet", "--resume"]) == 0
    assert (out / "history.csv").read_text() == serial


@pytest.mark.validation
def test_fresh_compilation_and_cached_kernels_agree(tmp_path):
    """A run compiled from scratch and a run from numba's cache give the same bits.

    A fastmath kernel calling another jitted function compiled differently when the
    callee came from the cache (object code, no LLVM inlining) than when it was compiled
    in the same process, so the first run after an install differed in the last bits
    from later ones, and a resume could not continue it exactly. Callees of fastmath
    kernels are now inlined at numba's level (inline="always")."""
    case = tmp_path / "mc.toml"
    case.write_text(textwrap.dedent(MOHR_COULOMB))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    for name in ("cold", "warm"):
        subprocess.run([sys.executable, "-m", "grainscale", "run", str(case), "--out",
                        str(tmp_path / name), "--quiet"], env=env, check=True, timeout=600)
    cold = (tmp_path / "cold" / "history.csv").read_text()
    assert cold == (tmp_path / "warm" / "history.csv").read_text()


def test_srun_tasks_that_mpi_does_not_join_are_refused(tmp_path, monkeypatch, capsys):
    """`srun --mpi=none -n 4` would run the whole case four times into one folder."""
    case = tmp_path / "mc.toml"
    case.write_text(textwrap.dedent(MOHR_COULOMB))
    monkeypatch.setenv("SLURM_STEP_NUM_TASKS", "4")
    assert main(["run", str(case), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "srun started 4 tasks but MPI sees 1 rank" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.validation
def test_retiled_rves_are_rank_independent_and_restart(rve_case, serial_out, tmp_path):
    """Cells doubled during the run (dem/retile.py) on some points only: RVEs of two
    sizes, split over 2 ranks, checkpointed padded to one size (one part per rank), the
    newest checkpoint damaged in rank 1's part, resumed on 3 ranks: every rank falls
    back to the previous checkpoint and the run ends on the serial history. The
    threshold lies between the packings' initial narrowest widths, so the points of
    some packings double at the first step."""
    narrowest = []
    for f in sorted((serial_out / "packings").glob("sand_*.h5")):
        b, _ = read_rve_state(f)
        narrowest.append(widths(b.h)[0].min() / (2 * b.radius[0].mean()))
    narrowest = sorted(narrowest)
    assert narrowest[1] < narrowest[2]
    case = tomllib.loads(rve_case.read_text())
    case["materials"]["sand"].update({"retile_width": 0.5 * (narrowest[1] + narrowest[2]),
                                      "retile_max_factor": 2})
    path = tmp_path / "retiled.toml"
    path.write_text(tomli_w.dumps(case))
    ref = tmp_path / "serial"
    assert main(["run", str(path), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    history = (ref / "history.csv").read_text()
    assert history != (serial_out / "history.csv").read_text()  # the doubling took place
    out = tmp_path / "part"
    common = ["run", str(path), "--out", str(out), "--quiet", "--checkpoint-every", "4"]
    r = mpirun(2, [*common, "--max-steps", "9"])  # last checkpoint at step 8
    assert r.returncode == 0, r.stderr
    parts = sorted((out / "checkpoint.parts").iterdir())
    # the end-of-run one and the previous (the fallback), older ones removed
    assert [p.name for p in parts] == ["0000000008_2", "0000000009_2"]
    assert all(len(list(p.iterdir())) == 2 for p in parts)  # one part per rank
    bad = parts[1] / "rank_00001.h5"
    with h5py.File(bad, "r") as f:
        offset = f["points/x"].id.get_offset()
    with open(bad, "r+b") as fh:
        fh.seek(offset)
        byte = fh.read(1)[0]
        fh.seek(offset)
        fh.write(bytes([byte ^ 0xFF]))
    r = mpirun(3, [*common, "--resume"])
    assert r.returncode == 0, r.stderr
    assert f"warning: {bad}: array points/x does not match its checksum" in r.stderr
    assert "previous checkpoint" in r.stderr and "(step 8," in r.stderr
    assert (out / "history.csv").read_text() == history
    sizes = meshio.read(sorted((out / "frames").glob("frame_*.vtu"))[-1]).point_data
    assert set(np.unique(sizes["rve_particles"])) == {120.0, 240.0}


@pytest.mark.validation  # 13 s; the material-level tests are in the fast tier
def test_adaptive_updates_are_rank_thread_independent_and_resume_bitwise(rve_case, tmp_path):
    """The small unit element with quasi-static RVEs from 4 packings and adaptive
    updates (tolerance 1e-4 = the strain per DEM step, at most 3 deferred steps), so
    that RVEs wait or step depending on their own increments: one history.csv, to the
    byte, on 1 rank with 1 and 2 threads, on 2 ranks with rebalancing every 5 steps,
    and on 3 ranks stopped at step 9 (deferred increments in the checkpoint) and
    resumed on 2. cost.json says that RVEs did wait."""
    case = tomllib.loads(rve_case.read_text())
    case["materials"]["sand"].update(time_integration="quasi_static",
                                     allow_rve_damping=True, strain_per_substep=1e-4,
                                     update_tolerance=1e-4, max_deferred_steps=3)
    case["solver"]["rebalance_every"] = 5
    path = tmp_path / "adaptive.toml"
    path.write_text(tomli_w.dumps(case))
    ref = tmp_path / "serial"
    assert main(["run", str(path), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    history = (ref / "history.csv").read_text()
    assert history.count("\n") > 20
    stepped = json.loads((ref / "cost.json").read_text())["fraction_of_rves_stepped"]
    assert 0.3 < stepped < 0.95, stepped

    same_history_everywhere(path, ref, tmp_path, stop_at=9)


@pytest.mark.validation  # 30 s; a serial resume with sleeping RVEs is in the fast tier
def test_sleeping_rves_are_rank_thread_independent_and_resume_bitwise(tmp_path):
    """The reduced column (small_column: geostatic stage, release, retiling, rebalancing
    every 7 steps) with sleeping RVEs (tolerance 1e-5, at most 5 steps asleep): one
    history.csv, to the byte, with its cost columns, on 1 rank with 1 and 2 threads, on 2
    ranks, and on 3 ranks stopped at step 47 (RVEs asleep in the checkpoint) and resumed
    on 2; some RVEs slept."""
    sys.path.insert(0, str(Path(__file__).parent))
    from test_sleeping import sleeping_column

    path = sleeping_column(tmp_path)
    ref = tmp_path / "serial"
    assert main(["run", str(path), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    history = (ref / "history.csv").read_text()
    rows = [r.split(",") for r in history.splitlines() if r[:1].isdigit()]
    assert float(rows[-1][-1]) < 0.97 * int(rows[-1][0])  # updates_per_rve: some slept

    same_history_everywhere(path, ref, tmp_path, stop_at=47)


@pytest.mark.validation
def test_rolling_resistance_across_ranks_retiling_and_restart(rve_case, tmp_path):
    """RVEs with rolling resistance (alpha_r = 1, eta_r = 0.2: a 6-component contact
    history) whose cells are all doubled at their first update (the moments copied to
    the new pairs, negated with a reversed pair): on 2 ranks stopped at step 9 and
    resumed on 3 (the moments travel through the MPI exchange and the checkpoint's
    parts), the history is the serial run's to the byte."""
    case = tomllib.loads(rve_case.read_text())
    case["rve"].update(rolling_stiffness=1.0, rolling_friction=0.2)
    case["materials"]["sand"].update({"retile_width": 20.0, "retile_max_factor": 2})
    path = tmp_path / "rolling.toml"
    path.write_text(tomli_w.dumps(case))
    ref = tmp_path / "serial"
    assert main(["run", str(path), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    history = (ref / "history.csv").read_text()
    assert history.count("\n") > 20
    out = tmp_path / "ranks"
    shutil.copytree(ref / "packings", out / "packings")
    assert interrupted_history(path, out, first=2, steps=9, then=3) == history
    sizes = meshio.read(sorted((out / "frames").glob("frame_*.vtu"))[-1]).point_data
    assert set(np.unique(sizes["rve_particles"])) == {240.0}  # every cell doubled


@pytest.mark.validation
def test_hertz_mindlin_across_ranks_threads_and_restart(rve_case, tmp_path):
    """RVEs with Hertz-Mindlin contacts (E = 70 GPa, nu = 0.25: its own time step and
    tangent moduli in the CFL bound) and a dashpot (restitution 0.5), packings generated
    with that law: one history.csv, to the byte, on 1 rank with 1 and 2 threads, on 2
    ranks, and on 3 ranks stopped at step 9 and resumed on 2."""
    case = tomllib.loads(rve_case.read_text())
    case["rve"].pop("stiffness_ratio", None)
    case["rve"].update(contact_law="hertz_mindlin", young_modulus=70e9, poisson_ratio=0.25,
                       restitution=0.5)
    path = tmp_path / "hertz.toml"
    path.write_text(tomli_w.dumps(case))
    ref = tmp_path / "serial"
    assert main(["run", str(path), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    history = (ref / "history.csv").read_text()
    assert history.count("\n") > 20
    same_history_everywhere(path, ref, tmp_path, stop_at=9)


def test_ranks_know_their_place_on_the_node(tmp_path):
    """node_rank numbers the ranks of a node 0..n-1 (each picks GPU node_rank % GPUs
    under `--device cuda`, cuda_kernel.select_gpu); node_ranks counts them."""
    script = tmp_path / "where.py"
    script.write_text(textwrap.dedent(f"""
        from pathlib import Path
        from grainscale.distributed.comm import world
        c = world()
        Path(r"{tmp_path}", f"rank{{c.rank}}").write_text(f"{{c.node_rank()}} {{c.node_ranks()}}")
    """))
    r = mpirun(3, [], timeout=120, script=script)
    assert r.returncode == 0, r.stderr
    found = [tuple(map(int, (tmp_path / f"rank{k}").read_text().split())) for k in range(3)]
    assert found == [(0, 3), (1, 3), (2, 3)]  # one machine: one node


@pytest.mark.validation  # ~3 min: the clumped kernel variant compiles, five runs
def test_clumped_rves_across_ranks_threads_retiling_and_restart(rve_case, tmp_path):
    """RVEs of rigid two-sphere clumps (aspect 1.5, 160 clumps from a library of 4)
    whose cells are all doubled at their first update (retile.multiply_cell: bodies
    copied, each member given to the body copy its image lies in): one history.csv, to
    the byte, on 1 rank with 1 and 2 threads, on 2 ranks, and on 3 ranks stopped at step
    9 and resumed on 2 (the clump arrays travel through the MPI exchange and the
    checkpoint's parts, padded to the most clumps)."""
    case = tomllib.loads(rve_case.read_text())
    case["rve"].update(particles=160, clump={"template": "elongated", "aspect": 1.5,
                                             "spheres": 2})
    for key in ("porosity", "porosity_tolerance"):  # consolidated at 100 kPa, as clumps.toml
        del case["rve"]["preparation"][key]
    case["materials"]["sand"].update({"retile_width": 20.0, "retile_max_factor": 2})
    path = tmp_path / "clumps.toml"
    path.write_text(tomli_w.dumps(case))
    ref = tmp_path / "serial"
    assert main(["run", str(path), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    history = (ref / "history.csv").read_text()
    assert history.count("\n") > 20
    sizes = meshio.read(sorted((ref / "frames").glob("frame_*.vtu"))[-1]).point_data
    assert set(np.unique(sizes["rve_particles"])) == {640.0}  # every cell doubled

    same_history_everywhere(path, ref, tmp_path, stop_at=9)

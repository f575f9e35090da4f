"""Multiscale runs (MPM x DEM) from the command line: restart and the unit element."""

import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import h5py
import numpy as np
import pytest
import tomli_w

from grainscale.analysis import read_columns
from grainscale.cli import main
from grainscale.io.rve_h5 import read_rve_state

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "unit_element"


def small_unit_element(tmp: Path, end: float, interval: float, **rve) -> Path:
    """The unit element example with a small RVE (fewer, smaller spheres) and a short run."""
    case = tomllib.loads((EXAMPLE / "case.toml").read_text())
    case["time"]["end"] = end
    case["output"]["interval"] = interval
    case["output"]["frame_interval"] = 10 * interval
    case["rve"].update({"particles": 120, "radius_min": 2e-3, "radius_max": 3e-3, **rve})
    case["rve"]["preparation"]["porosity"] = 0.38
    case["rve"]["preparation"]["porosity_tolerance"] = 0.006
    path = tmp / "case.toml"
    path.write_text(tomli_w.dumps(case))
    return path


def run_folder_with_packings_of(ref: Path, out: Path) -> Path:
    """A new run folder `out` whose packings are those of the run in `ref` (linked: no
    run regenerates them)."""
    out.mkdir()
    (out / "packings").symlink_to(ref / "packings", target_is_directory=True)
    return out


@pytest.fixture(scope="module")
def case_file(tmp_path_factory):
    return small_unit_element(tmp_path_factory.mktemp("ue"), end=0.012, interval=0.0004)


def test_resume_continues_bitwise(case_file, tmp_path):
    full = tmp_path / "full"
    assert main(["run", str(case_file), "--out", str(full), "--quiet",
                 "--checkpoint-every", "4"]) == 0
    part = tmp_path / "part"
    # stopped after 10 steps (last checkpoint at step 8), then resumed to the end
    assert main(["run", str(case_file), "--out", str(part), "--quiet", "--max-steps", "10",
                 "--checkpoint-every", "4"]) == 0
    assert main(["run", str(case_file), "--out", str(part), "--quiet", "--resume",
                 "--checkpoint-every", "4"]) == 0
    a = (full / "history.csv").read_text()
    b = (part / "history.csv").read_text()
    assert a == b  # every digit: RVE states, contact histories, lists all restored
    assert len(a.splitlines()) > 15


@pytest.mark.validation  # 15 s cold: it compiles the rolling kernel; the law's own
# tests (tests/dem/test_rolling.py, the CUDA simulator's rolling case) stay in the fast tier
def test_rolling_resistance_runs_and_resumes_bitwise(tmp_path):
    """The unit element with rolling-resistant RVEs (alpha_r = 1, eta_r = 0.2): the
    packings are generated with it (their recipe says so), the moments live in the
    contact history (6 components a slot) and a checkpoint carries them, so a resumed
    run is the uninterrupted one to the byte; its stress differs from the same run
    without rolling resistance."""
    case = small_unit_element(tmp_path, end=0.008, interval=0.0004, rolling_stiffness=1.0,
                              rolling_friction=0.2)
    full = tmp_path / "full"
    assert main(["run", str(case), "--out", str(full), "--quiet", "--checkpoint-every",
                 "8"]) == 0
    part = tmp_path / "part"
    shutil.copytree(full / "packings", part / "packings")
    assert main(["run", str(case), "--out", str(part), "--quiet", "--max-steps", "10",
                 "--checkpoint-every", "4"]) == 0
    assert main(["run", str(case), "--out", str(part), "--quiet", "--resume"]) == 0
    history = (full / "history.csv").read_text()
    assert (part / "history.csv").read_text() == history
    batch, recipe = read_rve_state(sorted((full / "packings").glob("*.h5"))[0])
    assert recipe["rolling_stiffness"] == 1.0 and recipe["rolling_friction"] == 0.2
    assert batch.ft.shape[3] == 6 and np.abs(batch.ft[..., 3:]).max() > 0.0
    newest = sorted((full / "checkpoint.parts").iterdir())[-1]
    with h5py.File(next(newest.glob("rank_*.h5")), "r") as f:
        ft = [f[k][...] for k in _dataset_names(f) if k.endswith("rve_ft")]
    assert ft and all(a.shape[-1] == 6 for a in ft)
    assert any(np.abs(a[..., 3:]).max() > 0.0 for a in ft)  # moments carried


def _dataset_names(f):
    names = []
    f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset)
                 else None)
    return names


@pytest.mark.validation
def test_resume_after_sigkill(case_file, tmp_path):
    ref = tmp_path / "ref"
    assert main(["run", str(case_file), "--out", str(ref), "--quiet",
                 "--checkpoint-every", "3"]) == 0
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "grainscale", "run", str(case_file), "--out", str(out),
           "--quiet", "--checkpoint-every", "3"]
    proc = subprocess.Popen(cmd)  # the installed package, as a user runs it
    ckpt = out / "checkpoint.h5"
    deadline = time.monotonic() + 300
    while not ckpt.is_file() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert main(["run", str(case_file), "--out", str(out), "--quiet", "--resume",
                 "--checkpoint-every", "3"]) == 0
    assert (out / "history.csv").read_text() == (ref / "history.csv").read_text()


def test_unit_element_deforms_homogeneously(case_file, tmp_path):
    """The 8 points of the unit element carry copies of one packing under a homogeneous
    deformation. Exactly so for an elastic material (residual ~1e-19, checked by hand);
    with RVEs, each point's dH differs from the others in its last bits (different
    rounding of the nodal sums it is interpolated from), and ~1000 chaotic DEM steps per
    MPM step turn that into stress differences (measured 2.8e-3 p after 8 steps, well
    below the RVE's own noise of several %), which the traction-controlled lateral
    boundary turns into a small non-affine motion (0.9 % after 8 steps). 8 steps pass
    the first frame time (4 ms) with room: the test reads that frame."""
    out = tmp_path / "run"
    assert main(["run", str(case_file), "--out", str(out), "--quiet", "--max-steps", "8"]) == 0
    import meshio

    frames = sorted((out / "frames").glob("frame_*.vtu"))
    assert len(frames) >= 2  # a frame after the start
    last = meshio.read(frames[-1])
    cols = read_columns(out / "history.csv")
    assert cols["p"][0] == pytest.approx(100e3, rel=0.02)  # prepared at 100 kPa
    stress = last.point_data["stress"].reshape(-1, 3, 3)
    assert np.abs(stress - stress[0]).max() < 1e-2 * cols["p"][-1]
    u = last.point_data["displacement"]
    X = last.point_data["position"] - u
    A = np.c_[X, np.ones(8)]
    residual = u - A @ np.linalg.lstsq(A, u, rcond=None)[0]
    assert np.abs(residual).max() < 0.05 * np.abs(u).max()
    assert np.abs(residual[:, 2]).max() < 1e-12 * np.abs(u).max()  # axial: prescribed


def test_a_checkpoint_the_host_cannot_hold_is_refused_before_the_first_step(
        case_file, tmp_path, monkeypatch, capsys):
    """A checkpoint gathers every RVE's state on the host (all of it when the RVEs live
    on a GPU): a run whose checkpoint would take more than 80 % of the memory available
    is refused before its first step, naming the key and both sizes, and what an
    earlier run left in the folder is untouched. Here the machine is made to report
    100 kB available."""
    from grainscale.coupling import driver

    out = tmp_path / "run"
    out.mkdir()
    earlier = {"history.csv": b"step,time\n0,0\n", "checkpoint.h5": b"an earlier run's"}
    for name, data in earlier.items():
        (out / name).write_bytes(data)
    monkeypatch.setattr(driver, "host_memory", lambda: 100_000)
    capsys.readouterr()
    assert main(["run", str(case_file), "--out", str(out), "--quiet", "--max-steps", "8",
                 "--checkpoint-every", "4"]) != 0
    err = capsys.readouterr().err
    assert "output.checkpoint_every = 4" in err and "0.1 MB available" in err, err
    # 8 RVEs of 120 spheres, 16 list slots, no rolling moments: per sphere 596 B
    # (positions, velocities, spins, list positions 96; rotation, radius, mass, inertia
    # 32; 16 slots of index, image code and tangential force 464; the row count 4), per
    # RVE 536 B: 8 (120 x 596 + 536) = 576,448 B, 576 % of the 100 kB
    assert "0.6 MB on this rank" in err and "(576% of it" in err, err
    assert {f.name: f.read_bytes() for f in out.iterdir() if f.is_file()} == earlier

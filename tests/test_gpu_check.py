"""benchmarks/gpu_check.py's intrusion section (its CPU-side parts): the per-step
records, the memory report and the projection of a whole run's wall time, on a shrunk
intrusion case (8 RVEs of 90 spheres, 2 MPM steps a stage) on the CPU here, and on
numba's CUDA simulator in the validation tier (the batch built on the device)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import grainscale as gs

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "studies" / "intrusion"))
import gpu_check  # noqa: E402
from reshape import reshape  # noqa: E402

STEPS = 2


def tiny_case(folder: Path) -> Path:
    """quick.toml on 0.5 m cells in a 1 x 1 m quarter of a 1 m bed (2 x 2 x 2 cells of
    one point: 8 RVEs), one packing of 90 spheres."""
    case = gs.load_case(ROOT / "examples" / "intrusion" / "quick.toml")
    reshape(case, cell=0.5, width=1.0, depth=1.0)
    case.materials["sand"].library = 1
    # the fewest spheres a cell of 8 r_max holds at porosity 0.38 (narrow radii)
    case.rve.particles = 90
    case.rve.radius_min, case.rve.radius_max = 2.0e-3, 2.2e-3
    path = folder / "tiny.toml"
    case.check().save(path)
    return path


def check_report(res: dict, device: str) -> None:
    """What section 7 reports for one case on one device, and its projection
    recomputed from the rows it reports."""
    stages = res["stages"]
    assert set(stages) == {"geostatic", "intrusion"}, stages
    hours = 0.0
    for name, st in stages.items():
        assert "error" not in st, st
        assert st["device"] == device and st["steps"] == STEPS == len(st["rows"])
        assert st["rves"] == 8 and st["particles"] == [90]
        for row in st["rows"]:
            assert row["wall_s"] > 0 and 0 <= row["dem_s"] <= row["wall_s"]
            # adaptive updates: an RVE waits until its strain reaches the tolerance, so a
            # step may step none; one that steps takes at least min_substeps
            assert 0 <= row["fraction_stepped"] <= 1
            assert row["dem_steps_per_rve"] >= row["fraction_stepped"]
            assert row["dt"] > 0
        assert st["host_peak_gb"] > 0
        # the stage's simulated span over its last dt, times the median of the steps
        # after the first (one here)
        span = (0.0 - (-0.3)) if name == "geostatic" else (st["start"] and 0.0) or 2.3
        n = span / st["rows"][-1]["dt"]
        assert st["median_step_s"] == st["rows"][1]["wall_s"]
        hours += n * st["median_step_s"] / 3600
    assert stages["intrusion"]["start"] == 0.0
    assert res["projected_h"] == pytest.approx(hours, abs=0.01)
    assert "unknown sign" in res["projection"]


def test_intrusion_section_reports_steps_memory_and_projection(tmp_path):
    case = tiny_case(tmp_path)
    res = gpu_check.intrusion([case], tmp_path / "inputs", tmp_path / "out", STEPS,
                              ("cpu",), threads=1)
    check_report(res["tiny_cpu"], "cpu")


@pytest.mark.validation
def test_intrusion_section_on_the_cuda_simulator(tmp_path):
    """The same on numba's CUDA simulator: the batch built on the device, its bytes per
    sphere (list capacity from the packing's longest row plus 3 slots) and bytes moved
    per RVE and step reported. Minutes: the simulator runs each GPU thread in Python."""
    case = tiny_case(tmp_path)
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", NUMBA_NUM_THREADS="1")
    # blocks of 8 threads (the simulator runs each as a Python thread)
    code = ("import json, sys; sys.path.insert(0, 'benchmarks'); import gpu_check; "
            "from pathlib import Path; from grainscale.dem import cuda_kernel, device_batch; "
            "cuda_kernel.THREADS = device_batch._COPY = 8; "
            f"r = gpu_check.intrusion([Path({str(case)!r})], Path({str(tmp_path)!r}) / "
            f"'inputs', Path({str(tmp_path)!r}) / 'out', {STEPS}, ('cuda',), 1); "
            "print(json.dumps(r))")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=1500)
    assert run.returncode == 0, run.stderr[-3000:]
    res = json.loads(run.stdout.strip().splitlines()[-1])["tiny_cuda"]
    check_report(res, "cuda")
    for st in res["stages"].values():
        # the simulator reports no device memory (None); the state's bytes it does
        assert "gpu_used_gb" in st
        # per sphere 132 B + 29 B a list slot, per RVE 444 B (docs/performance.md §2.1)
        (k,) = st["capacity"]
        assert st["device_bytes_per_sphere"] == pytest.approx(132 + 29 * k + 444 / 90,
                                                              abs=0.05)
        assert all(r["bytes_moved_per_rve"] > 0 for r in st["rows"][1:])

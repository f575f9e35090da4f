"""Probe RVEs ([[output.probes]]): the full RVE of chosen points as ParaView series.

The case: the small unit element (8 points) with 4 packings, a normal dashpot
(restitution 0.8) and a retile width between the packings' narrowest cells, so that
some RVEs double at the first step (120 -> 240 spheres) and others do not. One probe
sits on each point (distance 0, default names probe0..probe7), one more ("corner")
near point 7. The files are checked against the run itself: sphere counts against the
MPM frame's rve_particles, the Love-Weber stress recomputed from the written lines and
forces against the stress the RVE reports, and that against the point's stress in the
MPM frame.
"""

import json
import os
import shutil
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
import tomli_w

from grainscale.cli import main
from grainscale.config.base import ConfigError
from grainscale.config.case import load_case
from grainscale.coupling import materials
from grainscale.coupling.driver import run_case
from grainscale.dem.retile import widths
from grainscale.io.rve_h5 import read_rve_state

sys.path.insert(0, str(Path(__file__).parent))
from test_multiscale_run import small_unit_element  # noqa: E402

MPIEXEC = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which(
    "mpiexec")
KINDS = ("spheres", "contacts", "cell")
CORNER = [0.07, 0.07, 0.07]  # nearest point: 7 at (0.075, 0.075, 0.075)


def series(path: Path) -> list[tuple[float, str]]:
    return [(float(d.get("timestep")), d.get("file"))
            for d in ET.parse(path).getroot().iter("DataSet")]


@pytest.fixture(scope="module")
def probe_case(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("probes")
    path = small_unit_element(tmp, end=0.012, interval=0.0004, restitution=0.8)
    case = tomllib.loads(path.read_text())
    case["materials"]["sand"]["library"] = 4
    path.write_text(tomli_w.dumps(case))
    # the packings (cached in the output folder the runs use), to place the threshold
    out = tmp / "full"
    materials.prepare(load_case(path), tmp, out, progress=False)
    packings = [read_rve_state(f)[0] for f in sorted((out / "packings").glob("sand_*.h5"))]
    narrowest = sorted(widths(b.h)[0].min() / (2 * b.radius[0].mean()) for b in packings)
    assert narrowest[1] < narrowest[2]
    case["materials"]["sand"].update({"retile_width": 0.5 * (narrowest[1] + narrowest[2]),
                                      "retile_max_factor": 2})
    points = [[a, b, c] for c in (0.025, 0.075) for b in (0.025, 0.075) for a in (0.025, 0.075)]
    case["output"]["probes"] = [{"position": x} for x in points] + [
        {"position": CORNER, "name": "corner"}]
    path.write_text(tomli_w.dumps(case))
    return path


@pytest.fixture(scope="module")
def full(probe_case):
    out = probe_case.parent / "full"
    assert main(["run", str(probe_case), "--out", str(out), "--quiet"]) == 0
    return out


def test_probes_are_resolved_and_reported(full):
    record = json.loads((full / "probes.json").read_text())["probes"]
    assert [p["name"] for p in record] == [f"probe{i}" for i in range(8)] + ["corner"]
    frame = meshio.read(full / "frames" / "frame_00000.vtu").point_data
    x0 = frame["position"] - frame["displacement"]
    for p in record[:8]:  # on the points themselves
        assert p["distance"] < 1e-12
        np.testing.assert_allclose(x0[p["point"]], p["position"], atol=1e-12)
    assert record[8]["point"] == 7
    assert record[8]["distance"] == pytest.approx(np.sqrt(3) * 0.005, rel=1e-9)
    assert record[8]["series"]["contacts"] == "probe_corner_contacts.pvd"


def test_probe_files_hold_the_rve_at_every_frame(full):
    """Every frame time, every probe: three readable files, in the three series at the
    frames' times. Spheres: the point's sphere count (both sizes occur: retiled and
    not). Contacts: sigma = (1/V) sum d (x) f - (1/V) sum m v (x) v from the written
    lines (branch vectors), force vectors, masses and velocities equals the stress in
    the cell file (the kernel's, with the dashpot) to round-off, and the normal force
    is -f . n. The cell file's stress is the RVE's at the written configuration, and the
    point's stress in the MPM frame its symmetric part, to round-off at every frame (it
    was one DEM step older before the end-of-increment evaluation: 1.6e-4 p apart)."""
    times = [t for t, _ in series(full / "frames.pvd")]
    assert len(times) == 4  # t = 0, 4, 8, 12 ms
    record = json.loads((full / "probes.json").read_text())["probes"]
    sizes = set()
    for k, t in enumerate(times):
        frame = meshio.read(full / "frames" / f"frame_{k:05d}.vtu").point_data
        for p in record:
            for kind in KINDS:
                assert series(full / f"probe_{p['name']}_{kind}.pvd")[k] == (
                    t, f"frames/probe_{p['name']}_{k:05d}_{kind}.vtu")
            stem = full / "frames" / f"probe_{p['name']}_{k:05d}"
            sph, con, cell = (meshio.read(f"{stem}_{kind}.vtu") for kind in KINDS)
            n = len(sph.points)
            assert n == frame["rve_particles"][p["point"]]
            sizes.add(n)
            corners = cell.points
            h = np.stack([corners[1] - corners[0], corners[3] - corners[0],
                          corners[4] - corners[0]], axis=1)
            vol = np.linalg.det(h)
            lines = con.cells_dict["line"]
            d = con.points[lines[:, 1]] - con.points[lines[:, 0]]
            f = con.cell_data["force_vector"][0]
            m, v = sph.point_data["mass"], sph.point_data["velocity"]
            sigma = (d.T @ f - np.einsum("i,ia,ib->ab", m, v, v)) / vol
            reported = cell.cell_data["stress"][0].reshape(3, 3)
            p_rve = -np.trace(reported) / 3
            assert p_rve > 50e3 and len(lines) > n  # a dense, loaded packing
            np.testing.assert_allclose(sigma, reported, rtol=0, atol=1e-12 * p_rve)
            normal = d / np.linalg.norm(d, axis=1)[:, None]
            np.testing.assert_allclose(-np.einsum("ca,ca->c", f, normal),
                                       con.cell_data["normal_force"][0], rtol=1e-12,
                                       atol=1e-12 * np.abs(f).max())
            mpm = frame["stress"][p["point"]].reshape(3, 3)
            np.testing.assert_allclose(0.5 * (reported + reported.T), mpm, rtol=0,
                                       atol=1e-12 * p_rve)
    assert sizes == {120, 240}


@pytest.mark.parametrize("change,message", [
    ({"output": {"probes": [{"position": [0.05, 0.05, 0.5]}]}},
     r"output.probes\[0\].position = \[0.05, 0.05, 0.5\]: outside the grid; valid range "
     r"\[0.0, 0.0, 0.0\] .. \[0.2, 0.2, 0.2\]"),
    ({"output": {"probes": [{"position": [0.05] * 3, "name": "a"},
                            {"position": [0.02] * 3, "name": "probe0"},
                            {"position": [0.03] * 3, "name": "a"}]}},
     r"output.probes\[2\].name = 'a': already the name of output.probes\[0\].*not one of "
     r"\['a', 'probe0'\]"),
    ({"output": {"probes": [{"position": [0.05] * 3}, {"position": [0.02] * 3,
                                                       "name": "probe0"}]}},
     r"output.probes\[1\].name = 'probe0': already the name of output.probes\[0\] \(unnamed"),
    ({"output": {"probes": [{"position": [0.05] * 3, "name": "a b"}]}},
     r"output.probes\[0\].name = 'a b': String should match pattern"),
    ({"output": {"probes": [{"position": [0.05] * 3, "point": 3}]}},
     r"output.probes\[0\].point = 3: unknown key"),
    ({"materials": {"sand": {"type": "linear_elastic", "density": 1600.0,
                             "youngs_modulus": 1e7, "poisson_ratio": 0.3}},
      "output": {"probes": [{"position": [0.05] * 3}], "history": ["time"]}},
     r"output.probes\[0\].position = \[0.05, 0.05, 0.05\]: a probe shows the RVE of a "
     r"material point of a 'dem' material, and this case has none \(materials: \{'sand': "
     r"'linear_elastic'\}\)"),
    ({"materials": {"soil": {"type": "linear_elastic", "density": 1600.0,
                             "youngs_modulus": 1e7, "poisson_ratio": 0.3}},
      "bodies": [{"material": "soil"}], "output": {"probes": [{"position": [0.05] * 3}]}},
     r"output.probes\[0\].position = \[0.05, 0.05, 0.05\]: no material point of a 'dem' "
     r"material \(\['sand'\]\) to show; bodies use materials \['soil'\]"),
])
def test_bad_probes_are_refused_before_the_run(change, message, tmp_path):
    """Each error names the key, the value and what is valid, before any packing is
    generated (the output folder is not even created)."""
    case = tomllib.loads((Path(__file__).parents[2] / "examples" / "unit_element"
                          / "case.toml").read_text())
    for table, value in change.items():
        if table == "bodies":
            case["bodies"][0].update(value[0])
        else:
            case[table].update(value)
    path = tmp_path / "case.toml"
    path.write_text(tomli_w.dumps(case))
    out = tmp_path / "out"
    with pytest.raises(ConfigError, match=message):
        run_case(path, out, progress=False)
    assert not out.exists()


def test_resume_continues_the_probe_series(probe_case, full, tmp_path):
    """Stopped at step 9 (checkpoints at 7 and 9), the newest checkpoint lost: the
    resume falls back to step 7, drops the probe frame written after it (at step 8, the
    first past 4 ms) and writes it again. Series and files
    end identical, byte for byte, to the uninterrupted run's. A probe added on resume
    (output.probes may change) starts its series at the resume."""
    out = tmp_path / "part"
    common = ["run", str(probe_case), "--out", str(out), "--quiet", "--checkpoint-every", "7"]
    assert main([*common, "--max-steps", "9"]) == 0
    (out / "checkpoint.h5").unlink()
    with h5py.File(out / "checkpoint.prev.h5", "r") as f:
        t_ckpt, step = float(f.attrs["time"]), int(f.attrs["step"])
    assert step == 7
    # a frame after the checkpoint, dropped on resume
    assert series(out / "probe_corner_cell.pvd")[-1][0] > t_ckpt
    case = tomllib.loads(probe_case.read_text())
    case["output"]["probes"].append({"position": CORNER, "name": "late"})
    path = tmp_path / "case.toml"
    path.write_text(tomli_w.dumps(case))
    assert main(["run", str(path), "--out", str(out), "--quiet", "--checkpoint-every", "5",
                 "--resume"]) == 0
    names = [f"probe{i}" for i in range(8)] + ["corner"]
    for name in names:
        for kind in KINDS:
            pvd = f"probe_{name}_{kind}.pvd"
            assert (out / pvd).read_text() == (full / pvd).read_text()
            for _, f in series(full / pvd):
                assert (out / f).read_bytes() == (full / f).read_bytes(), f
    late = series(out / "probe_late_contacts.pvd")
    assert late and late[0][0] > t_ckpt
    assert late == [(t, f.replace("corner", "late"))
                    for t, f in series(full / "probe_corner_contacts.pvd") if t > t_ckpt]
    for _, f in late:  # the same point as "corner"
        assert (out / f).read_bytes() == (full / f.replace("late", "corner")).read_bytes()


@pytest.mark.validation
@pytest.mark.skipif(MPIEXEC is None, reason="no mpiexec (install the mpich wheel)")
def test_probes_under_mpi_with_rebalancing(probe_case, full, tmp_path):
    """3 ranks, points changing owner every 3 steps: the rank that holds a probe's point
    sends its RVE to rank 0, and the files are those of the serial run, byte for byte."""
    case = tomllib.loads(probe_case.read_text())
    case["solver"]["rebalance_every"] = 3
    path = probe_case.parent / "rebalanced.toml"
    path.write_text(tomli_w.dumps(case))
    out = tmp_path / "mpi"
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    r = subprocess.run([MPIEXEC, "-n", "3", sys.executable, "-m", "grainscale", "run",
                        str(path), "--out", str(out), "--quiet"], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "cost.json").read_text())["rebalances"] >= 3
    for name in [f"probe{i}" for i in range(8)] + ["corner"]:
        for kind in KINDS:
            pvd = f"probe_{name}_{kind}.pvd"
            assert (out / pvd).read_text() == (full / pvd).read_text()
            for _, f in series(full / pvd):
                assert (out / f).read_bytes() == (full / f).read_bytes(), f


def test_probes_without_frames(probe_case, tmp_path):
    """output.frames = false: the probes are still written at the frame times."""
    case = tomllib.loads(probe_case.read_text())
    case["output"]["frames"] = False
    case["output"]["probes"] = [{"position": CORNER}]
    path = tmp_path / "case.toml"
    path.write_text(tomli_w.dumps(case))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet", "--max-steps", "9"]) == 0
    assert not list(out.glob("frames/frame_*")) and not (out / "frames.pvd").exists()
    assert [f for _, f in series(out / "probe_probe0_spheres.pvd")] == [
        "frames/probe_probe0_00000_spheres.vtu", "frames/probe_probe0_00001_spheres.vtu"]

"""The Python API (grainscale.api, docs/api.md): the same run as the command line, byte
for byte; edited cases validated as files are; results read back from finished and
interrupted runs."""

from __future__ import annotations

import shutil
import textwrap
from pathlib import Path

import numpy as np
import pytest

import grainscale as gs
from grainscale.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


# a Mohr-Coulomb block slumping under gravity (test_mpi.py's case without the traction)
BLOCK = """
title = "Mohr-Coulomb block slumping under gravity"
[grid]
cell_size = 0.05
cells = [6, 4, 5]
[solver]
gravity = [0.0, 0.0, -9.81]
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
[output]
interval = 0.005
frame_interval = 0.01
history = ["time", "kinetic_energy", "p", "q"]
"""


@pytest.fixture
def block(tmp_path):
    path = tmp_path / "block.toml"
    path.write_text(textwrap.dedent(BLOCK))
    return path


def test_run_from_python_writes_what_the_cli_writes(block, tmp_path):
    """The acceptance of the API issue: gs.run of a loaded case and `grainscale run` of
    its file, same step count, write the same history.csv byte for byte (one code path:
    driver.run_loaded_case)."""
    r = gs.run(gs.load_case(block), tmp_path / "api", max_steps=50, progress=False)
    assert main(["run", str(block), "--out", str(tmp_path / "cli"), "--max-steps", "50",
                 "--quiet"]) == 0
    api = (tmp_path / "api" / "history.csv").read_bytes()
    assert api == (tmp_path / "cli" / "history.csv").read_bytes()
    h = r.history
    assert int(h["step"][-1]) == 50 and h["kinetic_energy"][-1] > 0.0  # slumping
    assert r.cost["steps"] == 50
    assert r.case.materials["soil"].friction_angle == 25.0


def test_an_edited_case_runs_as_its_saved_file(block, tmp_path):
    """An edit made in Python equals the same edit made in the file: the case saved after
    the edit and run by the CLI gives the history of the edited case run from Python."""
    case = gs.load_case(block)
    case.materials["soil"].friction_angle = 35.0
    case.time.end = 0.02
    saved = case.save(tmp_path / "edited.toml")
    back = gs.load_case(saved)
    assert back.materials["soil"].friction_angle == 35.0 and back.time.end == 0.02
    assert "poisson_ratio" in saved.read_text() and "velocity_update" not in saved.read_text()
    gs.run(case, tmp_path / "api", progress=False)
    assert main(["run", str(saved), "--out", str(tmp_path / "cli"), "--quiet"]) == 0
    assert (tmp_path / "api" / "history.csv").read_bytes() == (
        tmp_path / "cli" / "history.csv").read_bytes()


def test_edits_are_validated_as_a_file_is(block, tmp_path):
    """A bad value is refused on assignment; a cross-table rule broken by edits is found
    by case.check() and by gs.run before any computation, naming the key as the CLI."""
    case = gs.load_case(block)
    with pytest.raises(ValueError, match="friction_angle"):
        case.materials["soil"].friction_angle = -5.0
    case.bodies[0].material = "sand"
    with pytest.raises(gs.ConfigError, match=r"bodies\[0\]\.material = 'sand'"):
        case.check()
    with pytest.raises(gs.ConfigError, match=r"bodies\[0\]\.material"):
        gs.run(case, tmp_path / "o", progress=False)
    assert not (tmp_path / "o").exists()
    with pytest.raises(TypeError, match="a Case or a path"):
        gs.run({"grid": {}}, tmp_path / "o")


def test_open_result_of_a_finished_and_an_interrupted_run(block, tmp_path):
    """A run stopped at step 30 (checkpoint every 10) reads as far as it got; resumed to
    the end it reads as the run made in one go; frames come back as meshes."""
    whole = gs.run(block, tmp_path / "whole", progress=False)
    gs.run(block, tmp_path / "part", max_steps=30, checkpoint_every=10, progress=False)
    part = gs.open_result(tmp_path / "part")
    assert int(part.history["step"][-1]) == 30
    done = gs.run(block, tmp_path / "part", resume=True, checkpoint_every=10,
                  progress=False)
    for key in ("time", "kinetic_energy", "p"):
        np.testing.assert_array_equal(done.history[key], whole.history[key])
    frames = gs.open_result(tmp_path / "whole").frames()
    # a frame at the first step past each 0.01 s (steps ~1e-4 s)
    np.testing.assert_allclose([t for t, _ in frames], np.arange(6) * 0.01, atol=1e-3)
    t, mesh = frames[-1]
    assert mesh.points.shape[0] == mesh.point_data["stress"].shape[0] > 0
    with pytest.raises(ValueError, match="probe 'x'"):
        whole.probe("x")
    with pytest.raises(ValueError, match="not the output folder of a run"):
        gs.open_result(tmp_path)


def test_relative_paths_resolve_against_the_case_file(tmp_path):
    """A case with a points file given relatively, loaded from another working folder
    and edited, still finds the file next to it."""
    src = tmp_path / "case"
    src.mkdir()
    (src / "pts.txt").write_text("0.05 0.05 0.05 1e-4\n0.06 0.05 0.05 1e-4\n")
    text = textwrap.dedent(BLOCK).replace(
        'shape = "box"\nmaterial = "soil"\nlo = [0.0, 0.0, 0.0]\nhi = [0.15, 0.2, 0.2]',
        'shape = "file"\nmaterial = "soil"\npath = "pts.txt"')
    (src / "c.toml").write_text(text)
    case = gs.load_case(src / "c.toml")
    case.time.end = 0.01
    r = gs.run(case, tmp_path / "o", progress=False)
    assert r.history["time"][-1] == pytest.approx(0.01)
    shutil.rmtree(tmp_path / "o")


def test_on_step_sees_every_step_and_changes_nothing(block, tmp_path):
    """run(on_step=f): f gets the state after each of the 40 steps, in order, at the
    times history.csv records; a run with the hook writes the history a run without it
    writes, byte for byte."""
    seen = []

    def record(state):
        seen.append((state.step, state.time, state.last_dt, state.dH.shape))

    r = gs.run(block, tmp_path / "hooked", max_steps=40, progress=False, on_step=record)
    gs.run(block, tmp_path / "plain", max_steps=40, progress=False)
    assert [s[0] for s in seen] == list(range(1, 41))
    times = np.array([s[1] for s in seen])
    np.testing.assert_allclose(np.diff(times), [s[2] for s in seen[1:]], rtol=1e-12)
    h = r.history
    np.testing.assert_array_equal(times[h["step"][1:].astype(int) - 1], h["time"][1:])
    assert seen[0][3] == (r.cost["points"], 3, 3)
    assert (tmp_path / "hooked" / "history.csv").read_bytes() == (
        tmp_path / "plain" / "history.csv").read_bytes()


def test_edited_and_continuum_twin(tmp_path):
    """case.edited replaces or removes whole tables and validates the result;
    continuum_twin of the multiscale intrusion keeps its geometry and drops exactly its
    DEM side, and refuses a DEM material."""
    case = gs.load_case(EXAMPLES / "intrusion" / "quick.toml")
    twin = case.continuum_twin({"type": "mohr_coulomb", "density": 1600.0,
                                "youngs_modulus": 10e6, "poisson_ratio": 0.3,
                                "friction_angle": 20.0}, title="twin")
    assert twin.title == "twin" and list(twin.materials) == list(case.materials)
    assert twin.materials[next(iter(twin.materials))].type == "mohr_coulomb"
    assert twin.rve is None and twin.triaxial is None and twin.output.probes == []
    assert twin.output.checkpoint_every == 0
    assert not {"porosity", "coordination", "mean_rotation"} & set(twin.output.history)
    assert [c for c in case.output.history
            if c not in ("porosity", "coordination", "mean_rotation")] == twin.output.history
    assert twin.grid == case.grid and twin.bodies == case.bodies and twin.rigid == case.rigid
    assert twin._case_dir == case._case_dir
    with pytest.raises(gs.ConfigError, match="continuum"):
        case.continuum_twin({"type": "dem"})

    def drop_rve(t):
        del t["rve"]

    with pytest.raises(gs.ConfigError, match="needs an \\[rve\\] table"):
        case.edited(drop_rve)  # a 'dem' material without its RVE


def test_an_invalid_assignment_names_the_key_as_the_file_writes_it():
    """Edits from Python are validated as a file is and raise the CLI's ConfigError text
    with the key's dotted path in the case: a value out of range, a vector of the wrong
    length, a misspelt key (with the nearest valid one), a table's own check."""
    case = gs.load_case(EXAMPLES / "column_collapse" / "quick.toml")
    with pytest.raises(gs.ConfigError, match=r"rve\.preparation\.porosity = 0\.9: Input "
                                             r"should be less than 0\.5"):
        case.rve.preparation.porosity = 0.9
    with pytest.raises(gs.ConfigError, match=r"bodies\[0\]\.hi = 0\.2: expected a list of "
                                             r"3 values"):
        case.bodies[0].hi = 0.2
    with pytest.raises(gs.ConfigError, match=r"time\.ned: unknown key; did you mean 'end'"):
        case.time.ned = 3.0
    with pytest.raises(gs.ConfigError, match=r"time: time\.end = -1\.0 must be > time\.start"):
        case.time.end = -1.0
    case.time.end = 0.3  # a valid edit goes through
    assert case.time.end == 0.3

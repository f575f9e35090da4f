"""`grainscale run`: outputs, --max-steps, checkpoints and --resume, exit codes."""

import textwrap

import pytest

from grainscale.cli import main

CASE = """
title = "tiny block under a plate"

[grid]
cell_size = 0.05
cells = [4, 4, 5]

[solver]
gravity = [0.0, 0.0, -9.81]

[time]
start = -0.01
end = 0.03

[materials.soil]
type = "mohr_coulomb"
density = 1000.0
youngs_modulus = 1e6
poisson_ratio = 0.3
friction_angle = 30.0

[[bodies]]
shape = "box"
material = "soil"
lo = [0.0, 0.0, 0.0]
hi = [0.2, 0.2, 0.1]

[[boundaries]]
type = "fixed"
face = "z-"

[[boundaries]]
type = "roller"
face = "x-"

[[tractions]]
lo = [0.15, 0.0, 0.0]
hi = [0.2, 0.2, 0.1]
surface = "x+"
traction = [-2000.0, 0.0, 0.0]
ramp_time = 0.01

[damping]
alpha = 0.2
end_time = 0.0

[rigid]
shape = "box"
lo = [0.05, 0.05, 0.1]
hi = [0.15, 0.15, 0.15]
velocity = [0.0, 0.0, -0.05]
ramp_time = 0.01

[output]
interval = 0.004
checkpoint_every = 0
history = ["time", "kinetic_energy", "rigid_fz", "rigid_depth", "force"]
"""


def _case(tmp_path):
    p = tmp_path / "case.toml"
    p.write_text(textwrap.dedent(CASE))
    return p


def _rows(path):
    return [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]


def test_run_writes_outputs(tmp_path):
    case = _case(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(case), "--out", str(out), "--quiet"]) == 0
    rows = _rows(out / "history.csv")
    assert rows[0] == "step,time,kinetic_energy,rigid_fz,rigid_depth,force"
    last = rows[-1].split(",")
    assert abs(float(last[1]) - 0.03) < 1e-12  # ran to time.end
    assert float(last[3]) > 0  # the soil pushes the plate up
    # from time.start = -0.01: ramp over 0.01 s, then constant (midpoint rule at the kink)
    assert abs(float(last[4]) - 0.05 * (0.04 - 0.005)) < 1e-6
    assert float(last[5]) == float(last[3])  # downward motion: resistance = +f_z
    assert (out / "case.resolved.toml").read_text().count("grainscale_version") == 1
    assert 'velocity_update = "apic"' in (out / "case.resolved.toml").read_text()  # defaults
    frames = sorted((out / "frames").glob("frame_*.vtu"))
    assert len(frames) >= 10 and "frame_00000.vtu" in (out / "frames.pvd").read_text()
    import meshio

    m = meshio.read(frames[-1])
    for k in ("position", "velocity", "displacement", "stress", "p", "q", "eps_v", "material",
              "plastic_strain"):
        assert k in m.point_data, k
    assert m.point_data["stress"].shape[1] == 9


def test_a_new_run_replaces_an_earlier_runs_frames(tmp_path):
    """A shorter run into the folder of a longer one (no --resume) leaves only its own
    frames, and nothing but grainscale's outputs is removed."""
    case = _case(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(case), "--out", str(out), "--quiet"]) == 0
    n_long = len(list((out / "frames").glob("frame_*.vtu")))
    (out / "notes.txt").write_text("mine")
    (out / "frames" / "mine.vtu").write_text("mine")
    assert main(["run", str(case), "--out", str(out), "--max-steps", "3", "--quiet"]) == 0
    frames = sorted(f.name for f in (out / "frames").glob("frame_*.vtu"))
    assert 0 < len(frames) < n_long
    assert all(f in (out / "frames.pvd").read_text() for f in frames)
    assert (out / "notes.txt").exists() and (out / "frames" / "mine.vtu").exists()


def test_max_steps_writes_final_row(tmp_path):
    case = _case(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(case), "--out", str(out), "--max-steps", "7", "--quiet"]) == 0
    assert _rows(out / "history.csv")[-1].startswith("7,")


def test_resume_gives_the_same_history(tmp_path):
    case = _case(tmp_path)
    full, part = tmp_path / "full", tmp_path / "part"
    assert main(["run", str(case), "--out", str(full), "--checkpoint-every", "10",
                 "--quiet"]) == 0
    assert main(["run", str(case), "--out", str(part), "--checkpoint-every", "10",
                 "--max-steps", "25", "--quiet"]) == 0
    assert (part / "checkpoint.h5").is_file()
    assert (part / "history.csv").read_text() != (full / "history.csv").read_text()
    assert main(["run", str(case), "--out", str(part), "--checkpoint-every", "10",
                 "--resume", "--quiet"]) == 0
    assert (part / "history.csv").read_text() == (full / "history.csv").read_text()
    assert (part / "frames.pvd").read_text() == (full / "frames.pvd").read_text()
    assert (part / "rigid.pvd").read_text() == (full / "rigid.pvd").read_text()
    # resuming a finished run changes nothing (no second final row, same dt column)
    assert main(["run", str(case), "--out", str(part), "--checkpoint-every", "10",
                 "--resume", "--quiet"]) == 0
    assert (part / "history.csv").read_text() == (full / "history.csv").read_text()


def test_the_same_command_resumes_to_the_same_end(tmp_path):
    """--max-steps counts the whole run's steps, as time.end is a time of the whole run:
    a run stopped early (here by --steps-this-run, a per-job budget) and resumed with the
    identical command ends at the same step with a byte-identical history (it used to
    count from the resume point and run on to 38)."""
    case = _case(tmp_path)
    ref, part = tmp_path / "ref", tmp_path / "part"
    cmd = ["run", str(case), "--checkpoint-every", "10", "--max-steps", "25", "--quiet"]
    assert main([*cmd, "--out", str(ref)]) == 0
    assert _rows(ref / "history.csv")[-1].startswith("25,")
    assert main([*cmd, "--out", str(part), "--steps-this-run", "13"]) == 0
    assert _rows(part / "history.csv")[-1].startswith("13,")
    assert main([*cmd, "--out", str(part), "--resume"]) == 0
    assert (part / "history.csv").read_bytes() == (ref / "history.csv").read_bytes()
    assert main([*cmd, "--out", str(part), "--resume"]) == 0  # already at its end
    assert (part / "history.csv").read_bytes() == (ref / "history.csv").read_bytes()


def test_progress_in_a_log_is_plain_lines(tmp_path, capsys, monkeypatch):
    """Without a terminal (a batch job's log) the run writes plain progress lines every
    PLAIN_INTERVAL_S of wall time and one at the end, not a redrawn bar per update."""
    from grainscale.io import progress

    case = _case(tmp_path)
    monkeypatch.setattr(progress, "PLAIN_INTERVAL_S", 1e9)  # no timing in the assertion
    assert main(["run", str(case), "--out", str(tmp_path / "a"), "--max-steps", "40"]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("progress:")]
    assert len(lines) == 1 and "step 40," in lines[0] and "ETA" in lines[0]  # the final one
    monkeypatch.setattr(progress, "PLAIN_INTERVAL_S", 0.0)
    assert main(["run", str(case), "--out", str(tmp_path / "b"), "--max-steps", "40"]) == 0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("progress:")]
    assert len(lines) == 41  # one per step at interval 0, and the final one
    assert "\r" not in err  # no bar redraws in the log


def test_bad_case_exit_code_2(tmp_path, capsys):
    p = tmp_path / "bad.toml"
    p.write_text(textwrap.dedent(CASE).replace("cell_size = 0.05", "cell_size = 0.0"))
    assert main(["run", str(p), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "grid.cell_size" in err and "0.0" in err
    assert not (tmp_path / "o").exists()  # refused before anything was written


def test_resume_without_checkpoint_is_an_error(tmp_path, capsys):
    case = _case(tmp_path)
    assert main(["run", str(case), "--out", str(tmp_path / "o"), "--resume", "--quiet"]) == 2
    assert "checkpoint" in capsys.readouterr().err


def test_point_leaving_the_grid_stops_the_run_cleanly(tmp_path, capsys):
    """No wall at x+: a block thrown at it leaves the grid; exit code 1, rows intact."""
    text = textwrap.dedent(CASE).replace('lo = [0.0, 0.0, 0.0]\nhi = [0.2, 0.2, 0.1]',
                                         'lo = [0.0, 0.0, 0.0]\nhi = [0.2, 0.2, 0.1]\n'
                                         'velocity = [5.0, 0.0, 0.0]')
    assert "velocity = [5.0" in text
    p = tmp_path / "throw.toml"
    p.write_text(text)
    out = tmp_path / "o"
    assert main(["run", str(p), "--out", str(out), "--quiet"]) == 1
    assert "left the grid" in capsys.readouterr().err
    rows = _rows(out / "history.csv")
    assert len(rows) >= 2 and all(len(r.split(",")) == 6 for r in rows)


def test_history_has_the_normalised_resistance(tmp_path):
    """depth_over_R = depth / R and force_normalized = force / (S rho g R) in history.csv,
    for the plate of test_cli_run's case (0.1 m square inside the grid: S = 0.01 m^2,
    R = sqrt(S / pi); rho = 1000 kg/m^3)."""
    import numpy as np

    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE).replace(
        '"rigid_depth", "force"]', '"depth", "force", "depth_over_R", "force_normalized"]'))
    assert main(["run", str(case), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    lines = [ln for ln in (tmp_path / "out" / "history.csv").read_text().splitlines()
             if not ln.startswith("#")]
    names = lines[0].split(",")
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    col = {n: rows[:, i] for i, n in enumerate(names)}
    R = np.sqrt(0.01 / np.pi)
    assert col["force"][-1] > 0
    np.testing.assert_allclose(col["depth_over_R"], col["depth"] / R, rtol=1e-12)
    np.testing.assert_allclose(col["force_normalized"],
                               col["force"] / (0.01 * 1000.0 * 9.81 * R), rtol=1e-12)


def test_bearing_pressure_and_plane_strain_force_per_length(tmp_path):
    """bearing_pressure = force / S, S the plate's 0.1 m square inside the grid; with y
    periodic (plane strain: the block and plate span the 0.2 m period) S is the plate's
    width times the period (0.1 x 0.2 m) and force_per_length = force / 0.2 m. A
    periodic axis along the motion is refused."""
    import numpy as np

    from grainscale.analysis import read_columns
    from grainscale.config.base import ConfigError
    from grainscale.config.case import load_case

    text = textwrap.dedent(CASE).replace('"rigid_depth", "force"]',
                                         '"rigid_depth", "force", "bearing_pressure"]')
    case = tmp_path / "case.toml"
    case.write_text(text)
    assert main(["run", str(case), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    h = read_columns(tmp_path / "out" / "history.csv")
    assert h["force"][-1] > 0
    np.testing.assert_allclose(h["bearing_pressure"], h["force"] / 0.01, rtol=1e-12)
    plane = text.replace("cells = [4, 4, 5]", 'cells = [4, 4, 5]\nperiodic = ["y"]')
    plane = plane.replace("lo = [0.05, 0.05, 0.1]\nhi = [0.15, 0.15, 0.15]",
                          "lo = [0.05, 0.0, 0.1]\nhi = [0.15, 0.2, 0.15]")
    plane = plane.replace('"bearing_pressure"]', '"bearing_pressure", "force_per_length"]')
    plane = plane.replace('[[boundaries]]\ntype = "roller"\nface = "x-"',
                          '[[boundaries]]\ntype = "roller"\nface = "x-"\n')
    case.write_text(plane)
    assert main(["run", str(case), "--out", str(tmp_path / "plane"), "--quiet"]) == 0
    h = read_columns(tmp_path / "plane" / "history.csv")
    assert h["force"][-1] > 0
    np.testing.assert_allclose(h["bearing_pressure"], h["force"] / 0.02, rtol=1e-12)
    np.testing.assert_allclose(h["force_per_length"], h["force"] / 0.2, rtol=1e-12)
    case.write_text(plane.replace('periodic = ["y"]', 'periodic = ["z"]'))
    with pytest.raises(ConfigError):
        load_case(case)
    case.write_text(text.replace('"bearing_pressure"]', '"force_per_length"]'))
    with pytest.raises(ConfigError, match="force_per_length"):
        load_case(case)  # no periodic axis: not a plane-strain model


def test_more_threads_than_numba_started_with_are_named(capsys):
    """--threads beyond NUMBA_NUM_THREADS runs with what numba has, and says so."""
    from pathlib import Path

    import numba

    from grainscale.config.case import load_case
    from grainscale.coupling.driver import set_threads
    from grainscale.distributed.comm import Comm

    case = load_case(Path(__file__).resolve().parents[1] / "examples" / "intrusion"
                     / "mohr_coulomb.toml")
    most = numba.config.NUMBA_NUM_THREADS
    before = numba.get_num_threads()
    try:
        set_threads(case, most + 3, Comm())
        assert numba.get_num_threads() == most
    finally:
        numba.set_num_threads(before)
    err = capsys.readouterr().err
    assert f"{most + 3} threads asked" in err and f"NUMBA_NUM_THREADS = {most}" in err

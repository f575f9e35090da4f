"""Checkpoints that check themselves: checksums, the fallback to the previous checkpoint,
and a resume refused when the case's physics changed (issue 13, item 2)."""

import json
import os
import shutil
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from grainscale.cli import main
from grainscale.io.checkpoint import CorruptCheckpoint, read_checkpoint, write_checkpoint
from test_cli_run import CASE


def _case(path, text=None):
    path.write_text(textwrap.dedent(CASE) if text is None else text)
    return path


def _changed(tmp_path, old: str, new: str, name="changed.toml"):
    text = textwrap.dedent(CASE)
    assert text.count(old) == 1, old
    return _case(tmp_path / name, text.replace(old, new))


def _run(case, out, *extra):
    return main(["run", str(case), "--out", str(out), "--checkpoint-every", "10", "--quiet",
                 *extra])


def _flip_byte(path, array: str) -> None:
    """Invert one byte inside the stored data of `array` (group/key) of an HDF5 file."""
    with h5py.File(path, "r") as f:
        offset = f[array].id.get_offset()
    with open(path, "r+b") as fh:
        fh.seek(offset + 5)
        b = fh.read(1)[0]
        fh.seek(offset + 5)
        fh.write(bytes([b ^ 0xFF]))


def _truncate(path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _newest_part(out):
    with h5py.File(out / "checkpoint.h5", "r") as f:
        return out / str(f.attrs["parts"]) / "rank_00000.h5"


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run, and the same run stopped at step 25: checkpoints at steps
    20 (checkpoint.prev.h5) and 25 (checkpoint.h5)."""
    tmp = tmp_path_factory.mktemp("ref")
    case = _case(tmp / "case.toml")
    assert _run(case, tmp / "full") == 0
    assert _run(case, tmp / "part", "--max-steps", "25") == 0
    return case, tmp / "full", tmp / "part"


@pytest.fixture
def stopped(reference, tmp_path):
    """A fresh copy of the run stopped at step 25."""
    case, _, part = reference
    out = tmp_path / "part"
    shutil.copytree(part, out)
    return case, out


def test_every_array_and_attribute_is_checked(tmp_path):
    path = tmp_path / "c.h5"
    groups = {"points": {"x": np.arange(12.0).reshape(4, 3), "flag": np.ones(4, bool)},
              "empty": {"a": np.zeros((0, 3))}}
    write_checkpoint(path, groups, {"time": 0.25, "step": 7, "parts": "p"})
    g, attrs = read_checkpoint(path)
    assert attrs == {"time": 0.25, "step": 7, "parts": "p"}
    assert np.array_equal(g["points"]["x"], groups["points"]["x"])
    _flip_byte(path, "points/x")
    with pytest.raises(CorruptCheckpoint, match="points/x does not match its checksum"):
        read_checkpoint(path)
    write_checkpoint(path, groups, {"time": 0.25, "step": 7})
    with h5py.File(path, "r+") as f:
        f.attrs["step"] = 8  # as a damaged attribute would read
    with pytest.raises(CorruptCheckpoint, match="attributes do not match"):
        read_checkpoint(path)
    write_checkpoint(path, groups, {"step": 7})
    _truncate(path)
    with pytest.raises(CorruptCheckpoint, match="unreadable"):
        read_checkpoint(path)


def test_large_arrays_are_stored_compressed_and_still_checked(tmp_path):
    """An RVE neighbour table is mostly zero padding: above COMPRESS_BYTES an array is
    stored gzip-compressed (here 8 MB of it in well under 1 MB), reads back exactly, and
    a damaged compressed chunk is still reported as a corrupt checkpoint."""
    path = tmp_path / "c.h5"
    ft = np.zeros((200, 150, 12, 3))
    ft[:, :, :2] = np.random.default_rng(0).normal(size=(200, 150, 2, 3))
    write_checkpoint(path, {"material_0": {"rve_ft": ft}}, {"step": 1})
    assert path.stat().st_size < ft.nbytes / 4
    g, _ = read_checkpoint(path)
    assert np.array_equal(g["material_0"]["rve_ft"], ft)
    with h5py.File(path, "r") as f:
        chunk = f["material_0/rve_ft"].id.get_chunk_info(0)
    with open(path, "r+b") as fh:
        fh.seek(chunk.byte_offset + chunk.size // 2)
        b = fh.read(1)[0]
        fh.seek(chunk.byte_offset + chunk.size // 2)
        fh.write(bytes([b ^ 0xFF]))
    with pytest.raises(CorruptCheckpoint, match="material_0/rve_ft|unreadable"):
        read_checkpoint(path)


@pytest.mark.parametrize("damage", ["part byte", "part truncated", "manifest byte",
                                    "manifest truncated", "manifest missing"])
def test_damaged_newest_checkpoint_falls_back_to_the_previous(damage, reference, stopped,
                                                              capsys):
    """The newest checkpoint (step 25) damaged: the resume warns, naming the file and why,
    continues from the previous one (step 20), and history.csv and frames.pvd end
    byte-identical to an uninterrupted run's."""
    _, full, _ = reference
    case, out = stopped
    part, manifest = _newest_part(out), out / "checkpoint.h5"
    bad = part if damage.startswith("part") else manifest
    if damage.endswith("byte"):
        _flip_byte(bad, "points/x" if bad == part else "rigid/x")
    elif damage.endswith("truncated"):
        _truncate(bad)
    else:
        bad.unlink()  # as a kill between the renames of a save leaves it
    capsys.readouterr()
    assert _run(case, out, "--resume") == 0
    err = capsys.readouterr().err
    why = {"byte": "does not match its checksum", "truncated": "unreadable",
           "missing": "missing"}[damage.split()[1]]
    assert f"warning: {bad}: " in err and why in err, err
    assert f"previous checkpoint {out / 'checkpoint.prev.h5'} (step 20" in err
    assert (out / "history.csv").read_bytes() == (full / "history.csv").read_bytes()
    assert (out / "frames.pvd").read_bytes() == (full / "frames.pvd").read_bytes()
    # the continued run wrote valid checkpoints over the damaged one: no warning now
    assert _run(case, out, "--resume") == 0
    assert "warning" not in capsys.readouterr().err
    assert (out / "history.csv").read_bytes() == (full / "history.csv").read_bytes()


def test_a_save_keeps_the_previous_checkpoint(stopped):
    _, out = stopped
    with h5py.File(out / "checkpoint.h5", "r") as new, \
            h5py.File(out / "checkpoint.prev.h5", "r") as old:
        assert (new.attrs["step"], old.attrs["step"]) == (25, 20)
        names = {new.attrs["parts"], old.attrs["parts"]}
    assert {f"checkpoint.parts/{p.name}" for p in (out / "checkpoint.parts").iterdir()} == names


def test_no_valid_checkpoint_is_an_error(stopped, capsys):
    case, out = stopped
    _flip_byte(_newest_part(out), "points/x")
    _truncate(out / "checkpoint.prev.h5")
    history = (out / "history.csv").read_bytes()
    assert _run(case, out, "--resume") == 2
    err = capsys.readouterr().err
    assert "no valid checkpoint" in err
    assert "rank_00000.h5: array points/x does not match its checksum" in err
    assert f"{out / 'checkpoint.prev.h5'}: unreadable" in err
    assert (out / "history.csv").read_bytes() == history  # nothing touched


def test_a_history_shorter_than_the_checkpoint_is_refused(stopped, capsys):
    """history.csv cut back behind the rows the newest checkpoint counts (a copy from an
    older stage, or rows lost to a crash): the resume stops with a clear error before it
    writes anything, instead of continuing with a gap in the history."""
    case, out = stopped
    lines = (out / "history.csv").read_text().splitlines(keepends=True)
    short = "".join(lines[:-2]) + lines[-2][:5]  # the last row gone, the one before cut
    (out / "history.csv").write_text(short)
    manifest = (out / "checkpoint.h5").read_bytes()
    assert _run(case, out, "--resume") == 2
    err = capsys.readouterr().err
    n_rows = sum(not ln.startswith("#") for ln in lines) - 1  # the column names aside
    assert f"holds {n_rows - 2} complete data rows" in err, err
    # the stop's final row comes after the last checkpoint, which does not count it
    assert f"written after row {n_rows - 1}" in err and "without --resume" in err
    assert (out / "history.csv").read_text() == short  # nothing touched
    assert (out / "checkpoint.h5").read_bytes() == manifest


def test_history_rows_are_on_disk_before_a_checkpoint_counts_them(tmp_path, monkeypatch):
    """Every save fsyncs history.csv before the checkpoint that records its row count."""
    import grainscale.coupling.checkpoints as checkpoints
    import grainscale.io.history as history

    events = []
    fsync, save = history.os.fsync, checkpoints.save

    def traced_fsync(fd):
        events.append(("fsync", Path(os.readlink(f"/proc/self/fd/{fd}")).name))
        fsync(fd)

    def traced_save(*args, **kwargs):
        events.append(("save",))
        return save(*args, **kwargs)

    monkeypatch.setattr(history.os, "fsync", traced_fsync)
    monkeypatch.setattr(checkpoints, "save", traced_save)
    assert _run(_case(tmp_path / "case.toml"), tmp_path / "out", "--max-steps", "25") == 0
    saves = [i for i, e in enumerate(events) if e == ("save",)]
    assert len(saves) == 3  # steps 10, 20 and the stop at 25
    for i in saves:
        assert events[i - 1] == ("fsync", "history.csv")


def test_changed_physics_is_refused_unless_allowed(stopped, tmp_path, capsys):
    case, out = stopped
    changed = _changed(tmp_path, "youngs_modulus = 1e6", "youngs_modulus = 2e6")
    text = changed.read_text().replace("gravity = [0.0, 0.0, -9.81]",
                                       "gravity = [0.0, 0.0, -5.0]")
    changed.write_text(text)
    history = (out / "history.csv").read_bytes()
    manifest = (out / "checkpoint.h5").read_bytes()
    assert _run(changed, out, "--resume") == 2
    err = capsys.readouterr().err
    assert "solver.gravity = [0.0, 0.0, -9.81] -> [0.0, 0.0, -5.0]" in err
    assert "materials.soil.youngs_modulus = 1000000.0 -> 2000000.0" in err
    assert "--allow-changed solver.gravity materials.soil.youngs_modulus" in err
    assert (out / "history.csv").read_bytes() == history  # nothing touched
    assert (out / "checkpoint.h5").read_bytes() == manifest
    # one of the two allowed is not enough
    assert _run(changed, out, "--resume", "--allow-changed", "solver.gravity") == 2
    err = capsys.readouterr().err
    assert "youngs_modulus" in err and "solver.gravity =" not in err
    # both (a table names all its keys)
    assert _run(changed, out, "--resume", "--allow-changed", "solver.gravity",
                "materials.soil") == 0
    rows = (out / "history.csv").read_text().splitlines()
    assert rows[-1].split(",")[1] == "0.03"
    # the checkpoints now hold the new case: the same command resumes without the flag
    assert _run(changed, out, "--resume") == 0
    assert (out / "history.csv").read_text().splitlines() == rows


def test_time_end_and_outputs_may_change(tmp_path, stopped):
    """Extending a run is the normal use: a longer time.end (and no frames, checkpoints
    more often) resumes without a flag and continues as if it had been given from the
    start."""
    case, out = stopped
    longer = _changed(tmp_path, "end = 0.03", "end = 0.04")
    ref = tmp_path / "ref"
    assert _run(longer, ref) == 0
    text = longer.read_text().replace("checkpoint_every = 0", "checkpoint_every = 7\n"
                                      "frames = false")
    longer.write_text(text)
    assert main(["run", str(longer), "--out", str(out), "--quiet", "--resume"]) == 0
    assert (out / "history.csv").read_bytes() == (ref / "history.csv").read_bytes()


def test_output_history_cannot_change(tmp_path, stopped, capsys):
    _, out = stopped
    changed = _changed(tmp_path, '"rigid_depth", "force"]', '"rigid_depth"]')
    assert _run(changed, out, "--resume", "--allow-changed", "output.history") == 2
    err = capsys.readouterr().err
    assert "output.history changed" in err and "columns" in err


def test_allow_changed_names_keys_of_the_case(stopped, capsys):
    case, out = stopped
    assert _run(case, out, "--resume", "--allow-changed", "solver.gravty") == 2
    err = capsys.readouterr().err
    assert "--allow-changed solver.gravty: not a key of this case" in err
    assert "did you mean solver.gravity" in err
    # a key of the case that did not change is accepted (a job script may keep it)
    assert _run(case, out, "--resume", "--allow-changed", "solver.gravity") == 0


def test_allow_changed_needs_resume(tmp_path, capsys):
    case = _case(tmp_path / "case.toml")
    out = tmp_path / "o"
    assert _run(case, out, "--allow-changed", "solver.gravity") == 2
    assert "--allow-changed solver.gravity: applies only with --resume" in (
        capsys.readouterr().err)
    assert not out.exists()


@pytest.mark.parametrize("target", ["part", "manifest"])
def test_a_full_disk_stops_the_run_cleanly_and_keeps_the_last_checkpoint(
        target, reference, tmp_path, monkeypatch, capsys):
    """Disk full (ENOSPC) while writing the checkpoint of step 20 (its rank part, or the
    manifest): the run ends with exit code 1 and a message naming the file and the
    cause, not a traceback; the checkpoint of step 10 stays valid (as checkpoint.h5, or
    as checkpoint.prev.h5 once the manifests were rotated), and a resume once space is
    back ends with the uninterrupted run's history.csv, byte for byte."""
    import errno

    from grainscale.coupling import checkpoints
    from grainscale.io import checkpoint as io_checkpoint

    real = io_checkpoint.write_checkpoint
    calls = {"n": 0}

    def full_disk(path, groups, attrs, **kw):
        is_target = path.name.startswith("rank_") == (target == "part")
        if is_target:
            calls["n"] += 1
            if calls["n"] == 2:  # the second checkpoint: step 20
                raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, groups, attrs, **kw)

    monkeypatch.setattr(checkpoints, "write_checkpoint", full_disk)
    case = _case(tmp_path / "case.toml")
    out = tmp_path / "run"
    assert _run(case, out) == 1
    err = capsys.readouterr().err
    assert "No space left on device" in err and "checkpoint" in err, err
    assert "Traceback" not in err
    monkeypatch.setattr(checkpoints, "write_checkpoint", real)
    # a failed part leaves checkpoint.h5 (step 10) as it was; a failed manifest comes
    # after the rotation, so step 10 is checkpoint.prev.h5 and the resume falls back to it
    kept = out / ("checkpoint.h5" if target == "part" else "checkpoint.prev.h5")
    with h5py.File(kept, "r") as f:
        assert int(f.attrs["step"]) == 10
    assert _run(case, out, "--resume") == 0
    _, full, _ = reference
    assert (out / "history.csv").read_bytes() == (full / "history.csv").read_bytes()


def test_a_full_disk_while_writing_history_stops_cleanly(reference, tmp_path, monkeypatch,
                                                        capsys):
    """ENOSPC from a history row (after the checkpoint of step 20): exit code 1 and a
    message with the cause and how to continue, no traceback; the resume, once space is
    back, ends with the uninterrupted run's history.csv byte for byte."""
    import errno

    from grainscale.io.history import History

    real = History.write
    calls = {"n": 0}

    def full_disk(self, values):
        calls["n"] += 1
        if calls["n"] == 5:
            raise OSError(errno.ENOSPC, "No space left on device", str(self.path))
        return real(self, values)

    monkeypatch.setattr(History, "write", full_disk)
    case = _case(tmp_path / "case.toml")
    out = tmp_path / "run"
    assert _run(case, out) == 1
    err = capsys.readouterr().err
    assert "No space left on device" in err and "--resume" in err, err
    assert "Traceback" not in err
    monkeypatch.setattr(History, "write", real)
    assert _run(case, out, "--resume") == 0
    _, full, _ = reference
    assert (out / "history.csv").read_bytes() == (full / "history.csv").read_bytes()


def test_a_key_added_since_the_checkpoint_at_its_neutral_value_is_no_change():
    """A checkpoint written before materials.NAME.update_tolerance existed resumes with
    the key at 0 (adaptive updates off: the same physics), not at another value."""
    from grainscale.coupling.checkpoints import changed_keys

    old = {"materials": {"sand": {"type": "dem", "library": 2}}}
    new = {"materials": {"sand": {"type": "dem", "library": 2, "update_tolerance": 0.0,
                                  "max_deferred_steps": 20}}}
    assert changed_keys(old, new) == []
    new["materials"]["sand"]["update_tolerance"] = 2e-6
    assert [k for k, _, _ in changed_keys(old, new)] == ["materials.sand.update_tolerance"]
    assert [k for k, _, _ in changed_keys(new, old)] == [
        "materials.sand.update_tolerance", "materials.sand.max_deferred_steps"]


def test_a_checkpoint_from_before_hertz_mindlin_resumes_and_a_hertzian_case_round_trips():
    """The [rve] keys that came with Hertz-Mindlin (contact_law, poisson_ratio,
    numerics.max_overlap), absent from an older checkpoint's case, are no change while
    the law is the linear one; switching to Hertz-Mindlin is. A Hertzian case's record
    (and case.resolved.toml) holds no stiffness_ratio, which the law refuses: it reads
    back as the same case."""
    import grainscale as gs
    from grainscale.config.rve import RVEParams
    from grainscale.coupling.checkpoints import case_record, changed_keys

    case = gs.load_case(Path(__file__).parents[1] / "examples" / "column_collapse"
                        / "quick.toml")
    new = case_record(case)
    old = json.loads(json.dumps(new))
    for k in ("contact_law", "poisson_ratio"):
        del old["rve"][k]
    del old["rve"]["numerics"]["max_overlap"]
    del old["rve"]["clump"]  # came later still, with the clumps: None is no change
    assert changed_keys(old, new) == []
    new["rve"].update(contact_law="hertz_mindlin", poisson_ratio=0.25)
    assert {k for k, _, _ in changed_keys(old, new)} >= {"rve.contact_law",
                                                         "rve.poisson_ratio"}
    hz = RVEParams(contact_law="hertz_mindlin", poisson_ratio=0.25, young_modulus=70e9)
    dumped = hz.model_dump(mode="json")
    assert "stiffness_ratio" not in dumped
    assert RVEParams(**dumped) == hz
    assert "stiffness_ratio" in RVEParams().model_dump()
    clumped = json.loads(json.dumps(new))
    clumped["rve"]["clump"] = {"template": "elongated", "aspect": 1.5, "spheres": 2}
    assert "rve.clump.template" in {k for k, _, _ in changed_keys(old, clumped)}

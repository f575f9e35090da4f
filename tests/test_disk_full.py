"""A full disk (or any write error) while a run writes packings, checkpoints, frames or its
history: one line naming the file and the cause, exit code 1, no traceback, the last
checkpoint intact (a resume then gives the uninterrupted history)."""

import errno
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from grainscale.cli import main
from grainscale.io import faults
from grainscale.io.checkpoint import read_checkpoint, write_checkpoint

sys.path.insert(0, str(Path(__file__).parent / "coupling"))
from test_multiscale_run import run_folder_with_packings_of, small_unit_element  # noqa: E402


class FullDisk:
    """open() whose files take `room` bytes, then raise ENOSPC (a disk that fills)."""

    def __init__(self, room: int):
        self.room = room

    def __call__(self, path, mode="r", *args, **kw):
        f = open(path, mode, *args, **kw)  # noqa: SIM115 - wrapped and returned
        if "w" not in mode:
            return f
        room, write = [self.room], f.write

        def limited(data):
            if len(data) > room[0]:
                raise OSError(errno.ENOSPC, "No space left on device")
            room[0] -= len(data)
            return write(data)

        f.write = limited
        return f


def test_a_file_that_does_not_fit_is_an_error_naming_it_and_the_old_file_stays(
        tmp_path, monkeypatch):
    """write_checkpoint onto an existing file when the disk fills halfway: OSError
    ENOSPC naming the file, no temporary file left, the existing file as it was."""
    path = tmp_path / "c.h5"
    old = {"g": {"a": np.arange(10.0)}}
    write_checkpoint(path, old, {"step": 1})
    import grainscale.io.checkpoint as ck

    monkeypatch.setattr(ck, "open", FullDisk(100), raising=False)
    with pytest.raises(OSError) as info:
        write_checkpoint(path, {"g": {"a": np.arange(1e5)}}, {"step": 2})
    assert info.value.errno == errno.ENOSPC and "c.tmp.h5" in str(info.value)
    assert not (tmp_path / "c.tmp.h5").exists()
    groups, attrs = read_checkpoint(path)
    assert attrs["step"] == 1 and np.array_equal(groups["g"]["a"], old["g"]["a"])


@pytest.fixture(scope="module")
def unit_element(tmp_path_factory):
    """The small unit element (8 RVEs of 120 spheres), its uninterrupted history."""
    tmp = tmp_path_factory.mktemp("ue")
    case = small_unit_element(tmp, end=0.006, interval=0.0004)
    ref = tmp / "ref"
    assert main(["run", str(case), "--out", str(ref), "--quiet", "--checkpoint-every",
                 "4"]) == 0
    return case, ref, (ref / "history.csv").read_text()


@pytest.mark.validation  # 3 runs in their own processes; the writer's own test is fast
@pytest.mark.parametrize("point", ["checkpoint.part.mid_write:2", "vtu.tmp_written:2",
                                   "history.mid_row:10"])
def test_a_full_disk_during_a_run_stops_it_with_one_line(unit_element, tmp_path, point):
    """A full disk while the second checkpoint, the second frame or the tenth history
    row is written (an injected ENOSPC, in a process of its own): exit 1, one line on
    stderr naming the cause and the checkpoint to resume from; --resume, once there is
    room, gives the uninterrupted history to the byte."""
    case, ref, history = unit_element
    out = run_folder_with_packings_of(ref, tmp_path / "out")
    cmd = [sys.executable, "-m", "grainscale", "run", str(case), "--out", str(out),
           "--quiet", "--checkpoint-every", "4"]
    env = {**__import__("os").environ, faults.ENV: f"{point}/ENOSPC"}
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 1, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "No space left on device" in lines[0] and "--resume" in lines[0], lines[0]
    assert main(["run", str(case), "--out", str(out), "--quiet", "--checkpoint-every", "4",
                 "--resume"]) == 0
    assert (out / "history.csv").read_text() == history


def test_a_packing_that_does_not_fit_stops_the_run_before_it_starts(tmp_path, monkeypatch,
                                                                    capsys):
    """The first packing file cannot be written (the disk fills): exit 1 and one line
    naming the file, no packing or temporary file left, no checkpoint to resume."""
    import grainscale.io.checkpoint as ck

    monkeypatch.delenv("GRAINSCALE_PACKING_STORE", raising=False)  # generated, written
    case = small_unit_element(tmp_path, end=0.002, interval=0.0004)
    monkeypatch.setattr(ck, "open", FullDisk(1000), raising=False)
    out = tmp_path / "out"
    assert main(["run", str(case), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0] and "sand_0.h5" in err[0]
    assert "no checkpoint" in err[0]
    assert not list((out / "packings").glob("*"))


def test_the_h5_image_is_an_ordinary_hdf5_file(tmp_path):
    """Files built in memory are read by h5py as any other (a packing round trip is in
    tests/test_io_packing.py)."""
    path = tmp_path / "c.h5"
    write_checkpoint(path, {"g": {"a": np.arange(3e5)}}, {"step": 3})  # compressed
    with h5py.File(path, "r") as f:
        assert f["g/a"].compression == "gzip" and f.attrs["step"] == 3

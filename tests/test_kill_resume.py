"""SIGKILL at every point of the step loop and of the checkpoint write, then --resume:
history.csv, the frames and the .pvd series end byte-identical to an uninterrupted
run's (issue 13, item 1). studies/unit_element/kill_resume.py is the long version.

The runs kill themselves at the named points of grainscale.io.faults (GRAINSCALE_KILL_AT
= "POINT:N[@RANK]": the Nth time the process gets there). A chain: the first run is
killed at the first (point, N) of a schedule, each later run resumes the same command
and is killed at the next, a last resume ends the run. The counts are chosen so the
kills spread over the whole run; a run that ends without reaching its point fails the
test. Serial runs are forked from a server process that imported grainscale once (a run
then starts in ~0.5 s instead of ~2 s; each is still a process of its own, killed by a
real SIGKILL); MPI runs are started by mpiexec.
"""

import json
import os
import select
import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest
import tomli_w

from grainscale.config.base import ConfigError
from grainscale.coupling import checkpoints
from grainscale.distributed.comm import Comm
from grainscale.io import faults
from test_cli_run import CASE

sys.path.insert(0, str(Path(__file__).parent / "coupling"))
from test_mpi import MPIEXEC  # noqa: E402
from test_multiscale_run import small_unit_element  # noqa: E402

# One job per line on stdin ({"argv", "kill_at", "log"}), its wait status on stdout.
SERVER = """
import json, os, sys, traceback
import grainscale.coupling.driver  # noqa: F401  (the imports, once; no kernel runs here)
from grainscale.cli import main
from grainscale.io import faults
for line in sys.stdin:
    job = json.loads(line)
    pid = os.fork()
    if pid == 0:
        code = 99
        try:
            fd = os.open(job["log"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            faults.arm(job["kill_at"])
            code = main(job["argv"])
        except BaseException:
            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    print(json.dumps(os.waitstatus_to_exitcode(status)), flush=True)
"""

# Serial, checkpoints every 3 steps of 60, a history row and a frame (with the rigid
# body's) every 6 steps: (point, N) in the order of the kills, the step of the newest
# checkpoint they leave in the comment.
SERIAL = [
    ("checkpoint.committed", 1),             # 3, old parts not yet cleaned
    ("step.begin", 5),                       # 6
    ("history.mid_row", 1),                  # 9, half of row 12 on disk
    ("vtu.tmp_written", 1),                  # 9, frame 12 under its temporary name
    ("vtu.renamed", 2),                      # 9, rigid frame 12 not yet in rigid.pvd
    ("pvd.tmp_written", 1),                  # 9, a resume cutting back frames.pvd
    ("frame.written", 1),                    # 9, frame 12 complete, no checkpoint yet
    ("run.start", 1),                        # 9, the resume's outputs cut back
    ("checkpoint.begin", 2),                 # 12
    ("checkpoint.part.mid_write", 2),        # 15, half a part under its temporary name
    ("checkpoint.part.tmp_written", 2),      # 18
    ("checkpoint.part.renamed", 2),          # 21, step 24's part, no manifest for it
    ("checkpoint.parts_written", 2),         # 24
    ("checkpoint.rotated", 2),               # 27: checkpoint.h5 missing, prev is 27
    ("checkpoint.rotated", 1),               # 27 again: a resume from the fallback
    ("checkpoint.manifest.mid_write", 1),    # 27
    ("checkpoint.manifest.tmp_written", 1),  # 27
    ("checkpoint.manifest.renamed", 2),      # 33
    ("checkpoint.cleanup", 1),               # 36
    ("checkpoint.done", 2),                  # 42
    ("step.advanced", 4),                    # 45
    ("history.row", 1),                      # 45, row 48 written
    ("step.begin", 10),                      # 51
    ("history.mid_row", 2),                  # 57, half of row 60
    ("run.end", 1),                          # 60, the final row written
    ("history.truncate_tmp", 1),             # 60, a resume cutting back history.csv
]
# 2 ranks, rebalancing every 4 steps; @R: rank R alone dies (the job with it)
MPI = [
    ("checkpoint.part.tmp_written", "2@1"),
    ("step.rebalanced", "2"),
    ("checkpoint.rotated", "2@0"),
    ("step.advanced", "5@1"),
    ("history.mid_row", "2"),
    ("checkpoint.done", "3"),
    ("vtu.renamed", "3"),
]
# the small unit element (8 points, each a DEM RVE of 120 spheres), 18 steps, a row per
# step, checkpoints every 3
MULTISCALE = [
    ("checkpoint.part.mid_write", 2),
    ("step.advanced", 4),
    ("checkpoint.rotated", 2),
    ("history.mid_row", 4),
    ("checkpoint.committed", 2),
]


class Server:
    """Serial runs forked from one warm process; run() returns the exit code (-9 for
    SIGKILL) and what the run wrote to stdout and stderr."""

    def __init__(self, folder: Path):
        script = folder / "server.py"
        script.write_text(SERVER)
        self.log = folder / "run.log"
        self.proc = subprocess.Popen([sys.executable, str(script)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True)

    def run(self, argv: list[str], kill_at: str | None = None, timeout: float = 300):
        self.proc.stdin.write(json.dumps({"argv": argv, "kill_at": kill_at,
                                          "log": str(self.log)}) + "\n")
        self.proc.stdin.flush()
        if not select.select([self.proc.stdout], [], [], timeout)[0]:
            self.proc.kill()
            raise TimeoutError(f"{argv} (kill at {kill_at}) ran over {timeout} s")
        return json.loads(self.proc.stdout.readline()), self.log.read_text()

    def close(self):
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = Server(tmp_path_factory.mktemp("server"))
    yield s
    s.close()


def mpi_run(n: int, argv: list[str], kill_at: str | None = None, timeout: float = 300):
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    env.pop(faults.ENV, None)
    if kill_at:
        env[faults.ENV] = kill_at
    r = subprocess.run([MPIEXEC, "-n", str(n), sys.executable, "-m", "grainscale", *argv],
                       env=env, capture_output=True, text=True, timeout=timeout)
    # a rank killed by a signal: hydra ends the job, exit code the signal number
    code = -9 if r.returncode == 9 and "signal 9" in r.stdout + r.stderr else r.returncode
    return code, r.stdout + r.stderr


def newest_step(out: Path) -> int | None:
    try:
        return int(checkpoints.find(out, Comm(None)).attrs["step"])
    except ConfigError:
        return None


def kill_chain(run, argv: list[str], schedule, out: Path) -> tuple[list, list[str]]:
    """Kill `argv` at each (point, N) of the schedule in turn (runs after the first with
    --resume), then resume it to the end. Returns the newest checkpoint's step after
    each kill and the resumes' logs."""
    steps, logs = [], []
    for i, (point, n) in enumerate(schedule):
        code, log = run([*argv, *(["--resume"] if i else [])], f"{point}:{n}")
        assert code == -9, f"kill {i} at {point}:{n}: exit code {code}, not SIGKILL:\n{log}"
        if i:
            logs.append(log)
        steps.append(newest_step(out))
        assert steps[-1] is not None, f"no checkpoint to resume after the kill at {point}:{n}"
    code, log = run([*argv, "--resume"], None)
    assert code == 0, log
    return steps, [*logs, log]


def assert_same_outputs(out: Path, ref: Path) -> None:
    assert (out / "history.csv").read_bytes() == (ref / "history.csv").read_bytes()
    for series in ("frames.pvd", "rigid.pvd"):
        a, b = out / series, ref / series
        assert a.is_file() == b.is_file() and (not a.is_file() or a.read_bytes() == b.read_bytes()
                                               ), series
    frames = sorted(p.name for p in (ref / "frames").iterdir())
    assert sorted(p.name for p in (out / "frames").iterdir()) == frames
    for name in frames:
        assert (out / "frames" / name).read_bytes() == (ref / "frames" / name).read_bytes(), name
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]  # no temporary file left


def _case(tmp_path, **solver) -> Path:
    case = tomllib.loads(textwrap.dedent(CASE))
    case["solver"].update(solver)
    path = tmp_path / "case.toml"
    path.write_text(tomli_w.dumps(case))
    return path


@pytest.fixture(scope="module")
def block(tmp_path_factory, server):
    """The tiny block under a plate (test_cli_run.py), 60 steps, and its uninterrupted
    run; rebalance_every applies only under MPI."""
    tmp = tmp_path_factory.mktemp("block")
    case = _case(tmp, rebalance_every=4)
    ref = tmp / "ref"
    code, log = server.run(["run", str(case), "--out", str(ref), "--quiet",
                            "--checkpoint-every", "3"])
    assert code == 0, log
    return case, ref


def test_every_point_is_in_a_schedule():
    used = {p for p, _ in SERIAL + MPI + MULTISCALE}
    assert used == set(faults.POINTS), set(faults.POINTS) ^ used


def test_kill_spec_is_checked():
    for bad in ("step.begin", "step.begin:0", "step.begn:1", "step.begin:x", "step.begin:1@"):
        with pytest.raises(ValueError, match="GRAINSCALE_KILL_AT"):
            faults.arm(bad)
    faults.arm("step.begin:2@1")
    assert faults.ARMED
    faults.arm(None)
    assert not faults.ARMED
    faults.point("step.begin")  # unarmed: nothing happens


@pytest.mark.validation
def test_resume_after_sigkill_at_every_point(block, server, tmp_path):
    """26 kills over a serial run of 60 steps: every point of the step loop and of the
    checkpoint write, the fallback to checkpoint.prev.h5 (and kills while resuming from
    it), kills while a resume cuts its outputs back."""
    case, ref = block
    out = tmp_path / "out"
    argv = ["run", str(case), "--out", str(out), "--quiet", "--checkpoint-every", "3"]
    steps, logs = kill_chain(server.run, argv, SERIAL, out)
    assert len(steps) >= 20 and min(steps) <= 6 and max(steps) == 60, steps
    assert steps == sorted(steps), steps  # the run went on from kill to kill
    assert sum("resuming from the previous checkpoint" in log for log in logs) == 4, logs
    assert_same_outputs(out, ref)


@pytest.mark.validation
def test_resume_after_sigkill_under_mpi(block, tmp_path):
    """The same on 2 ranks (one rank killed alone, or both at the same point), with
    rebalancing: the serial run's outputs."""
    case, ref = block
    out = tmp_path / "out"
    argv = ["run", str(case), "--out", str(out), "--quiet", "--checkpoint-every", "3"]
    steps, _ = kill_chain(lambda a, k: mpi_run(2, a, k), argv, MPI, out)
    assert steps == sorted(steps) and min(steps) <= 6 and max(steps) >= 36, steps
    assert_same_outputs(out, ref)


@pytest.mark.validation
def test_resume_after_sigkill_multiscale(server, tmp_path):
    """RVE states with their contact histories in the parts."""
    case = small_unit_element(tmp_path, end=0.012, interval=0.0004)
    ref, out = tmp_path / "ref", tmp_path / "out"
    argv = ["run", str(case), "--quiet", "--checkpoint-every", "3"]
    code, log = server.run([*argv, "--out", str(ref)])
    assert code == 0, log
    shutil.copytree(ref / "packings", out / "packings")  # generated once
    steps, _ = kill_chain(server.run, [*argv, "--out", str(out)], MULTISCALE, out)
    assert steps == sorted(steps) and max(steps) == 18, steps
    shutil.rmtree(ref / "packings")
    shutil.rmtree(out / "packings")
    assert_same_outputs(out, ref)


def test_a_new_run_discards_an_earlier_runs_checkpoints(block, server, tmp_path):
    """A run without --resume into a folder with an earlier run's checkpoints, killed
    before its first checkpoint: a resume finds none. (They used to stay until the first
    checkpoint replaced them, so this resume continued the earlier run's end with the
    new history.csv: a history of one row, exit code 0.)"""
    case, ref = block
    out = tmp_path / "out"
    shutil.copytree(ref, out)
    argv = ["run", str(case), "--out", str(out), "--quiet", "--checkpoint-every", "3"]
    code, _ = server.run(argv, "step.begin:2")
    assert code == -9
    assert not (out / "checkpoint.h5").exists() and not (out / "checkpoint.parts").exists()
    code, log = server.run([*argv, "--resume"])
    assert code == 2 and "no checkpoint" in log, log
    code, log = server.run(argv)
    assert code == 0, log
    assert_same_outputs(out, ref)

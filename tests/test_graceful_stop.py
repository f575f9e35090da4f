"""Graceful stops (coupling/stops.py): SIGINT, SIGTERM and SIGUSR1 stop a run at the next
step boundary with a checkpoint, exit code 3 and a message; --resume then gives the
history of an uninterrupted run, to the byte. A second SIGINT stops at once."""

import os
import signal
import sys
from pathlib import Path

import pytest

import grainscale as gs
from grainscale.cli import main
from grainscale.coupling.stops import EXIT_STOPPED
from grainscale.io import faults

sys.path.insert(0, str(Path(__file__).parent / "coupling"))
from test_mpi import MPIEXEC, mpirun, small_column  # noqa: E402
from test_multiscale_run import run_folder_with_packings_of  # noqa: E402


@pytest.fixture(scope="module")
def column(tmp_path_factory):
    """The reduced column (geostatic stage, release, dynamic RVEs, retiling) and its
    uninterrupted history."""
    tmp = tmp_path_factory.mktemp("stop")
    case = small_column(tmp)
    ref = tmp / "full"
    assert main(["run", str(case), "--out", str(ref), "--quiet", "--threads", "1"]) == 0
    return case, ref, (ref / "history.csv").read_text()


@pytest.mark.parametrize("sig", ["TERM", pytest.param("INT", marks=pytest.mark.validation),
                                 pytest.param("USR1", marks=pytest.mark.validation)])
def test_a_signal_stops_at_the_next_step_with_a_checkpoint(column, tmp_path, capsys, sig):
    """The signal arrives during step 31 (after its MPM and DEM work): the run stops at
    the top of the next step, writes a checkpoint there although none is due (the case
    checkpoints every 2,000 steps), exits 3 and says where; --resume gives the uninterrupted
    history to the byte."""
    case, ref, history = column
    out = run_folder_with_packings_of(ref, tmp_path / "out")
    common = ["run", str(case), "--out", str(out), "--quiet", "--threads", "1"]
    faults.arm(f"step.advanced:31/{sig}")
    try:
        assert main(common) == EXIT_STOPPED
    finally:
        faults.arm(None)
    err = capsys.readouterr().err
    assert f"stopped at step 31 (SIG{sig})" in err and "continue with --resume" in err
    assert (out / "checkpoint.h5").is_file()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # handlers restored
    assert main([*common, "--resume"]) == 0
    assert (out / "history.csv").read_text() == history


def test_a_second_ctrl_c_stops_at_once(column, tmp_path):
    """Two SIGINTs in one step: the first asks for a stop at the next step, the second
    raises KeyboardInterrupt at once (from the Python API; the command line exits 130
    with a message). The checkpoint written before (step 20) is intact: --resume from it
    gives the uninterrupted history."""
    case, ref, history = column
    out = run_folder_with_packings_of(ref, tmp_path / "out")

    def twice(state):
        if state.step == 27:
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)

    with pytest.raises(KeyboardInterrupt):
        gs.run(case, out, checkpoint_every=20, threads=1, progress=False, on_step=twice)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    r = gs.run(case, out, checkpoint_every=20, threads=1, progress=False, resume=True)
    assert (r.out / "history.csv").read_text() == history


@pytest.mark.validation  # 2 MPI jobs
@pytest.mark.skipif(MPIEXEC is None, reason="no mpiexec")
def test_ranks_stop_together_when_one_is_signalled(column, tmp_path):
    """On 2 ranks, SIGTERM reaches rank 1 only (as a scheduler's signal may reach the
    ranks at different times): both stop at the same step (the ranks agree each step),
    the job exits 3, and a resume on 2 ranks gives the serial history to the byte."""
    case, ref, history = column
    out = run_folder_with_packings_of(ref, tmp_path / "out")
    common = ["run", str(case), "--out", str(out), "--quiet"]
    r = mpirun(2, common, env={faults.ENV: "step.advanced:31@1/TERM"})
    assert r.returncode == EXIT_STOPPED, r.stderr
    assert "stopped at step 31 (SIGTERM)" in r.stderr
    r = mpirun(2, [*common, "--resume"])
    assert r.returncode == 0, r.stderr
    assert (out / "history.csv").read_text() == history

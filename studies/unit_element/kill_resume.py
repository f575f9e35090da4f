"""Kill the unit element run with SIGKILL at many moments, resume it each time, and
check that history.csv ends byte-identical to an uninterrupted run's (issue 13, item 1;
tests/test_kill_resume.py is the CI version on a reduced case).

    python studies/unit_element/kill_resume.py [--case case.toml] [--out ue_kill]
        [--max-steps 3000] [--kills 24] [--checkpoint-every 100] [--ranks 1]

First the run to --max-steps without a stop (OUT/ref), then the same command into
OUT/killed, killed in turn at --kills moments spread evenly over the run, each at one of
the named fault-injection points of the solver (every phase of the step loop and of the
checkpoint write, in turn: GRAINSCALE_KILL_AT=POINT:N, the Nth time the process gets
there, N computed from the step the run resumes from, the target step and the reference
run's row and frame steps), and resumed with --resume after each, a last resume running
it to the end. Under --ranks N > 1 every run is `mpiexec -n N` and each kill takes every
rank that reaches the point. Prints a line per kill and, last, a JSON object: kills,
how many killed the run (a point not reached lets the run end: reported, not fatal),
the steps of the newest checkpoint after each, and whether history.csv, frames.pvd and
the frames are byte-identical. Exit code 0 if they are.

The unit element at 3000 steps (t = 2.1 s of 6.9 s, 31 history rows, frames at steps 0,
~1000 and ~2000), checkpoints every 100: 3.5 minutes uninterrupted on 2 cores, 7.5
minutes for the killed run (24 kills at 21 different points, 4 resumes falling back to
checkpoint.prev.h5); identical history.csv and frames.
"""

import argparse
import contextlib
import io
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import grainscale as gs
from grainscale import blocks

CASES = Path(__file__).resolve().parents[2] / "examples" / "unit_element"  # the case files

# kinds of point, by what their count N counts in a run resumed from a checkpoint
PER_STEP = {"step.begin": 1, "step.advanced": 0}  # hits at steps C0 + k (+1 for begin)
PER_ROW = ("history.mid_row", "history.row")
PER_FRAME = ("vtu.tmp_written", "vtu.renamed", "pvd.tmp_written", "frame.written")
PER_SAVE = ("checkpoint.begin", "checkpoint.part.mid_write", "checkpoint.part.tmp_written",
            "checkpoint.part.renamed", "checkpoint.parts_written", "checkpoint.rotated",
            "checkpoint.manifest.mid_write", "checkpoint.manifest.tmp_written",
            "checkpoint.manifest.renamed", "checkpoint.committed", "checkpoint.cleanup",
            "checkpoint.done")
AT_START = ("run.start", "history.truncate_tmp")  # a resume killed before its first step
# the order the kills go through the points; a frame point instead whenever a frame is
# written before the next kill's target step (frames are rare); run.end is the last kill
CYCLE = ("step.begin", *PER_SAVE[:6], "history.mid_row", *PER_SAVE[6:], "step.advanced",
         "history.row")


def command(case: Path, out: Path, max_steps: int, every: int, ranks: int) -> list[str]:
    cmd = [sys.executable, "-m", "grainscale", "run", str(case), "--out", str(out),
           "--quiet", "--max-steps", str(max_steps), "--checkpoint-every", str(every)]
    if ranks > 1:
        mpiexec = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) \
            or shutil.which("mpiexec")
        if mpiexec is None:
            raise SystemExit("--ranks: no mpiexec (install the mpich wheel)")
        cmd = [mpiexec, "-n", str(ranks), *cmd]
    return cmd


def run(cmd: list[str], kill_at: str | None) -> tuple[bool, int, str]:
    """(killed by SIGKILL, exit code, output)."""
    env = {k: v for k, v in os.environ.items() if k != blocks.FAULT_ENV}
    if kill_at:
        env[blocks.FAULT_ENV] = kill_at
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    text = r.stdout + r.stderr
    # serial: -9; mpiexec (hydra) ends the job and exits with the signal number
    killed = r.returncode == -9 or (r.returncode == 9 and "signal 9" in text)
    return killed, r.returncode, text


def newest_step(out: Path) -> int | None:
    try:
        with contextlib.redirect_stderr(io.StringIO()):  # its fallback warning: the run's
            return int(blocks.latest_checkpoint(out)[0]["step"])
    except gs.ConfigError:
        return None


def row_steps(history: Path) -> list[int]:
    rows = [ln for ln in history.read_text().splitlines() if not ln.startswith("#")][1:]
    return [int(r.split(",", 1)[0]) for r in rows]


def frame_steps(out: Path) -> list[int]:
    """Steps of the frames: a frame is written at the step of a history row (its time
    is one of the rows')."""
    import xml.etree.ElementTree as ET

    text = (out / "history.csv").read_text().splitlines()
    data = [ln.split(",") for ln in text if not ln.startswith("#")]
    col = data[0].index("time") if "time" in data[0] else None
    if col is None or not (out / "frames.pvd").is_file():
        return []
    step_of = {float(r[col]): int(r[0]) for r in data[1:]}
    times = [float(d.get("timestep")) for d in ET.parse(out / "frames.pvd").iter("DataSet")]
    return [step_of[t] for t in times if t in step_of]


def count(point: str, c0: int, target: int, every: int, rows, frames) -> int | None:
    """N such that the Nth arrival at `point` of a run resumed at step c0 is at (or just
    after) step `target`; None if the run has no such moment left."""
    if point in PER_STEP:
        return max(1, target - c0 + PER_STEP[point])
    if point in AT_START or point == "run.end":
        return 1
    if point in PER_SAVE:
        return max(1, target // every - c0 // every)
    steps = rows if point in PER_ROW else frames
    later = [s for s in steps if s > c0]
    if not later:
        return None
    return max(1, sum(s <= target for s in later))


def identical(a: Path, b: Path) -> bool:
    return a.is_file() == b.is_file() and (not a.is_file() or a.read_bytes() == b.read_bytes())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", type=Path, default=CASES / "case.toml")
    ap.add_argument("--out", type=Path, default=Path("ue_kill"))
    ap.add_argument("--max-steps", type=int, default=3000)
    ap.add_argument("--kills", type=int, default=24)
    ap.add_argument("--checkpoint-every", type=int, default=100)
    ap.add_argument("--ranks", type=int, default=1)
    args = ap.parse_args()
    m, every = args.max_steps, args.checkpoint_every
    if m < 3 * every:
        raise SystemExit("--max-steps must be at least 3 x --checkpoint-every")
    ref, out = args.out / "ref", args.out / "killed"
    for d in (ref, out):
        shutil.rmtree(d, ignore_errors=True)
    t0 = time.perf_counter()
    killed, code, text = run(command(args.case, ref, m, every, args.ranks), None)
    if code != 0:
        raise SystemExit(f"the reference run failed (exit code {code}):\n{text}")
    t_ref = time.perf_counter() - t0
    print(f"reference: {m} steps in {t_ref:.0f} s", flush=True)
    rows, frames = row_steps(ref / "history.csv"), frame_steps(ref)
    if (ref / "packings").is_dir():  # the RVE packings: generated once
        shutil.copytree(ref / "packings", out / "packings")

    cmd = command(args.case, out, m, every, args.ranks)
    # kill moments: target steps spread evenly over (every, m - every], the first after
    # the first checkpoint (a run killed before it has nothing to resume), two kills of
    # a resume at its start, and the last after the final row
    k = max(args.kills, 4)
    targets = [every + round(i * (m - 2 * every) / (k - 3)) for i in range(1, k - 2)]
    plan = [(None, t) for t in targets]
    plan.insert(1, ("run.start", targets[0]))
    plan.insert(len(plan) // 2, ("history.truncate_tmp", targets[len(targets) // 2]))
    plan.append(("run.end", m))
    t0 = time.perf_counter()
    log, c0, cycle, frame_kills, frames_left = [], 0, 0, 0, list(frames)
    for i, (point, target) in enumerate(plan):
        upto = next((t for p, t in plan[i + 1:] if p is None), m)
        frames_left = [s for s in frames_left if s > c0]
        if point is None and i and frames_left and frames_left[0] <= upto:
            point = PER_FRAME[frame_kills % len(PER_FRAME)]
            target = frames_left.pop(0)  # killed while writing the next frame
            frame_kills += 1
        elif point is None:
            point = CYCLE[cycle % len(CYCLE)]
            cycle += 1
        n = count(point, c0, target, every, rows, frames)
        if n is None:  # no row left after c0: a kill at the top of a step
            point, n = "step.begin", max(1, target - c0 + 1)
        spec = f"{point}:{n}"
        resumed = c0
        was_killed, code, text = run([*cmd, *(["--resume"] if i else [])], spec)
        fell_back = "resuming from the previous checkpoint" in text
        if not was_killed and code != 0:
            raise SystemExit(f"kill {i + 1} ({spec}): the run failed (exit code {code}):\n"
                             f"{text}")
        c0 = newest_step(out) or 0
        log.append({"at": spec, "target_step": target, "resumed_from": resumed if i else None,
                    "killed": was_killed, "fell_back": fell_back, "newest_checkpoint": c0})
        print(f"kill {i + 1}/{len(plan)} at {spec} (target step {target}, "
              f"{'resumed from ' + str(resumed) if i else 'new run'}"
              f"{', from checkpoint.prev.h5' if fell_back else ''}): "
              f"{'killed' if was_killed else 'ran to its end, exit code ' + str(code)}; "
              f"newest checkpoint at step {c0}", flush=True)
    _, code, text = run([*cmd, "--resume"], None)
    if code != 0:
        raise SystemExit(f"the last resume failed (exit code {code}):\n{text}")
    t_killed = time.perf_counter() - t0
    same_history = identical(out / "history.csv", ref / "history.csv")
    names = sorted(p.name for p in (ref / "frames").iterdir())
    same_frames = (identical(out / "frames.pvd", ref / "frames.pvd")
                   and sorted(p.name for p in (out / "frames").iterdir()) == names
                   and all(identical(out / "frames" / f, ref / "frames" / f) for f in names))
    result = {"case": str(args.case), "max_steps": m, "checkpoint_every": every,
              "ranks": args.ranks, "kills": len(plan),
              "killed": sum(e["killed"] for e in log),
              "fallbacks_to_previous": sum(e["fell_back"] for e in log),
              "points": sorted({e["at"].split(":")[0] for e in log if e["killed"]}),
              "newest_checkpoint_after_each": [e["newest_checkpoint"] for e in log],
              "history_rows": len(rows), "frames": len(names),
              "identical_history": same_history, "identical_frames": same_frames,
              "reference_seconds": round(t_ref, 1), "killed_run_seconds": round(t_killed, 1)}
    print(json.dumps(result))
    return 0 if same_history and same_frames else 1


if __name__ == "__main__":
    sys.exit(main())

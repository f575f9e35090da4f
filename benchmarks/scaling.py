"""Strong and weak scaling of a multiscale run over MPI ranks x numba threads.

Definitions of seed §4.2.2-4.2.3, with n = ranks x threads cores:
  strong (fixed problem):   speedup S = t_1 / t_n (Eq. 20), efficiency S / n (Eq. 21);
                            Amdahl bound 1 / (s + (1 - s) / n) (Eq. 23)
  weak (problem ~ n):       scaled speedup n t_1 / t_n (Eq. 24), efficiency t_1 / t_n
                            (Eq. 25); Gustafson bound s + (1 - s) n (Eq. 26)
t is the wall time per step (cost.json of `grainscale run`): MPM (this rank's points) +
DEM (its RVEs) + communication (reductions) + waiting (load imbalance, measured by a
barrier before every reduction). Outputs ("other") are reported beside it but left out
of t: the benchmark writes no frames or checkpoints, only the history rows of the first
and last step, whose cost over a few dozen steps says nothing about a real run.

The serial fraction s is reported two ways:
  profile     the share of a one-core step spent in work every rank repeats whatever n
              (the grid-node stages of the replicated grid), timed stage by stage; this
              is the s the seed takes from its time profile (its MPM share, 0.023);
  Karp-Flatt  e = (1/S - 1/n) / (1 - 1/n) from each measured strong speedup, which
              also absorbs imbalance, communication and a shared machine's noise.

Every configuration runs the same case with `--max-steps` in its own process group
(`mpiexec -n R ... --threads T`); packings are generated once and reused.

    PYTHONPATH=src python benchmarks/scaling.py [--case examples/column_collapse/quick.toml]
        [--configs 1x1 2x1 1x2] [--steps 30] [--weak-axis y] [--repeats 1] [--plot PNG]

On a cluster, run it inside an allocation with the configurations to study (e.g.
--configs 1x1 2x1 4x1 8x1 16x1 32x1); the last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import tomli_w

ROOT = Path(__file__).resolve().parents[1]


def parse_config(text: str) -> tuple[int, int]:
    r, t = text.lower().split("x")
    return int(r), int(t)


def widened(case: dict, axis: str, k: int) -> dict:
    """The column slice made k times thicker along `axis` (k times the points and RVEs):
    grid cells, the body, and the boxes of the far side wall and the gate scale with it."""
    a = "xyz".index(axis)
    c = json.loads(json.dumps(case))  # deep copy
    body = c["bodies"][0]
    width = body["hi"][a] - body["lo"][a]
    h = c["grid"]["cell_size"]
    h = h if isinstance(h, float) else h[a]
    c["grid"]["cells"][a] += round((k - 1) * width / h)
    body["hi"][a] = body["lo"][a] + k * width
    for bc in c["boundaries"]:
        box = bc.get("box")
        if box is None:
            continue
        if abs(box["lo"][a] - box["hi"][a]) < 1e-12:  # the far wall
            box["lo"][a] = box["hi"][a] = body["hi"][a]
        else:
            box["hi"][a] = body["hi"][a]
    return c


def for_benchmark(case: dict) -> dict:
    """No frames, no checkpoints, a history row only at the start and the end."""
    c = json.loads(json.dumps(case))
    c["output"].update(frames=False, checkpoint_every=0,
                       interval=c["time"]["end"] - c["time"].get("start", 0.0))
    return c


def step_seconds(r: dict) -> float:
    t = r["seconds_per_step"]
    return t["mpm"] + t["dem"] + t["comm"] + t["wait"]


def run(case_path: Path, out: Path, ranks: int, threads: int, steps: int) -> dict:
    """One `grainscale run` under mpiexec; its cost.json."""
    mpiexec = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or "mpiexec"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "NUMBA_NUM_THREADS": str(threads)}
    cmd = [mpiexec, "-n", str(ranks), sys.executable, "-m", "grainscale", "run",
           str(case_path), "--out", str(out), "--quiet", "--max-steps", str(steps),
           "--threads", str(threads)]
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return json.loads((out / "cost.json").read_text())


def replicated_share(case_path: Path, out: Path, steps: int) -> dict:
    """Time the stages of a one-rank, one-thread step; the grid-node stages are the work
    every rank repeats (serial fraction by profile)."""
    import numba

    numba.set_num_threads(1)
    from grainscale.config.case import load_case
    from grainscale.coupling import materials
    from grainscale.mpm import step as stages
    from grainscale.mpm.setup import build_state

    case = load_case(case_path)
    factory = materials.prepare(case, case_path.parent, out, progress=False)
    s = build_state(case, case_path.parent, n_threads=1, material_factory=factory)
    replicated = ("rigid_velocity", "grid_velocity", "integrate_grid", "advance_rigid")
    spent = dict.fromkeys(replicated, 0.0)
    originals = {name: getattr(stages, name) for name in replicated}

    def timed(name):
        def wrapper(*args):
            t = time.perf_counter()
            originals[name](*args)
            spent[name] += time.perf_counter() - t
        return wrapper

    for name in replicated:
        setattr(stages, name, timed(name))
    try:
        stages.step(s, s.stable_dt())  # warm-up
        spent.update(dict.fromkeys(replicated, 0.0))
        t = time.perf_counter()
        for _ in range(steps):
            stages.step(s, s.stable_dt())
        total = (time.perf_counter() - t) / steps
    finally:
        for name in replicated:
            setattr(stages, name, originals[name])
    rep = sum(spent.values()) / steps
    return {"step_seconds": total, "replicated_seconds": rep, "s_profile": rep / total,
            "grid_nodes": int(s.grid.n_nodes), "points": int(s.points.n)}


def table(rows: list[dict], weak: bool) -> None:
    head = (f"{'ranks':>5} {'thr':>3} {'pts':>6} {'step ms':>9} {'MPM':>7} {'DEM':>8} "
            f"{'comm':>6} {'wait':>6} {'other':>6} {'comm %':>6} {'KB/step':>7} "
            f"{'scaled S' if weak else 'speedup':>8} {'eff':>5} {'bound':>6}")
    print(head)
    for r in rows:
        t = r["seconds_per_step"]
        kb = r["this_invocation"]["reduced_bytes_per_rank_per_step"] / 1e3
        print(f"{r['ranks']:>5} {r['threads']:>3} {r['points']:>6} {step_seconds(r) * 1e3:9.2f} "
              f"{t['mpm'] * 1e3:7.2f} {t['dem'] * 1e3:8.2f} {t['comm'] * 1e3:6.3f} "
              f"{t['wait'] * 1e3:6.2f} {t['other'] * 1e3:6.2f} "
              f"{100 * t['comm'] / step_seconds(r):6.2f} "
              f"{kb:7.1f} {r['speedup']:8.3f} "
              f"{r['efficiency']:5.3f} {r['bound']:6.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=Path, default=ROOT / "examples/column_collapse/quick.toml")
    ap.add_argument("--configs", nargs="+", default=["1x1", "2x1", "1x2"],
                    help="RANKSxTHREADS; the first one is the reference (1x1)")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=1,
                    help="rounds over all configs (interleaved); the best of each is kept")
    ap.add_argument("--weak-axis", default="y", help="axis the weak-scaling case grows along")
    ap.add_argument("--no-weak", action="store_true")
    ap.add_argument("--work", type=Path, default=Path("scaling-work"))
    ap.add_argument("--plot", type=Path, default=None,
                    help="PNG of speedup against cores with the Amdahl/Gustafson bounds")
    args = ap.parse_args()
    configs = [parse_config(c) for c in args.configs]
    args.work.mkdir(parents=True, exist_ok=True)
    base = tomllib.loads(args.case.read_text())

    def case_file(k: int) -> Path:
        c = for_benchmark(base if k == 1 else widened(base, args.weak_axis, k))
        path = args.work / f"case_{k}.toml"
        path.write_text(tomli_w.dumps(c))
        return path

    def best_of_rounds(paths: list[Path]) -> list[dict]:
        """Each config once per round, rounds interleaved (a drifting machine then
        biases no config); the fastest step time of each config over the rounds."""
        out = args.work / "out"  # shared: packings are generated once and cached there
        runs = [[] for _ in configs]
        for _ in range(args.repeats):
            for i, (ranks, threads) in enumerate(configs):
                runs[i].append(run(paths[i], out, ranks, threads, args.steps))
        return [min(r, key=step_seconds) for r in runs]

    profile = replicated_share(case_file(1), args.work / "out", args.steps)
    print(f"profile (1 rank x 1 thread): {profile['step_seconds'] * 1e3:.2f} ms per step, "
          f"{profile['replicated_seconds'] * 1e6:.1f} us in replicated grid stages over "
          f"{profile['grid_nodes']} nodes -> s_profile = {profile['s_profile']:.2e}")
    s = profile["s_profile"]
    result = {"case": str(args.case), "steps": args.steps, "profile": profile}

    strong = best_of_rounds([case_file(1)] * len(configs))
    t1 = step_seconds(strong[0])
    for r in strong:
        n = r["ranks"] * r["threads"]
        r["speedup"] = t1 / step_seconds(r)
        r["efficiency"] = r["speedup"] / n
        r["bound"] = 1.0 / (s + (1 - s) / n)  # Amdahl with s_profile
        r["karp_flatt"] = (1 / r["speedup"] - 1 / n) / (1 - 1 / n) if n > 1 else None
    print("\nstrong scaling (fixed problem); bound = Amdahl with s_profile")
    table(strong, weak=False)
    kf = [r["karp_flatt"] for r in strong if r["karp_flatt"] is not None]
    if kf:
        print("Karp-Flatt serial fraction per config: "
              + ", ".join(f"{r['ranks']}x{r['threads']}: {r['karp_flatt']:.4f}"
                          for r in strong if r["karp_flatt"] is not None))
    result["strong"] = strong

    if not args.no_weak:
        weak = best_of_rounds([case_file(r * t) for r, t in configs])
        t1 = step_seconds(weak[0])
        for r in weak:
            n = r["ranks"] * r["threads"]
            r["efficiency"] = t1 / step_seconds(r)
            r["speedup"] = n * r["efficiency"]
            r["bound"] = s + (1 - s) * n  # Gustafson with s_profile
        print(f"\nweak scaling (points ~ cores, slice widened along {args.weak_axis}); "
              "bound = Gustafson with s_profile")
        table(weak, weak=True)
        result["weak"] = weak
    if args.plot:
        plot(result, s, args.plot)
    print(json.dumps(result, default=float))


def plot(result: dict, s: float, path: Path) -> None:
    """Measured (scaled) speedups against cores, with the ideal line and the Amdahl and
    Gustafson curves of s_profile up to 1024 cores (log axes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.logspace(0, 10, 200, base=2)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True)
    def amdahl(f):
        return 1 / (f + (1 - f) / n)

    def gustafson(f):
        return f + (1 - f) * n

    for a, key, law, label in [(ax[0], "strong", amdahl, "Amdahl"),
                               (ax[1], "weak", gustafson, "Gustafson")]:
        a.loglog(n, n, "k:", lw=1, label="ideal")
        a.loglog(n, law(s), "C0-", label=f"{label}, measured s = {s:.2g}")
        a.loglog(n, law(0.023), "C3--", label=f"{label}, seed's s = 0.023")
        for r in result.get(key, []):
            c = r["ranks"] * r["threads"]
            marker = "o" if r["threads"] == 1 else "s"
            a.loglog(c, r["speedup"], marker, color="C2" if r["threads"] == 1 else "C1",
                     ms=7, label=f"{r['ranks']} rank(s) x {r['threads']} thread(s)")
        a.set_xlabel("cores (ranks x threads)")
        a.set_ylabel("speedup" if key == "strong" else "scaled speedup")
        a.set_title(f"{key} scaling")
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(Path(result["case"]).name)
    fig.savefig(path, dpi=120)
    print(f"plot: {path}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()

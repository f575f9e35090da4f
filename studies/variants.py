"""Run variants of a case for a study, each once: the loop that the grid-convergence,
cross-scale and baseline studies share.

    import sys; sys.path.insert(0, "studies")
    from variants import run_variant
    case = gs.load_case("examples/column_collapse/mu_i.toml")
    case.grid.cell_size = [2.5e-3] * 3 ...
    wall_s = run_variant(case, Path("conv/mu_i_2.5"))   # runs into conv/mu_i_2.5/run

A variant whose run already reaches the case's time.end in OUT/run is not run again
(its wall time is read back), so a study can be extended or resumed by running it
again; OUT/case.toml records the variant's case (`grainscale run OUT/case.toml` reruns
it where the case has no relative paths).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import grainscale as gs


def finished(case: gs.Case, run: Path) -> bool:
    """Whether the run folder `run` holds a run of `case` that reached time.end."""
    if not (run / "history.csv").is_file():
        return False
    t = gs.open_result(run).history["time"]
    return len(t) > 0 and t[-1] >= case.time.end - 1e-9


def run_variant(case: gs.Case, out: Path) -> float:
    """Run `case` into out/run unless it finished there; the run's wall seconds.
    RunError (the run's simulation error) if it stops early."""
    out = Path(out)
    wall_file = out / "wall.json"
    if finished(case, out / "run") and wall_file.is_file():
        return float(json.loads(wall_file.read_text())["wall_s"])
    case = case.check()  # every edit validated before the folder is touched
    out.mkdir(parents=True, exist_ok=True)
    case.save(out / "case.toml")
    t0 = time.perf_counter()
    gs.run(case, out / "run", progress=False)
    wall = time.perf_counter() - t0
    wall_file.write_text(json.dumps({"wall_s": wall}))
    return wall

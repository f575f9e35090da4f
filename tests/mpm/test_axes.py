"""The same column collapse in rotated, shifted axes: the case keys that name axes and
positions (per-axis `cell_size`, `output.column` `flow_axis`, `up_axis`, `wall`, `base`,
faces, boxes, gravity) describe one physical problem whatever the frame, so the
history is the same to round-off."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import tomli_w

from grainscale.analysis import read_columns
from grainscale.cli import main

CASE = Path(__file__).resolve().parents[2] / "examples" / "column_collapse" / "mohr_coulomb.toml"
# original axis a (x flow, y width, z up) becomes axis PERM[a]: flow -> y, width -> z,
# up -> x; and the frame is shifted by SHIFT (new coordinates)
PERM = (1, 2, 0)
SHIFT = np.array([0.02, 0.03, -0.01])
AXES = "xyz"


def _vec(v, shift=True):
    out = np.zeros(3)
    for a in range(3):
        out[PERM[a]] = v[a]
    return (out + SHIFT if shift else out).tolist()


def _face(face: str) -> str:
    return AXES[PERM[AXES.index(face[0])]] + face[1]


def _cases(tmp: Path) -> tuple[Path, Path]:
    case = tomllib.loads(CASE.read_text())
    case["grid"]["cell_size"] = [0.005, 0.0075, 0.005]  # width cells coarser: 6 of them
    case["grid"]["cells"] = [60, 6, 14]
    case["time"].update(start=-0.003, end=0.006)
    case["output"].update(interval=0.001, frame_interval=0.006)
    case["output"]["history"] = ["time", "runout_ratio", "height_ratio", "kinetic_energy"]
    a = tmp / "a.toml"
    a.write_text(tomli_w.dumps(case))

    grid = case["grid"]
    size, cells = [0.0] * 3, [0] * 3
    for k in range(3):
        size[PERM[k]], cells[PERM[k]] = grid["cell_size"][k], grid["cells"][k]
    grid.update(origin=_vec(grid["origin"]), cell_size=size, cells=cells)
    case["solver"]["gravity"] = _vec(case["solver"]["gravity"], shift=False)
    for body in case["bodies"]:
        body.update(lo=_vec(body["lo"]), hi=_vec(body["hi"]))
    for bc in case["boundaries"]:
        if "face" in bc:
            bc["face"] = _face(bc["face"])
        if "box" in bc:
            bc["box"] = {"lo": _vec(bc["box"]["lo"]), "hi": _vec(bc["box"]["hi"])}
        if "normal" in bc:
            bc["normal"] = AXES[PERM[AXES.index(bc["normal"])]]
    col = case["output"]["column"]
    col.update(flow_axis=AXES[PERM[0]], up_axis=AXES[PERM[2]],
               wall=col["wall"] + SHIFT[PERM[0]], base=col["base"] + SHIFT[PERM[2]])
    b = tmp / "b.toml"
    b.write_text(tomli_w.dumps(case))
    return a, b


def test_a_rotated_shifted_frame_gives_the_same_collapse(tmp_path):
    """x (flow) -> y, y (width) -> z, z (up) -> x, shifted by (2, 3, -1) cm: geostatic
    stage and release (9 ms, ~150 steps), the runout, height and kinetic energy of
    every row agree within 1e-9 of their largest value (measured: 5e-13). A key
    read along the wrong axis (a flow_axis ignored, the per-axis cell sizes applied in
    the wrong order, the wall's offset dropped: the runout off by 0.3) changes them at
    order 1."""
    a, b = _cases(tmp_path)
    ha, hb = {}, {}
    for path, h in ((a, ha), (b, hb)):
        assert main(["run", str(path), "--out", str(tmp_path / path.stem), "--quiet"]) == 0
        h.update(read_columns(tmp_path / path.stem / "history.csv"))
    assert len(ha["time"]) == len(hb["time"]) >= 9
    assert ha["kinetic_energy"].max() > 0 and np.abs(ha["runout_ratio"]).max() > 0
    for key in ("time", "runout_ratio", "height_ratio", "kinetic_energy"):
        scale = np.abs(ha[key]).max()
        assert np.abs(ha[key] - hb[key]).max() <= 1e-9 * scale, key

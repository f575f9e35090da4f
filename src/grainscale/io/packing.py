"""Packing exchange text format (design.md), for moving packings between codes.

    # grainscale-packing v1
    h00 h01 h02 h10 h11 h12 h20 h21 h22      (cell matrix, row-major; columns = edges)
    x y z r                                  (one sphere a line, SI units)

Files from YADE (`export.text`, `ymport.text` layout "x y z r", '#' comments) are read
too when they carry the periodic cell in a comment line `# cell: h00 h01 ... h22`
(row-major), because the text layout itself has no cell.

Clumps (dem/clump.py) take a fifth column, the clump each sphere belongs to:

    x y z r k                                (members of clump k; k = 0, 1, ...)

a member at its place in the clump (not wrapped into the cell by itself), which is
what YADE's `O.bodies.appendClumped` takes (tests/data/triaxial_150/yade_triaxial.py
reads this layout). `write_packing(..., bodies=k)` writes it, `read_members` reads either
layout; a clump's mass properties are those of its members' union (clump.from_members).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from grainscale.config.base import ConfigError

if TYPE_CHECKING:
    from grainscale.dem.state import RVEBatch

HEADER = "# grainscale-packing v1"


def write_packing(path: str | Path, h: np.ndarray, centres: np.ndarray,
                  radii: np.ndarray, bodies: np.ndarray | None = None) -> None:
    """Write a packing atomically (a temporary file renamed into place); `bodies` (N,)
    the clump of each sphere (a fifth column), None for plain spheres."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as f:
        f.write(HEADER + "\n")
        f.write(" ".join(f"{v:.17g}" for v in np.asarray(h, float).ravel()) + "\n")
        for k, ((x, y, z), r) in enumerate(zip(centres, radii, strict=True)):
            tail = "" if bodies is None else f" {int(bodies[k])}"
            f.write(f"{x:.17g} {y:.17g} {z:.17g} {r:.17g}{tail}\n")
    os.replace(tmp, path)


def read_packing(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read (h, centres, radii) of spheres from the exchange format or a YADE text
    export; a file of clumps is refused (read it with `read_members`)."""
    h, centres, radii, bodies = read_members(path)
    if bodies is not None:
        raise ConfigError(f"{path}: a packing of clumps (a fifth column); this use takes "
                          "spheres")
    return h, centres, radii


def read_members(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                            np.ndarray | None]:
    """Read (h, centres, radii, bodies) from the exchange format: bodies (N,) int the
    clump of each sphere where the file has a fifth column, else None."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"packing file {str(path)!r} does not exist")
    lines = path.read_text().splitlines()
    h = None
    rows = []
    start = 0
    if lines and lines[0].strip() == HEADER:
        h = _numbers(lines[1], path, 2, 9).reshape(3, 3)
        start = 2
    for lineno, line in enumerate(lines[start:], start + 1):
        text = line.strip()
        if not text:
            continue
        if text.startswith("#"):
            body = text.lstrip("#").strip()
            if body.lower().startswith("cell:") and h is None:
                h = _numbers(body[5:], path, lineno, 9).reshape(3, 3)
            continue
        rows.append(_numbers(text, path, lineno, 5 if len(text.split()) == 5 else 4))
    if h is None:
        raise ConfigError(
            f"{path}: no periodic cell; start the file with '{HEADER}' and the 9 entries of "
            f"h, or add a comment line '# cell: h00 h01 ... h22' (row-major)")
    if not rows:
        raise ConfigError(f"{path}: no spheres")
    if len({len(r) for r in rows}) > 1:
        raise ConfigError(f"{path}: lines of 4 and of 5 numbers mixed; spheres have 4 (x y "
                          "z r), clump members 5 (x y z r clump)")
    data = np.array(rows)
    bodies = None
    if data.shape[1] == 5:
        bodies = data[:, 4].astype(np.int64)
        if np.any(bodies != data[:, 4]) or np.any(bodies < 0):
            raise ConfigError(f"{path}: the fifth column (clump) must hold integers >= 0")
    if np.any(data[:, 3] <= 0):
        bad = int(np.argmax(data[:, 3] <= 0))
        raise ConfigError(f"{path}: sphere {bad + 1} has radius {float(data[bad, 3])!r}; "
                          "must be > 0")
    if np.linalg.det(h) <= 0:
        raise ConfigError(f"{path}: cell matrix has det = {float(np.linalg.det(h)):.4g}; "
                          "must be > 0")
    return h, data[:, :3].copy(), data[:, 3].copy(), bodies


def _numbers(text: str, path: Path, lineno: int, count: int) -> np.ndarray:
    try:
        values = np.array([float(v) for v in text.split()])
    except ValueError:
        raise ConfigError(f"{path}:{lineno}: expected {count} numbers, got {text!r}") from None
    if values.size != count or not np.all(np.isfinite(values)):
        raise ConfigError(f"{path}:{lineno}: expected {count} finite numbers, got {text!r}")
    return values


def load_packing(path: Path, params) -> RVEBatch:  # noqa: F821 (dem.state, imported late)
    """A batch of one RVE from a .txt packing (at rest, grain density from params, an
    RVEParams) or a .h5 full state (io/rve_h5.py)."""
    from grainscale.dem.state import from_members, from_packing
    from grainscale.io.rve_h5 import read_rve_state

    if path.suffix == ".h5":
        batch, _ = read_rve_state(path)
        return fit_history(batch.take([0]), params, f"packing {str(path)!r}")
    h, centres, radii, bodies = read_members(path)
    if bodies is not None:
        return from_members(h, centres, radii, bodies, params.density)
    return from_packing(h, centres, radii, params.density)


def fit_history(batch, params, what: str):
    """`batch` with the contact-history width of the [rve] table `params` (an
    RVEParams; state.with_history: zero moments added where rolling resistance is on);
    a ConfigError naming `what` if it holds rolling moments that params switch off."""
    from grainscale.config.base import ConfigError
    from grainscale.dem.generate import contact_params
    from grainscale.dem.state import with_history

    try:
        return with_history(batch, contact_params(params).history)
    except ValueError:
        raise ConfigError(
            f"{what} holds rolling moments (it was made with rolling resistance) but [rve] "
            f"rolling_stiffness = {params.rolling_stiffness}; valid: the rolling_stiffness "
            "and rolling_friction it was made with, or a packing made without them"
        ) from None

"""history.csv: one row per output interval, named columns, a commented header.

The header states units and the sign convention. Rows are appended and flushed one at a
time, so a run that stops (or fails) keeps every row written so far intact; `sync` also
puts them on disk (fsync) before a checkpoint counts them, so a resume after a power loss
finds every row the checkpoint expects.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from grainscale.io import faults


class HistoryMismatch(ValueError):
    """history.csv holds fewer rows than the checkpoint a resume starts from expects."""

UNITS = {
    "step": "-", "time": "s", "dt": "s", "kinetic_energy": "J", "t_over_tc": "-",
    "runout_ratio": "-", "height_ratio": "-", "front": "m", "column_height": "m",
    "front_thick": "m", "runout_ratio_thick": "-",
    "rigid_fx": "N", "rigid_fy": "N", "rigid_fz": "N", "rigid_depth": "m", "depth": "m",
    "force": "N", "depth_over_R": "-", "force_normalized": "-",
    "p": "Pa", "q": "Pa", "q_over_p": "-", "axial_strain": "-", "volumetric_strain": "-",
    "porosity": "-", "coordination": "-", "mean_rotation": "rad",
}

CONVENTION = ("SI units. Stresses: tension positive internally; p = -tr(sigma)/3 and "
              "q = sqrt(3/2 s:s) are compression positive. rigid_f*: force of the "
              "material on the rigid body. rigid_depth: body displacement along its "
              "prescribed velocity (= depth); force: its resistance, -f . v/|v|; "
              "depth_over_R = d/R, force_normalized = p_u/(rho g R), p_u = force/S, S "
              "and R the body's section inside the grid and its (equivalent) radius, rho "
              "the material's initial bulk density. "
              "runout_ratio = (L - L_i)/L_i, height_ratio = H/H_i; *_thick: L where the "
              "deposit is at least min_thickness thick. p, q: of the "
              "volume-averaged stress; axial_strain = 1 - mean F_aa (compression "
              "positive); volumetric_strain = ln(V/V0) (positive = dilation).")


class History:
    """Append-only CSV writer. `resume_rows` keeps that many existing data rows."""

    def __init__(self, path: str | Path, columns: list[str], title: str = "",
                 resume_rows: int | None = None):
        self.path = Path(path)
        self.columns = list(columns)
        if resume_rows is None:
            head = [f"# grainscale history: {title}".rstrip(), f"# {CONVENTION}",
                    "# units: " + ", ".join(f"{c} [{UNITS.get(c, '-')}]" for c in columns),
                    ",".join(columns)]
            self.path.write_text("\n".join(head) + "\n")
            self.rows = 0
        else:
            self.truncate(resume_rows)
        self._f = open(self.path, "a")  # noqa: SIM115 (kept open for the run)

    def truncate(self, n_rows: int) -> None:
        """Keep the header and the first n_rows data rows (resume); HistoryMismatch,
        with the file untouched, if it holds fewer complete rows."""
        lines = self.path.read_text().splitlines(keepends=True)
        n_head = next(i for i, ln in enumerate(lines) if not ln.startswith("#")) + 1
        kept = lines[:n_head + n_rows]
        complete = sum(ln.endswith("\n") for ln in kept[n_head:])
        if complete < n_rows:
            raise HistoryMismatch(
                f"{self.path} holds {complete} complete data rows, but the checkpoint to "
                f"resume from was written after row {n_rows}: the file was replaced or cut "
                f"short; restore it, or start the run afresh without --resume")
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text("".join(kept))
        faults.point("history.truncate_tmp")
        tmp.replace(self.path)
        self.rows = len(kept) - n_head

    def write(self, values: dict[str, float]) -> None:
        row = []
        for c in self.columns:
            v = values[c]
            row.append(str(int(v)) if c == "step" else repr(float(v)))
        line = ",".join(row) + "\n"
        if faults.ARMED:  # tests (io/faults.py): a kill with half the row on disk
            self._f.write(line[:len(line) // 2])
            self._f.flush()
            faults.point("history.mid_row")
            line = line[len(line) // 2:]
        self._f.write(line)
        self._f.flush()
        self.rows += 1

    def sync(self) -> None:
        """Every row written so far on disk (flush and fsync)."""
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


def read_history(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a history.csv as History writes it ('#' comment lines, then a header
    row), or of any such CSV. A last row cut short (a run killed while writing) is
    dropped; any other bad row raises ValueError naming the file and the row."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    if not lines:
        raise ValueError(f"{path}: no header row")
    names = [c.strip() for c in lines[0].split(",")]
    rows = []
    for k, ln in enumerate(lines[1:]):
        fields = ln.split(",")
        try:
            if len(fields) != len(names):
                raise ValueError(f"{len(fields)} fields, header has {len(names)}")
            rows.append([float(v) for v in fields])
        except ValueError as err:
            if k == len(lines) - 2:
                break  # the last row, cut short
            raise ValueError(f"{path}: data row {k + 1}: {err}") from None
    data = np.array(rows, dtype=float).reshape(len(rows), len(names))
    return {n: data[:, i] for i, n in enumerate(names)}

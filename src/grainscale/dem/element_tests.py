"""Pure-DEM element tests on one RVE (or a batch): the stress paths of a periodic cell.

Each test advances the RVE under a mixed strain/stress control (engine.Control) and
records one row every `output_interval` of its strain measure. Rows are dicts of floats
in report conventions: p, q and the normal stresses compression positive; strains as
stated per column (see `COLUMN_DOC`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from grainscale.config.rve import (
    AXES,
    IsotropicTest,
    RVEParams,
    ShearTest,
    TriaxialTest,
    UndrainedTest,
)
from grainscale.dem import engine, homogenise, lattice
from grainscale.dem.generate import contact_params
from grainscale.dem.state import RVEBatch

COLUMN_DOC = (
    "units SI (Pa, s); stresses compression positive (geomechanics): p = -tr(sigma)/3, "
    "q = sqrt(3/2 s:s), sigma_xx.. = -(Cauchy normal stress); axial_strain = (L0 - L)/L0 "
    "(compression positive); volumetric_strain = ln(V/V0) (positive = dilation); "
    "shear_strain = gamma = integral of L_xz dt; coordination = 2 Nc/N; "
    "mean_rotation = mean of integral |omega| dt [rad]; unbalanced = mean |F_net| / mean "
    "|f_contact|")

Row = dict[str, float]


def state_row(batch: RVEBatch, r: int = 0, time: float = 0.0) -> Row:
    """One output row of RVE r: stresses in report convention plus microstructure."""
    s = homogenise.summary(batch)
    row = {"time": time}
    for key in ("p", "q", "q_over_p", "volumetric_strain", "porosity", "coordination"):
        row[key] = float(s[key][r])
    row["sigma_xx"] = -float(batch.stress[r, 0, 0])
    row["sigma_yy"] = -float(batch.stress[r, 1, 1])
    row["sigma_zz"] = -float(batch.stress[r, 2, 2])
    row["tau_xz"] = -float(0.5 * (batch.stress[r, 0, 2] + batch.stress[r, 2, 0]))
    row["mean_rotation"] = float(s["mean_rotation"][r])
    row["unbalanced"] = float(s["unbalanced"][r])
    return row


def _run(batch: RVEBatch, params: RVEParams, control: engine.Control, dt: float,
         steps_per_row: int, n_rows: int, extra: Callable[[RVEBatch, float, int], Row],
         on_row: Callable[[Row], None] | None, reduce: bool = False,
         every_rve: bool = False):
    """Rows of RVE 0 (or, with every_rve, a list of rows per RVE of the batch)."""
    cp = contact_params(params)
    engine.refresh(batch, cp)
    rves = range(batch.n_rve if every_rve else 1)

    def rows_now(t: float) -> list[Row]:
        return [{**extra(batch, t, r), **state_row(batch, r, t)} for r in rves]

    table = [rows_now(0.0)]
    if on_row:
        on_row(table[-1][0])
    for k in range(1, n_rows + 1):
        engine.advance(batch, steps_per_row, dt, cp, control)
        if reduce:  # a sheared cell is re-expressed by a compact basis (dem/lattice.py)
            lattice.reduce_cells(batch)
        table.append(rows_now(k * steps_per_row * dt))
        if on_row:
            on_row(table[-1][0])
    per_rve = [[row[r] for row in table] for r in rves]
    return per_rve if every_rve else per_rve[0]


def timestep(batch: RVEBatch, params: RVEParams) -> float:
    return engine.critical_dt(batch, contact_params(params), params.numerics.timestep_safety)


def triaxial(batch: RVEBatch, params: RVEParams, test: TriaxialTest,
             on_row: Callable[[Row], None] | None = None, every_rve: bool = False):
    """Drained triaxial compression: the axial cell edge shortens at a constant
    engineering rate, h_aa(t) = h_aa(0) (1 - rate t), or at a constant true rate,
    h_aa(t) = h_aa(0) exp(-rate t); the two lateral normal stresses are servo-held at
    -confining_pressure; the cell stays rectangular."""
    a = AXES[test.axis]
    dt = timestep(batch, params)
    lateral = {k: -test.confining_pressure for k in range(3) if k != a}
    ctrl = engine.rate_control(batch.n_rve, servo=lateral, max_rate=10 * test.strain_rate,
                               gain=params.numerics.servo_gain)
    if test.rate == "true":
        ctrl.l_ctrl[:, a, a] = -test.strain_rate
        total = -math.log(1.0 - test.axial_strain)  # time x rate to reach the strain
    else:
        ctrl.hdot_fixed[:, a, :] = -test.strain_rate * batch.h[:, a, :]
        total = test.axial_strain
    l0 = batch.h[:, a, a].copy()
    steps = max(1, round(test.output_interval / (test.strain_rate * dt)))
    n_rows = math.ceil(total / (steps * test.strain_rate * dt) - 1e-9)

    def extra(b: RVEBatch, t: float, r: int) -> Row:
        return {"axial_strain": float((l0[r] - b.h[r, a, a]) / l0[r])}

    return _run(batch, params, ctrl, dt, steps, n_rows, extra, on_row, every_rve=every_rve)


def undrained(batch: RVEBatch, params: RVEParams, test: UndrainedTest,
              on_row: Callable[[Row], None] | None = None) -> list[Row]:
    """Constant-volume triaxial: L_aa = -rate, lateral L = rate/2 (trace zero)."""
    a = AXES[test.axis]
    dt = timestep(batch, params)
    lc = np.eye(3) * (0.5 * test.strain_rate)
    lc[a, a] = -test.strain_rate
    ctrl = engine.rate_control(batch.n_rve, l_ctrl=lc)
    l0 = batch.h[:, a, a].copy()
    steps = max(1, round(test.output_interval / (test.strain_rate * dt)))
    total_log = -math.log(1.0 - test.axial_strain)  # true strain needed
    n_rows = math.ceil(total_log / (steps * test.strain_rate * dt) - 1e-9)

    def extra(b: RVEBatch, t: float, r: int) -> Row:
        return {"axial_strain": float((l0[r] - b.h[r, a, a]) / l0[r])}

    return _run(batch, params, ctrl, dt, steps, n_rows, extra, on_row)


def isotropic(batch: RVEBatch, params: RVEParams, test: IsotropicTest,
              on_row: Callable[[Row], None] | None = None) -> list[Row]:
    """Isotropic compression: all normal stresses servoed to -pressure_final at a strain
    rate limited to strain_rate, until static (rows every output_interval of eps_v)."""
    dt = timestep(batch, params)
    p = test.pressure_final
    ctrl = engine.rate_control(batch.n_rve, servo={0: -p, 1: -p, 2: -p},
                               max_rate=test.strain_rate, gain=params.numerics.servo_gain)
    steps = max(1, round(test.output_interval / (3 * test.strain_rate * dt)))
    cp = contact_params(params)
    engine.refresh(batch, cp)
    rows = [state_row(batch, 0, 0.0)]
    if on_row:
        on_row(rows[-1])
    k = 0
    while True:
        engine.advance(batch, steps, dt, cp, ctrl)
        k += 1
        rows.append(state_row(batch, 0, k * steps * dt))
        if on_row:
            on_row(rows[-1])
        if abs(rows[-1]["p"] / p - 1.0) < 0.01 and rows[-1]["unbalanced"] < 0.01:
            return rows
        if k > 100_000:
            raise RuntimeError("isotropic compression did not reach a static state")


def shear_schedule(test: ShearTest, dt: float) -> tuple[int, int]:
    """(DEM steps per output row, rows) of a simple-shear test at time step dt: whole
    steps per output_interval of strain, enough rows to reach shear_strain."""
    steps = max(1, round(test.output_interval / (test.strain_rate * dt)))
    return steps, math.ceil(test.shear_strain / (steps * test.strain_rate * dt) - 1e-9)


def simple_shear(batch: RVEBatch, params: RVEParams, test: ShearTest,
                 on_row: Callable[[Row], None] | None = None) -> list[Row]:
    """Simple shear in the x-z plane: L_xz = rate (v_x = rate z), sigma_zz servo-held at
    -normal_stress, no strain in x and y. gamma = rate x time; the cell is re-expressed
    by a compact basis whenever shear makes it thin, so gamma is not limited."""
    dt = timestep(batch, params)
    lc = np.zeros((3, 3))
    lc[0, 2] = test.strain_rate
    ctrl = engine.rate_control(batch.n_rve, l_ctrl=lc, servo={2: -test.normal_stress},
                               max_rate=10 * test.strain_rate,
                               gain=params.numerics.servo_gain)
    steps, n_rows = shear_schedule(test, dt)

    def extra(b: RVEBatch, t: float, r: int) -> Row:
        return {"shear_strain": test.strain_rate * t}

    return _run(batch, params, ctrl, dt, steps, n_rows, extra, on_row, reduce=True)

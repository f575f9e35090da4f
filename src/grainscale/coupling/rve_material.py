"""The DEM RVE as an MPM material: one periodic assembly per material point (seed §2).

Each MPM step hands every point's full incremental displacement gradient dH (spin
included, seed Eq. 17) to its RVE: the cell is deformed h <- (I + dH) h over a whole
number of DEM steps, and the homogenised Love-Weber stress (seed Eq. 11) goes back to
the point. The RVEs of all points are one batch, stepped in parallel over RVEs.

Time integration (docs/coupling.md):
- "dynamic" (default): the RVE lives in real time. The MPM step dt is split into
  n = max(min_substeps, ceil(dt / dt_crit)) equal DEM steps, dt_DEM = dt / n <= dt_crit
  = safety sqrt(m_min/k_max), so the strain rate the grains see is the MPM's.
- "quasi_static": the increment is applied over n = ceil(max|dH| / strain_per_substep)
  DEM steps of dt_crit, independent of the MPM dt (as FEMxDEM codes do): the RVE is
  loaded at a fixed, slow strain per DEM step, whatever the macroscopic rate.
After each increment, cells sheared thin are re-expressed by a compact basis
(dem/lattice.py), so strongly deformed RVEs keep their history instead of being reset.
"""

from __future__ import annotations

import math
import time

import numpy as np

from grainscale.config.rve import RVEParams
from grainscale.dem import engine, homogenise, lattice
from grainscale.dem.generate import contact_params
from grainscale.dem.state import (
    STATE_FIELDS,
    RVEBatch,
    concatenate,
    from_state_arrays,
    state_arrays,
)
from grainscale.mpm.step import SimulationError


def bulk_density(library: list[RVEBatch]) -> float:
    """Mean grain mass per cell volume of the packings [kg/m^3]."""
    return float(np.mean([b.mass[0].sum() / b.volume()[0] for b in library]))


class RVEMaterial:
    """Batched RVE material with the MPM material interface (mpm/materials/base.py)."""

    def __init__(self, name: str, params: RVEParams, library: list[RVEBatch], n_points: int,
                 assignment_seed: int = 0, mode: str = "dynamic", min_substeps: int = 1,
                 strain_per_substep: float = 1e-5, local: np.ndarray | None = None):
        """n_points: points of this material over all ranks; local: the indices (into
        them) of the points this process holds (default: all). The packing of each point
        is drawn for all points with the seed, so it does not depend on the ranks."""
        if mode not in ("dynamic", "quasi_static"):
            raise ValueError(f"mode = {mode!r}: must be 'dynamic' or 'quasi_static'")
        self.name = name
        self.params = params
        self.mode = mode
        self.min_substeps = int(min_substeps)
        self.strain_per_substep = float(strain_per_substep)
        self.cp = contact_params(params)
        rng = np.random.default_rng(assignment_seed)
        self.assignment = rng.integers(len(library), size=n_points)
        self.local = local  # for error messages: the material's point numbers
        if local is not None:
            self.assignment = self.assignment[local]
            n_points = len(local)
        self.batch = concatenate([library[k] for k in self.assignment]) if n_points else None
        self._none = library[0].take(np.zeros(0, np.int64))  # the shape of "no RVE"
        self.density = bulk_density(library)
        self.dt_crit = min(engine.critical_dt(b, self.cp, params.numerics.timestep_safety)
                           for b in library)
        self.theta_prev = np.zeros(n_points)
        self.spin_rate = np.zeros(n_points)
        self.substeps = 0  # DEM steps of the last update (largest over RVEs)
        self.seconds = 0.0  # wall time spent in DEM updates
        self.rve_steps = 0  # sum over RVEs of DEM steps taken
        # per RVE, particle-steps plus contact-steps since the last rebalancing: the
        # measured work that decides the load balance over ranks
        self.work = np.zeros(n_points)
        if self.batch is not None:
            engine.refresh(self.batch, self.cp)
            self.theta_prev = homogenise.mean_rotation(self.batch)

    # ------------------------------------------------------------------ interface
    def update(self, dH: np.ndarray, dt: float, stress: np.ndarray) -> None:
        """Deform each RVE by its dH over the step dt [s]; stress <- Love-Weber sigma."""
        if self.batch is None:
            return
        t0 = time.perf_counter()
        n_rve = self.batch.n_rve
        if self.mode == "dynamic":
            n = max(self.min_substeps, math.ceil(dt / self.dt_crit - 1e-9))
            nsteps = np.full(n_rve, n, np.int64)
            dt_dem = dt / n
        else:
            size = np.abs(dH).max(axis=(1, 2))
            nsteps = np.maximum(self.min_substeps,
                                np.ceil(size / self.strain_per_substep)).astype(np.int64)
            dt_dem = self.dt_crit
        ctrl = engine.increment_control(self.batch, dH, nsteps, dt_dem)
        try:
            engine.advance(self.batch, nsteps, dt_dem, self.cp, ctrl)
        except engine.RVEError as err:
            point = err.rve if self.local is None else int(self.local[err.rve])
            raise SimulationError(
                f"material {self.name!r}, its point {point}: {err} (the run stops; "
                "history and checkpoints so far are intact)") from None
        lattice.reduce_cells(self.batch)
        stress[:] = self.batch.stress
        theta = homogenise.mean_rotation(self.batch)
        self.spin_rate = (theta - self.theta_prev) / dt
        self.theta_prev = theta
        self.substeps = int(nsteps.max())
        self.rve_steps += int(nsteps.sum())
        self.work += nsteps * (self.batch.n_particles + self.batch.ncontact)
        self.seconds += time.perf_counter() - t0

    def initial_stress(self) -> np.ndarray:
        """(P,3,3) Love-Weber stress of the prepared RVEs [Pa]."""
        return self.batch.stress.copy()

    def wave_speed(self) -> float:
        """Largest P-wave speed of the RVEs, sqrt(max_k C_kk / rho) of each [m/s].

        max_k C_kk of an RVE (its affine stiffness, an upper bound of its constrained
        modulus) over its own bulk density: conservative, so the CFL step is safe, and a
        maximum over RVEs, so it does not depend on how RVEs are split over ranks.
        """
        if self.batch is None:
            return 0.0
        c = np.diagonal(self.batch.stiffness, axis1=1, axis2=2).max(axis=1)
        rho = self.batch.mass.sum(axis=1) / self.batch.volume()
        return float(np.sqrt(c / rho).max())

    def state(self) -> dict[str, np.ndarray]:
        out = {f"rve_{k}": v for k, v in self._arrays().items()}
        out["theta_prev"] = self.theta_prev
        out["spin_rate"] = self.spin_rate
        out["assignment"] = self.assignment
        out["work"] = self.work
        return out

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        batch = from_state_arrays({k: np.asarray(state[f"rve_{k}"]) for k in STATE_FIELDS})
        self.batch = batch if batch.n_rve else None
        self.theta_prev = np.asarray(state["theta_prev"], float).copy()
        self.assignment = np.asarray(state["assignment"]).copy()
        n = len(self.theta_prev)
        self.spin_rate = np.asarray(state.get("spin_rate", np.zeros(n)), float).copy()
        self.work = np.asarray(state.get("work", np.zeros(n)), float).copy()
        # no refresh here: re-evaluating contacts would re-project the tangential history
        # at the saved positions, and a resumed run must continue bitwise

    def point_fields(self) -> dict[str, np.ndarray]:
        """Per-point RVE quantities for VTK frames and history: porosity, coordination,
        mean accumulated rotation [rad] and its rate [rad/s] (seed Eq. 15, Fig. 15)."""
        if self.batch is None:
            return {}
        return {
            "porosity": self.batch.porosity(),
            "coordination": homogenise.coordination(self.batch),
            "mean_rotation": homogenise.mean_rotation(self.batch),
            "rotation_rate": self.spin_rate,
            "rve_eps_v": homogenise.volumetric_strain(self.batch),
        }

    @staticmethod
    def merge_states(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """One state from the states of several sets of points (checkpoint parts written
        by different ranks), in order; neighbour-list capacities may differ."""
        batches = [from_state_arrays({k: p[f"rve_{k}"] for k in STATE_FIELDS})
                   for p in parts]
        batches = [b for b in batches if b.n_rve] or batches[:1]
        out = {f"rve_{k}": v for k, v in state_arrays(concatenate(batches)).items()}
        for key in ("theta_prev", "spin_rate", "assignment", "work"):
            if all(key in p for p in parts):
                out[key] = np.concatenate([p[key] for p in parts])
        return out

    def _arrays(self) -> dict[str, np.ndarray]:
        return state_arrays(self.batch if self.batch is not None else self._none)

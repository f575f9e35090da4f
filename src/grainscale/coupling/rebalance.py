"""Measured-cost load balancing: points (and their RVEs) move to the ranks that
equalise the work, every `solver.rebalance_every` steps.

The random assignment balances the number of points per rank, not their cost. RVE cost
is uneven when RVEs differ in contacts or, in quasi-static time integration, in the DEM
steps an increment takes (a shear band costs many times a resting region). Each RVE
counts the particle-steps plus contact-steps it did since the last rebalancing (its
measured work); points of other materials count the MPM work of a point-step, worth
about `MPM_POINT_WORK` particle-steps. Every rank gathers all costs and computes the same
new ownership with a greedy longest-processing-time assignment; the rows that change
owner travel in the checkpoint-part format, and every rank rebuilds its state for its
new points. Results do not depend on ownership, so rebalancing never changes them.
"""

from __future__ import annotations

import numpy as np

from grainscale.coupling.checkpoints import load_rows, rank_state, rows_of
from grainscale.coupling.rve_material import RVEMaterial
from grainscale.mpm.setup import build_state
from grainscale.mpm.step import MPMState

MPM_POINT_WORK = 10.0  # particle-steps (~100 ns each) that one MPM point-step costs (~1 us)


def point_costs(s: MPMState, steps: int) -> np.ndarray:
    """Work of each of this rank's points over the last `steps` steps [particle-steps]."""
    cost = np.full(s.points.n, MPM_POINT_WORK * steps)
    for m, ids in zip(s.materials, s.mat_points, strict=True):
        if isinstance(m, RVEMaterial) and m.n_rve:
            cost[slice(None) if ids is None else ids] += m.work
    return cost


def lpt_owners(cost: np.ndarray, n_ranks: int) -> np.ndarray:
    """Greedy longest-processing-time assignment: the costliest point first, each to the
    least-loaded rank (lowest rank on ties); deterministic, within 4/3 of optimal."""
    owners = np.empty(len(cost), dtype=np.int64)
    load = np.zeros(n_ranks)
    for p in np.argsort(-cost, kind="stable"):
        r = int(np.argmin(load))
        owners[p] = r
        load[r] += cost[p]
    return owners


def imbalance(cost: np.ndarray, owners: np.ndarray, n_ranks: int) -> float:
    """Largest rank load over the mean rank load (1 = perfect)."""
    load = np.bincount(owners, weights=cost, minlength=n_ranks)
    return float(load.max() / load.mean()) if load.mean() > 0 else 1.0


def rebalance(s: MPMState, case, case_dir, factory, steps: int) -> tuple[MPMState, dict]:
    """The state rebuilt on the ownership that balances the work measured over the last
    `steps` steps, and a report {before, after} of the imbalance. Collective."""
    comm = s.comm
    parts = comm.mpi.allgather((s.point_ids, point_costs(s, steps)))
    cost = np.zeros(s.n_global)
    old = np.zeros(s.n_global, dtype=np.int64)
    for r, (ids, c) in enumerate(parts):
        cost[ids] = c
        old[ids] = r
    owners = lpt_owners(cost, comm.size)
    report = {"before": imbalance(cost, old, comm.size),
              "after": imbalance(cost, owners, comm.size)}
    mine = rank_state(s)
    outgoing = []
    for r in range(comm.size):  # the rows each rank will own, from this rank
        keep = np.flatnonzero(owners == r)
        outgoing.append({g: _select(group, keep) for g, group in mine.items()})
    incoming = comm.mpi.alltoall(outgoing)
    new = build_state(case, case_dir, n_threads=s.n_threads, material_factory=factory,
                      comm=comm, owners=owners)
    if not comm.any(not load_rows(new, incoming)):
        for a, b in zip(s.materials, new.materials, strict=True):
            # the cost report's sums
            for counter in ("seconds", "rve_steps", "rve_updates", "particle_steps"):
                if hasattr(a, counter):
                    setattr(b, counter, getattr(a, counter))
            if isinstance(b, RVEMaterial):
                b.work[:] = 0.0
        new.rigid = s.rigid
        new.time, new.step, new.vmax, new.last_dt = s.time, s.step, s.vmax, s.last_dt
        return new, report
    raise RuntimeError("rebalancing lost points")  # a bug: aborts the job


def _select(group: dict[str, np.ndarray], wanted: np.ndarray) -> dict[str, np.ndarray]:
    """The rows of a rank_state() group whose global ids are in `wanted`, still tagged."""
    ids, arrays = rows_of(group, wanted)
    return {**arrays, "global_id": ids}

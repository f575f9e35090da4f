"""Which rank owns which material point (and so its RVE): seeded random assignment.

As in the seed (§3, "the numbering of RVEs is randomised"), points are dealt to ranks in
a random order so that every rank gets a spatially mixed share: expensive regions (a
shear band, a stagnant zone with many contacts) are spread over all ranks, and the
counts differ by at most one. The permutation depends only on the seed and the number of
points, so every rank computes the same ownership without communicating.
"""

from __future__ import annotations

import numpy as np


def owners(n_points: int, n_ranks: int, seed: int = 0) -> np.ndarray:
    """(n_points,) int64 rank of each point: a seeded permutation cut into n_ranks blocks
    of sizes differing by at most one."""
    order = np.random.default_rng(seed).permutation(n_points)
    rank = np.empty(n_points, dtype=np.int64)
    bounds = np.linspace(0, n_points, n_ranks + 1).round().astype(np.int64)
    for r in range(n_ranks):
        rank[order[bounds[r]:bounds[r + 1]]] = r
    return rank


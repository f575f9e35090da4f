"""The load-balancing assignment (coupling/rebalance.py), checked against bounds."""

import numpy as np

from grainscale.coupling.rebalance import imbalance, lpt_owners
from grainscale.distributed.partition import owners as random_owners


def test_lpt_balances_uneven_costs():
    """Costs spread like RVEs in and out of a shear band (lognormal, a factor ~100):
    the greedy assignment is within Graham's 4/3 - 1/(3m) of the optimum, and the
    optimum is at least max(mean load, largest single cost)."""
    rng = np.random.default_rng(3)
    cost = rng.lognormal(0.0, 1.5, size=2000)
    for ranks in (2, 3, 8, 64):
        owners = lpt_owners(cost, ranks)
        assert np.bincount(owners, minlength=ranks).min() > 0
        lower = max(cost.sum() / ranks, cost.max())  # no assignment does better
        load = np.bincount(owners, weights=cost, minlength=ranks)
        assert load.max() <= (4 / 3 - 1 / (3 * ranks)) * lower * (1 + 1e-12)
        # and better than the seeded random deal of the same points
        assert imbalance(cost, owners, ranks) <= imbalance(cost, random_owners(
            len(cost), ranks, 0), ranks)


def test_lpt_is_deterministic_and_handles_ties():
    cost = np.ones(10)  # all equal: round robin from rank 0, same on every call
    a = lpt_owners(cost, 3)
    assert np.array_equal(a, lpt_owners(cost.copy(), 3))
    assert np.array_equal(np.bincount(a), [4, 3, 3])
    assert imbalance(cost, a, 3) == 4 / (10 / 3)

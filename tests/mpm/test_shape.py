"""Shape functions: partition of unity and sum(grad S) = 0 at random points, near edges too."""

import numpy as np
import pytest

from grainscale.mpm.grid import Grid
from grainscale.mpm.shape import GIMP, LINEAR, evaluate


def _full(base, w, dw, ns):
    """Tensor-product weights and gradients, (P, ns^3) and (P, ns^3, 3)."""
    wx, wy, wz = w[:, 0, :ns], w[:, 1, :ns], w[:, 2, :ns]
    gx, gy, gz = dw[:, 0, :ns], dw[:, 1, :ns], dw[:, 2, :ns]
    S = np.einsum("pi,pj,pk->pijk", wx, wy, wz).reshape(len(w), -1)
    G = np.stack([np.einsum("pi,pj,pk->pijk", gx, wy, wz),
                  np.einsum("pi,pj,pk->pijk", wx, gy, wz),
                  np.einsum("pi,pj,pk->pijk", wx, wy, gz)], axis=-1).reshape(len(w), -1, 3)
    return S, G


@pytest.mark.parametrize("kind,ns", [(GIMP, 3), (LINEAR, 2)])
def test_partition_of_unity_and_zero_gradient_sum(kind, ns):
    rng = np.random.default_rng(1)
    grid = Grid.make([-1.0, 0.0, 2.0], [0.1, 0.2, 0.05], [7, 5, 9])
    # interior points, plus points hugging every face (inside the grid, support crossing it)
    x = grid.origin + rng.random((400, 3)) * (grid.upper - grid.origin)
    edge = x[:60].copy()
    edge[:30, 0] = grid.origin[0] + rng.random(30) * 0.02
    edge[30:, 2] = grid.upper[2] - rng.random(30) * 0.01
    x = np.ascontiguousarray(np.vstack([x, edge]))
    lp = np.full(len(x), 0.25 * grid.cell_size.min())
    base, w, dw = evaluate(x, lp, grid, kind)
    S, G = _full(base, w, dw, ns)
    # exact identities up to round-off of a few flops
    np.testing.assert_allclose(S.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(G.sum(axis=1), 0.0, atol=1e-9)
    assert np.all(S >= -1e-15)
    assert np.all(base >= 0) and np.all(base + ns - 1 <= grid.cells)


@pytest.mark.parametrize("kind,ns", [(GIMP, 3), (LINEAR, 2)])
def test_linear_field_reproduced_away_from_edges(kind, ns):
    """sum_I S_Ip x_I = x_p and sum_I grad S_Ip x_I = I (linear completeness)."""
    rng = np.random.default_rng(2)
    grid = Grid.make([0.0, 0.0, 0.0], 0.1, [8, 8, 8])
    x = np.ascontiguousarray(0.2 + rng.random((200, 3)) * 0.4)
    lp = np.full(len(x), 0.025)
    base, w, dw = evaluate(x, lp, grid, kind)
    S, G = _full(base, w, dw, ns)
    k = np.arange(ns)
    xi = grid.origin[0] + (base[:, 0, None] + k) * 0.1
    yi = grid.origin[1] + (base[:, 1, None] + k) * 0.1
    zi = grid.origin[2] + (base[:, 2, None] + k) * 0.1
    XI = np.stack(np.broadcast_arrays(xi[:, :, None, None], yi[:, None, :, None],
                                      zi[:, None, None, :]), axis=-1).reshape(len(x), -1, 3)
    np.testing.assert_allclose(np.einsum("pn,pna->pa", S, XI), x, atol=1e-12)
    np.testing.assert_allclose(np.einsum("pnb,pna->pab", G, XI),
                               np.broadcast_to(np.eye(3), (len(x), 3, 3)), atol=1e-9)

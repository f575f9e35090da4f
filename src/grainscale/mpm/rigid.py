"""A rigid body made of material points, moving with a prescribed velocity history.

Velocity: zero before `start_time`, a linear ramp to `velocity` over `ramp_time`, then
constant. Every step the body marks the grid nodes it covers (nodes inside or on the
surface of its points' domains, |x_I - x_p| <= l_p per axis) and imposes its velocity
there, on top of the ordinary boundary conditions. The force it needs to do so is its
reaction: at a covered node with material mass m_I, momentum p_I and force f_I, the body
supplies F_I = (m_I v_body - p_I)/dt - f_I; the force of the material on the body is
-sum F_I.

Marking every node within the shape functions' support instead would reach a cell
beyond the surface and stiffen the contact (a test caught a 33 % excess). The contact
surface therefore advances node plane by node plane: the reaction of a moving body has a
ripple with the period of one cell in depth.
The body has no mass on the grid (its own inertia is irrelevant to a prescribed motion).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from grainscale.mpm.grid import Grid
from grainscale.mpm.transfer import mark_covered_nodes_kernel


@dataclass
class RigidBody:
    x: np.ndarray  # (R,3) m, positions of the body's points
    lp: np.ndarray  # (R,) m, GIMP half-widths
    velocity: np.ndarray  # (3,) m/s, final velocity
    ramp_time: float = 0.0  # s
    start_time: float = 0.0  # s
    displacement: np.ndarray = field(default_factory=lambda: np.zeros(3))  # m
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))  # N, material on body

    def velocity_at(self, t: float) -> np.ndarray:
        if t <= self.start_time:
            return np.zeros(3)
        if self.ramp_time > 0.0 and t < self.start_time + self.ramp_time:
            return self.velocity * ((t - self.start_time) / self.ramp_time)
        return self.velocity.copy()

    def covered_nodes(self, grid: Grid) -> np.ndarray:
        """Ids of the nodes the body covers at its current position."""
        mark = np.zeros(grid.n_nodes, dtype=np.bool_)
        mark_covered_nodes_kernel(self.x, self.lp, grid.origin, grid.cell_size, grid.cells,
                                  mark)
        return np.flatnonzero(mark)

    def advance(self, t: float, dt: float) -> None:
        """Move the body from t to t + dt (midpoint velocity: exact for the ramp)."""
        d = dt * self.velocity_at(t + 0.5 * dt)
        self.x += d
        self.displacement += d

"""Orientation of rigid grains (clumps): unit quaternions and the rotational leapfrog.

A quaternion q = (q0, q1, q2, q3), |q| = 1, turns the body frame into the lab frame:
x_lab = R(q) x_body. A grain carries its lab angular momentum L [kg m^2/s] at half steps
and its principal moments J (3,) [kg m^2]; its angular velocity is
omega = R diag(1/J) R^T L. One step of dt under the torque T [N m] (`advance`; Omelyan
1998's implicit midpoint, as YADE's NewtonIntegrator with exactAsphericalRot):

1. L_n = L_(n-1/2) + T dt/2, omega_n from L_n and q_n;
   L_(n+1/2) = L_(n-1/2) + T dt;
2. q_(n+1/2) = exp(omega_n dt/4) q_n (a turn by |omega_n| dt/2 about omega_n);
3. omega_(n+1/2) from L_(n+1/2) and q_(n+1/2); q_(n+1) = exp(omega_(n+1/2) dt/2) q_n.

Second order and, torque-free, L exactly constant; the kinetic energy (1/2) L . omega
oscillates by O(dt^2) without drift (tests/dem/test_clump.py). For a sphere (J equal)
omega = L/J and step 3 is the spheres' rotation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def matrix(q, out):
    """out = R(q) (3,3), the rotation of the unit quaternion q."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    out[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[0, 1] = 2.0 * (x * y - w * z)
    out[0, 2] = 2.0 * (x * z + w * y)
    out[1, 0] = 2.0 * (x * y + w * z)
    out[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[1, 2] = 2.0 * (y * z - w * x)
    out[2, 0] = 2.0 * (x * z - w * y)
    out[2, 1] = 2.0 * (y * z + w * x)
    out[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True, inline="always")
def turned(q, a0, a1, a2, out):
    """out = exp((a/2) n) q for the rotation vector a = angle n [rad] (lab frame): q
    followed by a turn of |a| about a, normalised against round-off."""
    ang = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if ang > 0.0:
        s = math.sin(0.5 * ang) / ang
        c = math.cos(0.5 * ang)
    else:
        s = 0.5
        c = 1.0
    p0, p1, p2 = s * a0, s * a1, s * a2
    w = c * q[0] - p0 * q[1] - p1 * q[2] - p2 * q[3]
    x = c * q[1] + p0 * q[0] + p1 * q[3] - p2 * q[2]
    y = c * q[2] - p0 * q[3] + p1 * q[0] + p2 * q[1]
    z = c * q[3] + p0 * q[2] - p1 * q[1] + p2 * q[0]
    norm = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    out[0] = w * norm
    out[1] = x * norm
    out[2] = y * norm
    out[3] = z * norm


@njit(cache=True, inline="always")
def angular_velocity(q, L, J, rot, out):
    """out = R diag(1/J) R^T L [rad/s], the lab angular velocity of a grain at
    orientation q with lab angular momentum L and principal moments J; rot (3,3)
    scratch (left holding R(q))."""
    matrix(q, rot)
    for a in range(3):
        body = (rot[0, a] * L[0] + rot[1, a] * L[1] + rot[2, a] * L[2]) / J[a]
        if a == 0:
            out[0] = rot[0, 0] * body
            out[1] = rot[1, 0] * body
            out[2] = rot[2, 0] * body
        else:
            out[0] += rot[0, a] * body
            out[1] += rot[1, a] * body
            out[2] += rot[2, a] * body


@njit(cache=True, inline="always")
def step(q, L, J, T0, T1, T2, dt, omega, rot, ln, half, new, W0=0.0, W1=0.0, W2=0.0):
    """One rotational leapfrog step (module docstring) in place: q (4,) from t_n to
    t_(n+1), L (3,) from t_(n-1/2) to t_(n+1/2) under the torque T [N m]; omega (3,)
    receives omega_(n+1/2) [rad/s]. rot (3,3), ln (3,), half (4,), new (4,) scratch.
    W (rad/s, default 0): a spin the orientation turns with besides omega (the mean
    field's, when L is the angular momentum of the spin about it: dem/rigid.py)."""
    ln[0] = L[0] + 0.5 * dt * T0
    ln[1] = L[1] + 0.5 * dt * T1
    ln[2] = L[2] + 0.5 * dt * T2
    L[0] += dt * T0
    L[1] += dt * T1
    L[2] += dt * T2
    angular_velocity(q, ln, J, rot, omega)
    turned(q, 0.5 * dt * (omega[0] + W0), 0.5 * dt * (omega[1] + W1),
           0.5 * dt * (omega[2] + W2), half)
    angular_velocity(half, L, J, rot, omega)
    turned(q, dt * (omega[0] + W0), dt * (omega[1] + W1), dt * (omega[2] + W2), new)
    for a in range(4):
        q[a] = new[a]


@njit(cache=True)
def advance(q, L, J, T, dt, omega):
    """`step` with its scratch allocated and the torque as an array T (3,)."""
    step(q, L, J, T[0], T[1], T[2], dt, omega, np.empty((3, 3)), np.empty(3),
         np.empty(4), np.empty(4))

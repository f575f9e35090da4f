"""Constants of the Hertz-Mindlin contact law (`[rve] contact_law = "hertz_mindlin"`).

Two elastic spheres of one material (Young's modulus E [Pa], Poisson's ratio nu) pressed
together by an overlap delta [m] (Johnson, Contact Mechanics, 1985, §4.2 and §7.2):

- reduced radius R* = r_i r_j / (r_i + r_j) [m], contact radius a = sqrt(R* delta) [m];
- normal force f_n = (4/3) E* sqrt(R*) delta^(3/2) = (2/3) k_n delta [N], with
  E* = E / (2 (1 - nu^2)) and the tangent normal stiffness k_n = 2 E* a [N/m];
- tangential stiffness k_t = 8 G* a [N/m] (Mindlin 1949, no micro-slip), with
  G* = G / (2 (2 - nu)), G = E / (2 (1 + nu)); so k_t / k_n = 2 (1 - nu) / (2 - nu) <= 1.

These are YADE's `Ip2_FrictMat_FrictMat_MindlinPhys` constants (kno = (4/3) E* sqrt(R*),
kso = 8 sqrt(R*) G*) for one material. The kernels evaluate k_n = HERTZ_KN a with
HERTZ_KN = 2 E* and k_t = (k_t / k_n) k_n.

Dashpot (only where a restitution e < 1 is given): c_n = 2 beta sqrt(m* k_n) on the
normal relative velocity, Tsuji et al. (1992)'s form, beta = TSUJI gamma with gamma =
-ln e / sqrt(pi^2 + ln^2 e) the linear dashpot's ratio (engine.ContactParams.gamma):
with k_n ~ delta^(1/2) a binary collision restitutes the same e at every impact speed.
"""

from __future__ import annotations

import math

HERTZ_TIME = 2.94328  # 2 int_0^1 dx / sqrt(1 - x^(5/2)): t_c = HERTZ_TIME delta_max / v0
# Tsuji et al. (1992): the Hertzian dashpot's ratio is sqrt(5/6) times the linear one's
# for the same restitution; integrating the collision itself gives e to 3e-6 over
# e = 0.05-0.99 (tests/dem/test_hertz.py)
TSUJI = math.sqrt(5.0 / 6.0)


def effective_modulus(young: float, poisson: float) -> float:
    """E* = E / (2 (1 - nu^2)) of two spheres of one material [Pa]."""
    return young / (2.0 * (1.0 - poisson * poisson))


def effective_shear_modulus(young: float, poisson: float) -> float:
    """G* = G / (2 (2 - nu)), G = E / (2 (1 + nu)), of one material [Pa]."""
    return young / (2.0 * (1.0 + poisson)) / (2.0 * (2.0 - poisson))


def stiffness_ratio(poisson: float) -> float:
    """k_t / k_n = 8 G* / (2 E*) = 2 (1 - nu) / (2 - nu) [-]."""
    return 2.0 * (1.0 - poisson) / (2.0 - poisson)


def contact_time(young: float, poisson: float, r_i: float, r_j: float, m_i: float,
                 m_j: float, v0: float) -> float:
    """Duration of an elastic head-on collision at approach speed v0 [m/s] (Hertz):
    t_c = 2.94328 delta_max / v0, delta_max = (15 m* v0^2 / (16 E* sqrt(R*)))^(2/5) [s]."""
    es = effective_modulus(young, poisson)
    rs = r_i * r_j / (r_i + r_j)
    ms = m_i * m_j / (m_i + m_j)
    dmax = (15.0 * ms * v0 * v0 / (16.0 * es * math.sqrt(rs))) ** 0.4
    return HERTZ_TIME * dmax / v0


OVERLAP_SPREAD = 20.0  # largest delta/R* over (p/E*)^(2/3) in a packing at rest


def largest_overlap(pressure: float, young: float, poisson: float) -> float:
    """The largest overlap delta/R* [-] of a packing at rest at mean stress `pressure`
    [Pa], estimated as OVERLAP_SPREAD (p/E*)^(2/3): the Hertzian overlap of the mean
    contact force scales as (p/E*)^(2/3), and the strongest contacts of a force network
    carry several times the mean (measured: 19.8 (p/E*)^(2/3) at the largest contact of
    examples/rve/hertz_mindlin.toml's 800 spheres at 100 kPa, 4.7 at the mean)."""
    return OVERLAP_SPREAD * (pressure / effective_modulus(young, poisson)) ** (2.0 / 3.0)

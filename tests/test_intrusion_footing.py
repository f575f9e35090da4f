"""studies/intrusion/footing.py: the intrusion twins' Mohr-Coulomb continuum (penalty
contact, psi = 0) against Prandtl's exact bearing capacity factor N_q."""

import math

import pytest

from example_scripts import load_example

footing = load_example("intrusion/footing.py")


def test_prandtl_factor_and_davis_angle():
    """N_q against the textbook table (Terzaghi & Peck; Vesic 1973: 6.40 at 20 deg,
    18.40 at 30 deg, 1 at 0); Davis's angle at psi = 0 is atan(sin phi), and at psi = phi
    the angle itself (an associated material needs no reduction)."""
    assert footing.prandtl_nq(20.0) == pytest.approx(6.40, abs=0.005)
    assert footing.prandtl_nq(30.0) == pytest.approx(18.40, abs=0.005)
    assert footing.prandtl_nq(0.0) == pytest.approx(1.0, rel=1e-12)
    assert footing.davis_angle(30.0) == pytest.approx(math.degrees(math.atan(0.5)), rel=1e-12)
    assert footing.davis_angle(25.0, 25.0) == pytest.approx(25.0, rel=1e-12)


@pytest.mark.validation
def test_strip_footing_converges_into_the_radenkovic_bounds():
    """phi = 20 deg (the intrusion RVE's angle), one point a cell, 8 and 16 cells over the
    footing's width, to a settlement of 0.06 B (the plateau starts near 0.03 B). A
    non-associated (psi = 0) material's limit load lies between the associated ones at
    Davis's angle and at phi: N_q in [5.73, 6.40]. The coarse grids are too strong and
    converge from above (measured to 0.1 B: 7.07, 6.64, 6.30 on 8, 16, 32 cells), so the
    finer of the two must lie below the coarser and within 10 % above the upper bound:
    the 16-cell value's own grid error, its distance to the 32-cell one, is 5.4 %. A
    Drucker-Prager cone circumscribing Mohr-Coulomb, a dilating return or a wrong angle
    would each leave it well outside."""
    n8 = footing.footing(20.0, 8, 0.06, points_per_cell=1)
    n16 = footing.footing(20.0, 16, 0.06, points_per_cell=1)
    lower = footing.prandtl_nq(footing.davis_angle(20.0))
    upper = footing.prandtl_nq(20.0)
    assert n16["N_q_plateau"] < n8["N_q_plateau"]
    assert lower <= n16["N_q_plateau"] <= 1.10 * upper


@pytest.mark.validation
def test_footing_goes_on_where_a_light_node_threw_a_point_out():
    """16 cells over B, one point a cell, to 0.25 B. Without the light-node rule
    (mpm/step.py, affine_velocity) a node holding a sliver of a point's mass beside the
    footing's corner fed its acceleration into the point's affine field C_p, the point's
    stress grew tenfold over ~300 steps and it left the grid at 0.21 B (measured with
    LIGHT_MASS_TOL = 0). With the rule the run reaches 0.25 B, and the pressure over
    the second half of the settlement (measured 6.16) stays between Davis's lower bound
    and 10 % above the upper one, the bounds of the test above."""
    run = footing.footing(20.0, 16, 0.25, points_per_cell=1)
    assert run["failure"] is None
    lower = footing.prandtl_nq(footing.davis_angle(20.0))
    assert lower <= run["N_q_plateau"] <= 1.10 * footing.prandtl_nq(20.0)

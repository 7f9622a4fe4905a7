"""Pressure integration against the panel solution: dense taps recover its Kutta–Joukowski lift."""

import math

import pytest

from pressure_scanner.integration import PressureIntegrator
from pressure_scanner.naca_section import contour_parameter
from pressure_scanner.taps import cosine_clustered_taps
from wing_sim.panel import speed_basis


def test_dense_taps_recover_the_kutta_joukowski_lift_of_the_panel_solution() -> None:
    taps = cosine_clustered_taps(n_per_surface=1500, x_last=0.99999)
    basis = speed_basis()
    alpha = math.radians(7.0)
    cp = basis.pressure_coefficient(contour_parameter(taps.x_c, taps.side), alpha)
    c = PressureIntegrator(taps).integrate_cp(cp, alpha)
    kutta_joukowski = float(basis.solution.lift_coefficient_kutta_joukowski(alpha))
    assert c.cl[0] == pytest.approx(kutta_joukowski, rel=0.006)
    assert abs(c.cd[0]) < 2e-3

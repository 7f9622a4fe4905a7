"""Hess–Smith panel method against potential-flow truths for the NACA 0018."""

import math

import numpy as np
import pytest

from pressure_scanner.integration import contour_weights
from pressure_scanner.naca_section import contour_point, panel_nodes
from wing_sim.panel import solve_hess_smith, speed_basis


def _pressure_coefficients(alpha_rad: float) -> tuple[float, float, float]:
    """(C_l, C_d, C_m) of the inviscid Cp integrated on a 4001-point contour."""
    basis = speed_basis()
    phi = np.linspace(-np.pi, np.pi, 4001)
    x, z = contour_point(phi)
    cn, ca, cm = contour_weights(x, z) @ basis.pressure_coefficient(phi, alpha_rad)
    cl = cn * math.cos(alpha_rad) - ca * math.sin(alpha_rad)
    cd = cn * math.sin(alpha_rad) + ca * math.cos(alpha_rad)
    return cl, cd, cm


def test_lift_slope_matches_thick_aerofoil_theory() -> None:
    # thin-aerofoil 2π with the thickness correction 2π(1 + 0.77 t/c) (Abbott & von Doenhoff §4)
    basis = speed_basis()
    alpha = math.radians(4.0)
    slope = basis.solution.lift_coefficient_kutta_joukowski(alpha) / math.sin(alpha)
    assert slope == pytest.approx(2 * math.pi * (1 + 0.77 * 0.18), rel=0.03)


@pytest.mark.parametrize("alpha_deg", [2.0, 8.0, 14.0])
def test_pressure_lift_equals_kutta_joukowski_and_drag_vanishes(alpha_deg: float) -> None:
    alpha = math.radians(alpha_deg)
    cl, cd, cm = _pressure_coefficients(alpha)
    kj = float(speed_basis().solution.lift_coefficient_kutta_joukowski(alpha))
    assert cl == pytest.approx(kj, rel=0.006)
    assert abs(cd) < 1e-3  # d'Alembert: no drag in potential flow
    assert abs(cm) < 0.02 * cl  # symmetric section: near-zero moment about c/4


def test_zero_incidence_is_symmetric_and_lift_free() -> None:
    basis = speed_basis()
    phi = np.linspace(0.05, np.pi - 0.05, 50)
    cp_upper = basis.pressure_coefficient(phi, 0.0)
    cp_lower = basis.pressure_coefficient(-phi, 0.0)
    np.testing.assert_allclose(cp_upper, cp_lower, atol=1e-9)
    assert basis.pressure_coefficient(0.0, 0.0) == pytest.approx(1.0, abs=1e-3)  # stagnation
    assert _pressure_coefficients(0.0)[0] == pytest.approx(0.0, abs=1e-9)


def test_solution_is_converged_in_panel_count() -> None:
    alpha = math.radians(6.0)
    coarse = solve_hess_smith(*panel_nodes(240)).lift_coefficient_kutta_joukowski(alpha)
    fine = solve_hess_smith(*panel_nodes(480)).lift_coefficient_kutta_joukowski(alpha)
    assert coarse == pytest.approx(fine, rel=0.003)


def test_bad_geometry_is_refused() -> None:
    with pytest.raises(ValueError, match="even"):
        panel_nodes(121)
    x = np.zeros(30)
    with pytest.raises(ValueError, match="zero-length"):
        solve_hess_smith(x, x)

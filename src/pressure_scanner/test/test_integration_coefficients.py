"""Pressure integration against known integrals; inputs in Pa and Cp; invalid inputs."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from pressure_scanner.integration import (
    Coverage,
    PressureIntegrator,
    integrate_pressures,
)
from pressure_scanner.naca_section import half_thickness
from pressure_scanner.taps import load_taps


def test_uniform_pressure_exerts_no_force_or_moment() -> None:
    coeffs = PressureIntegrator().integrate_cp(np.full(49, -0.7), math.radians(10.0))
    assert coeffs.valid[0]
    for value in (coeffs.cn, coeffs.ca, coeffs.cm, coeffs.cl, coeffs.cd):
        assert value[0] == pytest.approx(0.0, abs=1e-12)


def test_linear_loading_gives_the_exact_normal_force_and_moment() -> None:
    """Cp_upper = −k(1 − x), Cp_lower = +k(1 − x): linear in x, so the trapezoidal C_n is exact
    except on the first segment, where the shared leading-edge tap carries Cp = 0:
    C_n = k(1 − x_1). About c/4: C_m = −k/12 − k ∫ z_t² dx (the second term from the axial
    force acting on the thick section)."""
    taps = load_taps()
    k = 0.8
    cp = np.where(taps.side > 0, -k * (1 - taps.x_c), k * (1 - taps.x_c))
    cp[taps.leading_edge] = 0.0
    coeffs = PressureIntegrator(taps).integrate_cp(cp, 0.0)
    x1 = taps.x_c[taps.upper][0]
    assert coeffs.cn[0] == pytest.approx(k * (1 - x1), rel=1e-9)
    thickness_term, _ = quad(lambda x: float(half_thickness(x)) ** 2, 0.0, 1.0)
    assert coeffs.cm[0] == pytest.approx(-k / 12 - k * thickness_term, rel=0.01)


def test_rotation_into_lift_and_drag() -> None:
    integrator = PressureIntegrator()
    rng = np.random.default_rng(0)
    cp = rng.normal(0.0, 0.5, 49)
    alpha = math.radians(30.0)
    c = integrator.integrate_cp(cp, alpha)
    assert c.cl[0] == pytest.approx(c.cn[0] * math.cos(alpha) - c.ca[0] * math.sin(alpha))
    assert c.cd[0] == pytest.approx(c.cn[0] * math.sin(alpha) + c.ca[0] * math.cos(alpha))


def test_pascal_input_equals_cp_input_and_vectorises() -> None:
    integrator = PressureIntegrator()
    rng = np.random.default_rng(1)
    cp = rng.normal(-0.3, 0.4, (5, 49))
    alpha = np.deg2rad([1.0, 3.0, 5.0, 7.0, 9.0])
    q = np.array([100.0, 110.0, 120.0, 130.0, 140.0])
    from_pa = integrator.integrate(cp * q[:, None], alpha, q)
    from_cp = integrator.integrate_cp(cp, alpha)
    np.testing.assert_allclose(from_pa.cl, from_cp.cl, rtol=1e-12)
    one = integrate_pressures(cp[2] * q[2], alpha[2], q[2])
    assert one.cl.shape == (1,) and one.cl[0] == pytest.approx(from_cp.cl[2], rel=1e-12)


def test_saturated_tap_is_excluded_and_reported() -> None:
    integrator = PressureIntegrator(scanner_range_pa=(-1000.0, 1000.0))
    p = np.full(49, -50.0)
    p[10] = 1500.0
    c = integrator.integrate(p, 0.1, 122.0)
    assert c.valid[0] and c.n_excluded[0] == 1
    assert c.excluded[0, 10] and c.out_of_range[0, 10]
    assert "U10" in c.describe(0) and "out of scanner range" in c.describe(0)
    assert c.cl[0] == pytest.approx(0.0, abs=1e-12)  # uniform remaining pressure


def test_bad_angle_or_dynamic_pressure_invalidates_only_that_sample() -> None:
    integrator = PressureIntegrator()
    p = np.full((3, 49), -40.0)
    c = integrator.integrate(p, np.array([0.1, np.nan, 0.1]), np.array([122.0, 122.0, 0.0]))
    assert c.valid.tolist() == [True, False, False]
    assert c.reason[1] == Coverage.INVALID_ALPHA
    assert c.reason[2] == Coverage.INVALID_DYNAMIC_PRESSURE
    assert np.isnan(c.cl[1]) and np.isnan(c.cl[2])


def test_wrong_shapes_are_refused() -> None:
    integrator = PressureIntegrator()
    with pytest.raises(ValueError, match=r"\(49,\) or \(K, 49\)"):
        integrator.integrate(np.zeros(48), 0.0, 122.0)
    with pytest.raises(ValueError, match="alpha_rad"):
        integrator.integrate_cp(np.zeros((4, 49)), np.zeros(3))
    with pytest.raises(ValueError, match="low < high"):
        PressureIntegrator(scanner_range_pa=(10.0, -10.0))

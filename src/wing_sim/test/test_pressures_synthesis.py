"""Pressure synthesis: the distribution integrates to the aero model's lift; sensing chain."""

import math

import numpy as np
import pytest

from pressure_scanner.integration import PressureIntegrator, contour_weights
from pressure_scanner.taps import load_taps
from wing_sim import aero
from wing_sim.aero import kirchhoff_factor
from wing_sim.plant import WingPlant
from wing_sim.pressures import N_TRUTH, T_CA, T_CL, T_CM, T_CN, PressureModel
from wing_sim.random_stream import new_state
from wing_sim.wing_params import WingParams


def _aero_rows(n: int, seed: int = 0) -> np.ndarray:
    """Random but consistent aero states: attached, trailing-edge and fully separated, with
    vortex and added-mass lift, both signs of α."""
    rng = np.random.default_rng(seed)
    p = WingParams()
    rows = np.zeros((n, aero.N_OUT))
    alpha = np.deg2rad(rng.uniform(-12.0, 30.0, n))
    alpha_e = alpha + np.deg2rad(rng.normal(0.0, 1.0, n))
    f = np.where(rng.random(n) < 0.3, 1.0, rng.uniform(0.01, 1.0, n))
    cl_circ = p.lift_slope_per_rad * alpha_e * np.array([kirchhoff_factor(v) for v in f])
    cl_vortex = np.sign(alpha_e) * np.where(rng.random(n) < 0.5, rng.uniform(0, 0.6, n), 0.0)
    cl_nc = rng.normal(0.0, 0.01, n)
    rows[:, aero.O_ALPHA] = alpha
    rows[:, aero.O_ALPHA_E] = alpha_e
    rows[:, aero.O_F] = f
    rows[:, aero.O_CL_CIRC] = cl_circ
    rows[:, aero.O_CL_VORTEX] = cl_vortex
    rows[:, aero.O_CL_NC] = cl_nc
    rows[:, aero.O_CL] = cl_circ + cl_vortex + cl_nc
    rows[:, aero.O_X_V] = rng.uniform(0.25, 0.9, n)
    return rows


def test_fine_grid_integral_of_the_pressures_is_the_model_lift() -> None:
    model = PressureModel(WingParams(), load_taps())
    rows = _aero_rows(200)
    cp_fine, truth = model.clean_cp(rows, fine=True)
    t = model.tables
    cn, ca, cm = contour_weights(t.x, t.z) @ cp_fine.T
    alpha = rows[:, aero.O_ALPHA]
    cl = cn * np.cos(alpha) - ca * np.sin(alpha)
    # the tabulated truth is the direct fine-grid integral of the synthesised Cp ...
    np.testing.assert_allclose(truth[:, T_CN], cn, atol=1e-3)
    np.testing.assert_allclose(truth[:, T_CA], ca, atol=1e-3)
    np.testing.assert_allclose(truth[:, T_CM], cm, atol=1e-3)
    # ... and it reproduces the aero model's C_l (what the rig's lift must behave like)
    np.testing.assert_allclose(cl, rows[:, aero.O_CL], atol=1e-3)
    np.testing.assert_allclose(truth[:, T_CL], rows[:, aero.O_CL], atol=1e-9)


def test_mirrored_angle_gives_mirrored_pressures() -> None:
    taps = load_taps()
    model = PressureModel(WingParams(), taps)
    rows = _aero_rows(20, seed=3)
    mirrored = rows.copy()
    for col in (aero.O_ALPHA, aero.O_ALPHA_E, aero.O_CL_CIRC, aero.O_CL_VORTEX, aero.O_CL_NC):
        mirrored[:, col] = -rows[:, col]
    cp, truth = model.clean_cp(rows)
    cp_m, truth_m = model.clean_cp(mirrored)
    swap = np.concatenate([[taps.leading_edge], taps.lower, taps.upper])
    np.testing.assert_allclose(cp_m, cp[:, swap], atol=1e-10)
    np.testing.assert_allclose(truth_m[:, T_CN], -truth[:, T_CN], atol=1e-12)
    np.testing.assert_allclose(truth_m[:, T_CA], truth[:, T_CA], atol=1e-12)


@pytest.mark.parametrize("alpha_deg", [2.0, 6.0, 10.0])
def test_tap_integral_bias_is_below_one_percent_in_attached_flow(alpha_deg: float) -> None:
    alpha = np.full(300, math.radians(alpha_deg))
    _, truth, cp = WingPlant(seed=0).simulate(alpha, clean_cp=True)
    taps = PressureIntegrator().integrate_cp(cp, alpha)
    bias = taps.cl[-1] / truth.cl_fine[-1] - 1.0
    assert abs(bias) < 0.01
    assert bias == pytest.approx(-0.0027, abs=0.001)  # the documented figure (docs/plant.md)


def test_tap_integral_bias_stays_a_few_percent_when_stalled() -> None:
    alpha = np.full(400, math.radians(26.0))
    _, truth, cp = WingPlant(WingParams(light_stall_fraction=0.0), seed=0).simulate(
        alpha, clean_cp=True
    )
    assert truth.stalled[-1]
    taps = PressureIntegrator().integrate_cp(cp, alpha)
    bias = np.mean(taps.cl[100:] / truth.cl_fine[100:] - 1.0)
    assert -0.06 < bias < 0.0


def test_tube_lag_is_an_exact_first_order_lag_for_ramped_pressure() -> None:
    params = WingParams(pressure_noise_pa=0.0, drift_std_pa=0.0)
    model = PressureModel(params, load_taps())
    rows = _aero_rows(1, seed=1)
    rows[0, aero.O_F] = 1.0
    rows = np.repeat(rows, 30, axis=0)
    rows[5:, [aero.O_ALPHA, aero.O_ALPHA_E, aero.O_CL_CIRC, aero.O_CL]] *= 1.3
    cp, _ = model.clean_cp(rows)
    u = params.dynamic_pressure_pa * cp
    measured = np.empty_like(u)
    model.synthesize(
        rows, new_state(0, 2), measured, np.zeros((0, u.shape[1])), np.empty((30, N_TRUTH))
    )
    T = params.sample_period_s
    tau = model.tube_lag_s
    u0, u1 = u[0], u[-1]
    y5 = u1 - (u1 - u0) * tau / T * (1.0 - np.exp(-T / tau))
    expected = u1 + (y5 - u1) * np.exp(-np.arange(25)[:, None] * T / tau)
    np.testing.assert_allclose(measured[:5], u[:5], atol=1e-9)
    np.testing.assert_allclose(measured[5:], expected, atol=1e-9)
    assert np.all((tau >= params.tube_lag_min_s) & (tau <= params.tube_lag_max_s))


def test_noise_and_drift_have_the_configured_size() -> None:
    params = WingParams(drift_std_pa=0.3, drift_time_s=300.0)
    plant = WingPlant(params, seed=4)
    alpha = np.full(6000, math.radians(5.0))
    pressure, _, cp = plant.simulate(alpha, clean_cp=True)
    error = pressure - params.dynamic_pressure_pa * cp
    white = np.diff(error, axis=0) / math.sqrt(2.0)  # differencing removes the slow drift
    assert white.std() == pytest.approx(params.pressure_noise_pa, rel=0.03)
    drift = error.mean(axis=0)  # 30 s ≪ 300 s: the drift has wandered little from its zero
    assert 0.0 < np.abs(drift).max() < 0.3

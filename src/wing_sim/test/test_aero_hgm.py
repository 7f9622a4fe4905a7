"""Unsteady aero model: static targets, Wagner/HGM linear dynamics, stall hazard, seeding."""

import math

import numpy as np
import pytest
from scipy import signal

from wing_sim.aero import (
    UnsteadyAerodynamics,
    static_lift_coefficient,
    static_separation_point,
)
from wing_sim.wing_params import WingParams


def test_constant_angle_settles_on_the_kirchhoff_static_lift() -> None:
    params = WingParams(separation_noise_std=0.0)
    for alpha_deg, branch in ((4.0, "attached"), (14.0, "attached"), (27.0, "separated")):
        alpha = np.full(600, math.radians(alpha_deg))
        series = UnsteadyAerodynamics(params, seed=0).simulate(alpha)
        expected = float(static_lift_coefficient(alpha[0], params, branch))
        assert series.cl[-1] == pytest.approx(expected, rel=1e-9)
        assert series.separation_point[-1] == pytest.approx(
            float(static_separation_point(alpha[0], params, branch)), rel=1e-9
        )


def test_static_targets_follow_the_documented_parametrisation() -> None:
    p = WingParams()
    deg = np.array([2.0, 8.0, 10.0, 14.0, 24.0, 28.0])
    cl_att = static_lift_coefficient(np.deg2rad(deg), p, "attached")
    cl_sep = static_lift_coefficient(np.deg2rad(deg), p, "separated")
    # linear below 10° with C_lα = 0.104/°
    np.testing.assert_allclose(cl_att[:3], 0.104 * deg[:3], rtol=1e-12)
    # slope falls above 10°, branches merge (fully separated) from 24°
    assert cl_att[3] < 0.104 * 14.0 * 0.95
    np.testing.assert_allclose(cl_att[4:], cl_sep[4:], rtol=1e-12)
    f24 = static_separation_point(np.deg2rad(24.0), p, "attached")
    assert f24 == pytest.approx(p.f_full_separation)


def test_effective_angle_follows_the_wagner_response_from_scipy() -> None:
    """Attached flow (|α| < 10°): α_E is the output of the linear two-lag Wagner system
    (HGM eq. 9–10) driven by α_3/4; compare with scipy's exact linear simulation."""
    p = WingParams()
    fs = p.sample_rate_hz
    t = np.arange(0, 6.0, 1.0 / fs)
    amp, freq = math.radians(3.0), 1.3
    alpha = math.radians(4.0) + amp * np.sin(2 * math.pi * freq * t)
    alpha_dot = amp * 2 * math.pi * freq * np.cos(2 * math.pi * freq * t)
    downwash = p.chord_m * (0.75 - p.pivot_x_c) / p.velocity_m_s
    alpha_34 = alpha + alpha_dot * downwash
    tu = p.convective_time_s
    b1, b2 = p.wagner_b1 / tu, p.wagner_b2 / tu
    system = signal.StateSpace(
        np.diag([-b1, -b2]),
        np.array([[p.wagner_a1 * b1], [p.wagner_a2 * b2]]),
        np.array([[1.0, 1.0]]),
        np.array([[1.0 - p.wagner_a1 - p.wagner_a2]]),
    )
    x0 = np.array([p.wagner_a1, p.wagner_a2]) * alpha_34[0]
    _, alpha_e_ref, _ = signal.lsim(system, alpha_34, t, X0=x0)
    series = UnsteadyAerodynamics(p, seed=0).simulate(alpha)
    # the model differentiates the sampled α (backward difference); allow for that
    tail = t > 1.0
    err = np.abs(series.alpha_effective[tail] - alpha_e_ref[tail])
    assert err.max() < math.radians(0.01)
    # the lag is real: α_E differs from α by far more than that
    assert np.abs(series.alpha_effective - alpha).max() > math.radians(0.2)


def test_stall_waiting_time_matches_the_hazard_rate() -> None:
    """At constant α between the thresholds, attached flow stalls after an exponential waiting
    time with rate Φ((α − α_stall)/Δ)/τ (the deep-stall switch alone: no light regime)."""
    p = WingParams(light_stall_fraction=0.0)
    alpha_deg = 21.5
    rate = 0.5 * math.erfc(-((alpha_deg - p.alpha_stall_deg) / p.switch_spread_deg) / math.sqrt(2))
    rate /= p.switch_time_s
    alpha = np.full(2400, math.radians(alpha_deg))  # 12 s, ≈ 14 mean waiting times
    waits = []
    for seed in range(300):
        stalled = UnsteadyAerodynamics(p, seed=seed).simulate(alpha).stalled
        assert not stalled[0]
        assert stalled.any()
        waits.append(np.argmax(stalled) / p.sample_rate_hz)
    mean_wait = float(np.mean(waits))
    # mean of 300 exponential waits: standard error 5.8 %
    assert mean_wait == pytest.approx(1.0 / rate, rel=0.18)


def test_vortex_lift_appears_at_a_stall_event_and_decays() -> None:
    p = WingParams(separation_noise_std=0.0, light_stall_fraction=0.0)
    alpha = np.full(1200, math.radians(23.0))
    alpha[:100] = math.radians(20.0)  # start attached, then jump past the stall angle
    series = UnsteadyAerodynamics(p, seed=2).simulate(alpha)
    k = int(np.argmax(series.stalled))
    assert series.stalled[k] and k >= 100
    assert series.cl_vortex[:k].max() == 0.0
    assert series.cl_vortex[k : k + 40].max() > 0.05
    assert series.cl_vortex[-1] < 1e-3
    # the suction bump travels aft during the vortex time T_VL
    pos = series.vortex_position[k : k + 60]
    assert np.all(np.diff(pos) >= 0) and pos[-1] == pytest.approx(p.vortex_end_c)


def test_same_seed_reproduces_and_other_seed_differs() -> None:
    t = np.arange(4000) / 200.0
    alpha = np.deg2rad(19.9 + 4.7 * np.sin(2 * math.pi * 1.0 * t))
    a = UnsteadyAerodynamics(seed=5).simulate(alpha)
    b = UnsteadyAerodynamics(seed=5).simulate(alpha)
    c = UnsteadyAerodynamics(seed=6).simulate(alpha)
    np.testing.assert_array_equal(a.cl, b.cl)
    assert np.abs(a.cl - c.cl).max() > 0.1


def test_invalid_parameters_are_refused_with_the_field_named() -> None:
    with pytest.raises(ValueError, match="alpha_reattach_deg"):
        WingParams(alpha_reattach_deg=23.0)
    with pytest.raises(ValueError, match="velocity_m_s"):
        WingParams(velocity_m_s=0.0)
    with pytest.raises(ValueError, match="finite"):
        WingParams(chord_m=float("nan"))
    with pytest.raises(ValueError, match="NaN"):
        UnsteadyAerodynamics().simulate(np.array([0.1, np.nan]))


def test_default_flow_matches_the_rig() -> None:
    p = WingParams()
    assert p.dynamic_pressure_pa == pytest.approx(122.0, rel=0.01)
    assert p.convective_time_s == pytest.approx(0.0105, rel=0.01)
    assert p.reynolds_number == pytest.approx(285_000, rel=0.01)

"""Simulated actuator: sampled sine responses match `frf` (and the continuous model of
docs/design.md §6), the rate limit holds, the logged pitch has the specified noise and encoder
step, and a seed reproduces a run."""

import math

import numpy as np
import pytest

from pitch_actuator.dynamics import ActuatorModel, ActuatorParams

FS = 200.0


def _run(model: ActuatorModel, commands_rad: np.ndarray) -> dict[str, np.ndarray]:
    samples = [model.step(float(c)) for c in commands_rad]
    return {
        name: np.array([getattr(s, name) for s in samples])
        for name in ("position_rad", "velocity_rad_s", "true_position_rad", "alpha_true_rad")
    }


def _sine_gain(freq_hz: float, signal: str, seed: int = 3) -> tuple[complex, complex]:
    """Simulate a sine (1°, on a 4° offset), return (measured ratio, model.frf)."""
    model = ActuatorModel(ActuatorParams(initial_deg=4.0), fs=FS, seed=seed)
    per_period = round(FS / freq_hz)
    assert per_period == FS / freq_hz
    settle = per_period * math.ceil(0.5 * freq_hz)  # ≥ 0.5 s: transient e^{-ζω_n t} < 1e-14
    periods = 2
    k = np.arange(settle + periods * per_period)
    command = np.radians(4.0 + 1.0 * np.sin(2 * np.pi * freq_hz * k / FS))
    out = _run(model, command)[signal][settle:]
    line = periods  # the sine sits on DFT bin `periods` of the analysed window
    ratio = np.fft.rfft(out)[line] / np.fft.rfft(command[settle:])[line]
    return complex(ratio), complex(model.frf(freq_hz))


@pytest.mark.parametrize("freq_hz", [0.4, 1.6, 5.0, 12.5])
def test_simulated_sine_matches_frf(freq_hz: float) -> None:
    measured, predicted = _sine_gain(freq_hz, "true_position_rad")
    assert abs(measured / predicted - 1.0) < 1e-9


@pytest.mark.parametrize("freq_hz", [1.0, 5.0])
def test_logged_pitch_sine_matches_frf_within_noise(freq_hz: float) -> None:
    measured, predicted = _sine_gain(freq_hz, "position_rad")
    assert abs(abs(measured) / abs(predicted) - 1.0) < 2e-3
    assert abs(math.degrees(np.angle(measured / predicted))) < 0.1


def test_frf_equals_the_continuous_model_with_zoh() -> None:
    """docs/design.md §6 model, sampled: G(jω) e^{-jωτ_d} · ZOH (sinc · e^{-jωT/2}) · e^{jωT}
    (sample k is the state at the end of interval k). Aliased ZOH images are neglected, so the
    agreement is to 1e-3 in gain and 0.05° in phase below 10 Hz."""
    model = ActuatorModel(fs=FS)
    f = np.array([0.02, 0.4, 1.0, 1.98, 5.0, 10.0])
    s = 2j * np.pi * f
    wn, zeta, T = 2 * np.pi * 15.0, 0.7, 1 / FS
    continuous = wn**2 / (s**2 + 2 * zeta * wn * s + wn**2) * np.exp(-s * 0.001)
    expected = continuous * np.sinc(f * T) * np.exp(s * T / 2)
    G = model.frf(f)
    np.testing.assert_allclose(np.abs(G), np.abs(expected), rtol=1e-3)
    np.testing.assert_allclose(np.degrees(np.angle(G / expected)), 0.0, atol=0.05)
    assert G.shape == f.shape


def test_rate_limit_is_respected_on_a_large_step() -> None:
    model = ActuatorModel(ActuatorParams(noise_std_deg=0.0, encoder_step_deg=0.0), fs=FS)
    out = _run(model, np.full(100, math.radians(25.0)))
    vmax = math.radians(250.0)
    assert np.max(np.abs(out["velocity_rad_s"])) <= vmax * (1 + 1e-12)
    assert np.max(out["velocity_rad_s"]) == pytest.approx(vmax)  # the limit is reached
    increments = np.diff(np.concatenate([[0.0], out["true_position_rad"]]))
    assert np.max(np.abs(increments)) <= vmax / FS * (1 + 1e-12)
    assert out["true_position_rad"][-1] == pytest.approx(math.radians(25.0), abs=1e-6)


def test_logged_pitch_noise_and_encoder_step() -> None:
    model = ActuatorModel(ActuatorParams(initial_deg=5.0), fs=FS, seed=11)
    out = _run(model, np.full(20_000, math.radians(5.0)))
    error_deg = np.degrees(out["position_rad"] - out["true_position_rad"])
    # 0.01° white noise plus uniform quantisation error of a 0.005° step: √(0.01² + 0.005²/12).
    expected = math.hypot(0.01, 0.005 / math.sqrt(12))
    assert np.std(error_deg) == pytest.approx(expected, rel=0.03)
    assert abs(np.mean(error_deg)) < 3e-4
    counts = np.degrees(out["position_rad"]) / 0.005
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)


def test_same_seed_reproduces_a_run_and_another_seed_does_not() -> None:
    k = np.arange(600)
    command = np.radians(10.0 + 2.0 * np.sin(2 * np.pi * k / FS))
    a = _run(ActuatorModel(seed=5), command)
    b = _run(ActuatorModel(seed=5), command)
    c = _run(ActuatorModel(seed=6), command)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name])
    assert not np.array_equal(a["position_rad"], c["position_rad"])
    assert not np.array_equal(a["alpha_true_rad"], c["alpha_true_rad"])
    np.testing.assert_array_equal(a["true_position_rad"], c["true_position_rad"])


def test_alpha_adds_the_free_stream_gust() -> None:
    k = np.arange(20_000)
    command = np.radians(np.full(k.size, 8.0))
    out = _run(ActuatorModel(ActuatorParams(initial_deg=8.0), seed=2), command)
    gust_deg = np.degrees(out["alpha_true_rad"] - out["true_position_rad"])
    assert np.std(gust_deg) == pytest.approx(0.2, rel=0.15)  # 100 s ≈ 1000 correlation times
    calm = _run(ActuatorModel(ActuatorParams(gust_std_deg=0.0)), command[:100])
    np.testing.assert_array_equal(calm["alpha_true_rad"], calm["true_position_rad"])


def test_invalid_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="damping_ratio must be > 0"):
        ActuatorParams(damping_ratio=-0.1)
    with pytest.raises(ValueError, match="noise_std_deg must be >= 0"):
        ActuatorParams(noise_std_deg=-1.0)
    with pytest.raises(ValueError, match="fs must be > 0"):
        ActuatorModel(fs=0.0)
    with pytest.raises(ValueError, match="command must be finite"):
        ActuatorModel().step(math.nan)


def test_internal_step_and_delay_fit_the_sample_grid() -> None:
    model = ActuatorModel(fs=FS)
    assert model.substeps == 10 and model.h == pytest.approx(0.0005)
    assert model.delay_steps == 2  # 1 ms
    odd = ActuatorModel(ActuatorParams(internal_step_s=0.0007), fs=FS)
    assert odd.h <= 0.0007 and odd.substeps * odd.h == pytest.approx(1 / FS)

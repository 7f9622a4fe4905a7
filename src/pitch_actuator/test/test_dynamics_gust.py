"""Ornstein–Uhlenbeck gust: stationary std σ and autocorrelation e^{−lag/τ}, seeded."""

import math

import numpy as np
import pytest

from pitch_actuator.gust import FreeStreamGust

FS = 200.0


def test_gust_std_and_correlation_time() -> None:
    gust = FreeStreamGust(std_deg=0.2, time_constant_s=0.1, fs=FS, seed=4)
    x = gust.sample(400_000)  # 2000 s ≈ 20,000 correlation times
    assert np.std(x) == pytest.approx(0.2, rel=0.03)
    assert abs(np.mean(x)) < 0.01
    x = x - x.mean()
    lags = np.arange(1, 41)
    rho = np.array([np.dot(x[:-lag], x[lag:]) / np.dot(x, x) for lag in lags])
    np.testing.assert_allclose(rho, np.exp(-lags / (FS * 0.1)), atol=0.02)
    # Correlation time from the log-linear fit of the autocorrelation over 0 < lag ≤ 2τ.
    tau_hat = -1.0 / np.polyfit(lags / FS, np.log(rho), 1)[0]
    assert tau_hat == pytest.approx(0.1, rel=0.05)


def test_first_sample_is_already_stationary() -> None:
    first = np.array([FreeStreamGust(0.2, 0.1, FS, seed=s).step() for s in range(4000)])
    assert np.std(first) == pytest.approx(0.2, rel=0.05)


def test_gust_is_seeded_and_step_equals_sample() -> None:
    a = FreeStreamGust(seed=9).sample(5000)
    b = FreeStreamGust(seed=9)
    stepped = np.array([b.step() for _ in range(5000)])
    np.testing.assert_array_equal(a, stepped)
    assert not np.array_equal(a, FreeStreamGust(seed=10).sample(5000))


def test_exact_discretisation_coefficients() -> None:
    gust = FreeStreamGust(std_deg=0.3, time_constant_s=0.05, fs=100.0)
    assert gust.decay == pytest.approx(math.exp(-0.01 / 0.05))
    assert gust.innovation_std_deg == pytest.approx(0.3 * math.sqrt(1 - math.exp(-0.02 / 0.05)))


def test_invalid_gust_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="time_constant_s must be > 0"):
        FreeStreamGust(time_constant_s=0.0)
    with pytest.raises(ValueError, match="std_deg must be >= 0"):
        FreeStreamGust(std_deg=-0.1)

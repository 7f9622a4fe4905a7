"""Relative RMS error and the BLA FRF's prediction of single-sine validation records."""

import numpy as np
import pytest
from scipy.signal import freqz, lfilter

from aero_identification import (
    BLA,
    PeriodicData,
    estimate_bla,
    predict_bla_sine,
    relative_rms_error,
)
from aero_identification.metrics import interpolate_frf
from aero_identification.periodic_data import random_phase_period

FS = 200.0
N, P, M = 1000, 3, 4  # 0.2 Hz resolution, odd lines 0.2 … 7.8 Hz
B, A = [0.05, 0.05], [1.0, -1.6, 0.7]


def test_relative_rms_error_definition() -> None:
    y = np.array([1.0, 3.0, 1.0, 3.0])  # mean 2, rms deviation 1
    assert relative_rms_error(y, y) == 0.0
    assert relative_rms_error(y, np.full(4, 2.0)) == pytest.approx(1.0)
    assert relative_rms_error(y, y + 0.5) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="same shape"):
        relative_rms_error(y, y[:3])
    with pytest.raises(ValueError, match="constant"):
        relative_rms_error(np.ones(4), y)
    with pytest.raises(ValueError, match="NaN"):
        relative_rms_error(y, np.full(4, np.nan))


def multisine_bla(rng: np.random.Generator, sigma: float) -> BLA:
    lines = np.arange(1, 40, 2)
    u = np.empty((N, P, M))
    y = np.empty((N, P, M))
    for m in range(M):
        period = random_phase_period(rng, N, lines)
        record = np.tile(period / period.std(), P + 1)
        out = lfilter(B, A, record)[N:] + sigma * rng.standard_normal(N * P)
        u[:, :, m] = record[N:].reshape(P, N).T
        y[:, :, m] = out.reshape(P, N).T
    return estimate_bla(PeriodicData(u, y, FS, lines))


def test_predict_bla_sine_on_linear_system_reaches_noise_level() -> None:
    rng = np.random.default_rng(7)
    sigma = 0.01
    bla = multisine_bla(rng, sigma)
    offset = 0.4  # operating point of the output (C_l at the mean angle)
    for f in (0.5, 1.0, 1.7):  # between excited lines (0.2 Hz grid, odd lines)
        t = np.arange(int(5 * FS / f)) / FS  # 5 whole periods
        u_sine = 2.0 + np.cos(2 * np.pi * f * t + 0.3)
        x = lfilter(B, A, np.tile(u_sine, 2))[t.size :]  # steady state
        y_lin = x - x.mean() + offset
        y = y_lin + sigma * rng.standard_normal(t.size)
        y_hat = predict_bla_sine(bla, f, u_sine, y_mean=float(y.mean()))
        err = relative_rms_error(y, y_hat)
        noise_only = sigma / np.std(y)
        assert err == pytest.approx(noise_only, rel=0.15)
        # The true FRF interpolated from the estimate is close to the exact one.
        _, G_f = freqz(B, A, worN=[2 * np.pi * f / FS])
        assert abs(interpolate_frf(bla, f) - G_f[0]) < 0.02 * abs(G_f[0])


def test_predict_bla_sine_refuses_frequencies_outside_the_band() -> None:
    bla = multisine_bla(np.random.default_rng(0), 0.01)
    u = np.cos(2 * np.pi * 9.0 * np.arange(400) / FS)
    with pytest.raises(ValueError, match="outside the excited band"):
        predict_bla_sine(bla, 9.0, u, y_mean=0.0)

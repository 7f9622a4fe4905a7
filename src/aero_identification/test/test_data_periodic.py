"""PeriodicData: validation, spectra scaling, selection, transient check."""

import numpy as np
import pytest
from scipy.signal import lfilter

from aero_identification import PeriodicData, transient_periods
from aero_identification.periodic_data import random_phase_period, transient_ratio


def test_shape_and_line_errors_say_what_is_wrong() -> None:
    x = np.zeros((64, 3, 2))
    with pytest.raises(ValueError, match="same shape"):
        PeriodicData(x, np.zeros((64, 2, 2)), 10.0, [1])
    with pytest.raises(ValueError, match=r"u\[:, :, None\]"):
        PeriodicData(x[:, :, 0], x[:, :, 0], 10.0, [1])
    with pytest.raises(ValueError, match="below Nyquist"):
        PeriodicData(x, x, 10.0, [1, 32])
    with pytest.raises(ValueError, match="not Hz"):
        PeriodicData(x, x, 10.0, [0.5, 1.5])
    with pytest.raises(ValueError, match="positive sampling"):
        PeriodicData(x, x, 0.0, [1])
    bad = x.copy()
    bad[3, 1, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        PeriodicData(bad, x, 10.0, [1])


def test_period_spectra_scaling() -> None:
    N, fs = 128, 50.0
    t = np.arange(N) / fs
    amplitude, k = 0.7, 5
    u = amplitude * np.cos(2 * np.pi * k * fs / N * t)
    data = PeriodicData(np.tile(u[:, None, None], (1, 2, 1)), np.zeros((N, 2, 1)), fs, [k])
    # 1/√N scaling: a sine of amplitude A on bin k has |U[k]| = A√N/2.
    np.testing.assert_allclose(np.abs(data.U[k, :, 0]), amplitude * np.sqrt(N) / 2)
    assert data.U.shape == (N // 2 + 1, 2, 1)
    np.testing.assert_allclose(data.excited_freq, [k * fs / N])


def test_select_keeps_same_latest_periods_per_realization() -> None:
    N, P, M = 16, 6, 3
    u = np.arange(N * P * M, dtype=float).reshape(N, P, M)
    data = PeriodicData(u, -u, 1.0, [1])
    keep = np.zeros((P, M), dtype=bool)
    keep[[0, 2, 3, 5], 0] = True  # 4 kept
    keep[[1, 4, 5], 1] = True  # 3 kept
    keep[[2], 2] = True  # 1 kept: realization dropped (needs 2)
    sub = data.select(keep)
    assert (sub.N, sub.P, sub.M) == (N, 3, 2)
    np.testing.assert_array_equal(sub.period_index, [[2, 1], [3, 4], [5, 5]])
    np.testing.assert_array_equal(sub.realization_index, [0, 1])
    np.testing.assert_array_equal(sub.u[:, 0, 1], u[:, 1, 1])
    np.testing.assert_array_equal(sub.y[:, 2, 0], -u[:, 5, 0])
    with pytest.raises(ValueError, match="boolean"):
        data.select(keep.astype(int))
    with pytest.raises(ValueError, match="no realization keeps"):
        data.select(keep, min_periods=5)
    again = sub.select_realizations([1]).drop_leading(1)
    np.testing.assert_array_equal(again.period_index[:, 0], [4, 5])
    np.testing.assert_array_equal(again.realization_index, [1])


def test_transient_check_finds_leading_transient_period() -> None:
    rng = np.random.default_rng(2)
    N, P, M = 512, 5, 2
    lines = np.arange(1, 60, 2)
    u = np.empty((N, P, M))
    y_transient = np.empty((N, P, M))
    y_steady = np.empty((N, P, M))
    b, a = [0.1], [1.0, -0.97]  # time constant ≈ 33 samples: transient dies in period 0
    for m in range(M):
        period = random_phase_period(rng, N, lines)
        record = np.tile(period / period.std(), P + 1)
        out = lfilter(b, a, record)
        noise = 0.01 * rng.standard_normal(N * P)
        u[:, :, m] = record[N:].reshape(P, N).T
        y_transient[:, :, m] = (out[: N * P] + noise).reshape(P, N).T  # from rest
        y_steady[:, :, m] = (out[N:] + noise).reshape(P, N).T  # one period settled
    fs = 10.0
    assert transient_periods(PeriodicData(u, y_transient, fs, lines)) == 1
    assert transient_periods(PeriodicData(u, y_steady, fs, lines)) == 0
    ratio = transient_ratio(PeriodicData(u, y_steady, fs, lines))
    assert np.all(np.isnan(ratio[-2:]))
    np.testing.assert_allclose(ratio[:-2], 1.0, atol=0.3)
    with pytest.raises(ValueError, match="more periods"):
        transient_periods(PeriodicData(u[:, :2], y_steady[:, :2], fs, lines))

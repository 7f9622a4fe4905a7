"""Local Polynomial Method: transient removal on single realizations (Pintelon et al. 2010)."""

import numpy as np
import pytest
from scipy.signal import freqz, lfilter

from aero_identification import PeriodicData, estimate_bla
from aero_identification.lpm import lpm_periodic
from aero_identification.periodic_data import random_phase_period

N, P = 256, 4
FS = 100.0
# Lightly damped resonance (pole radius 0.99): its start-up transient lasts a few periods.
R_POLE, THETA = 0.99, 0.15
A = [1.0, -2 * R_POLE * np.cos(THETA), R_POLE**2]
B = [0.02, 0.0]


def transient_record(rng: np.random.Generator, lines: np.ndarray, M: int, sigma: float):
    """Odd multisine applied from rest (zero initial state): transient in the first periods."""
    u = np.empty((N, P, M))
    y = np.empty((N, P, M))
    for m in range(M):
        period = random_phase_period(rng, N, lines)
        record = np.tile(period / period.std(), P)
        out = lfilter(B, A, record) + sigma * rng.standard_normal(N * P)
        u[:, :, m] = record.reshape(P, N).T
        y[:, :, m] = out.reshape(P, N).T
    return PeriodicData(u, y, FS, lines)


def excited(rng: np.random.Generator) -> np.ndarray:
    odd = np.arange(1, 100, 2)
    return odd[rng.random(odd.size) > 0.25]  # random detection lines


def test_lpm_single_realization_with_transient_is_unbiased() -> None:
    rng = np.random.default_rng(3)
    lines = excited(rng)
    data = transient_record(rng, lines, M=1, sigma=0.003)
    _, G_true = freqz(B, A, worN=2 * np.pi * lines / N)
    bla = estimate_bla(data)  # M == 1 selects the LPM
    assert bla.method == "lpm"
    sigma_G = np.sqrt(bla.var_noise)
    assert np.mean(np.abs(bla.G - G_true) < 3 * sigma_G) >= 0.95
    # Plain averaging of the transient-affected periods is biased beyond its noise level.
    G_plain = np.mean(data.Y[lines, :, 0] / data.U[lines, :, 0], axis=1)
    assert np.mean(np.abs(G_plain - G_true) < 3 * sigma_G) < 0.85
    assert np.mean(np.abs(G_plain - G_true) ** 2 / bla.var_noise) > 5.0  # noise alone gives ≈ 1
    # With M == 1 the nonlinear variance cannot be separated: reported as zero.
    np.testing.assert_array_equal(bla.var_total, bla.var_noise)


def test_lpm_noise_variance_is_calibrated() -> None:
    """Across realizations, the spread of G_m matches the LPM's own variance estimate."""
    rng = np.random.default_rng(8)
    lines = excited(rng)
    data = transient_record(rng, lines, M=40, sigma=0.02)
    _, G_true = freqz(B, A, worN=2 * np.pi * lines / N)
    G_m, var_m = [], []
    for m in range(data.M):
        b = estimate_bla(data.select_realizations([m]), method="lpm")
        G_m.append(b.G)
        var_m.append(b.var_noise)
    err2 = np.abs(np.array(G_m) - G_true) ** 2
    ratio = np.median(err2.mean(axis=0) / np.mean(var_m, axis=0))
    assert ratio == pytest.approx(1.0, abs=0.25)
    # The multi-realization LPM BLA agrees with the truth too, and its var_total ≈ var_noise
    # for this linear system (median over lines: at the resonance the polynomial cannot follow
    # the transient and the LPM variance is conservative, a known LPM limitation).
    bla = estimate_bla(data, method="lpm")
    assert np.mean(np.abs(bla.G - G_true) < 3 * np.sqrt(bla.var_noise)) >= 0.95
    assert np.median(bla.var_total / bla.var_noise) == pytest.approx(1.0, abs=0.3)


def test_lpm_single_period_uses_non_excited_lines() -> None:
    rng = np.random.default_rng(4)
    lines = np.arange(1, 100, 4)  # every other odd line free as LPM neighbours
    X = np.zeros(N * 4 // 2 + 1, complex)
    X[lines] = np.exp(2j * np.pi * rng.random(lines.size))
    # One long period (N' = 4N) of a steady-state linear response plus noise.
    period = np.fft.irfft(X, 4 * N)
    period /= period.std()
    record = np.tile(period, 3)
    out = lfilter(B, A, record)[-4 * N :] + 0.01 * rng.standard_normal(4 * N)
    data = PeriodicData(period[:, None, None], out[:, None, None], FS, lines)
    bla = estimate_bla(data)
    _, G_true = freqz(B, A, worN=2 * np.pi * lines / (4 * N))
    assert bla.P == 1 and bla.method == "lpm"
    assert np.mean(np.abs(bla.G - G_true) < 3 * np.sqrt(bla.var_noise)) >= 0.95


def test_lpm_degrees_of_freedom_check() -> None:
    rng = np.random.default_rng(0)
    u = rng.standard_normal((64, 2, 1))
    with pytest.raises(ValueError, match="degrees of freedom"):
        lpm_periodic(u, u, np.array([3]), np.array([3]), degree=2, n_per_side=1)

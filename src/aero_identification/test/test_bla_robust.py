"""Robust BLA (Pintelon & Schoukens 2012 §4.3.1) against simulated systems with known truth."""

from collections.abc import Callable

import numpy as np
import pytest
from scipy.signal import freqz, lfilter

from aero_identification import BLA, PeriodicData, estimate_bla
from aero_identification.bla import detection_lines
from aero_identification.periodic_data import random_phase_period

N, P, M = 512, 4, 8
FS = 200.0
B, A = [0.05, 0.05], [1.0, -1.6, 0.7]  # 2nd-order low-pass, steady state after ~20 samples


def odd_lines_random_skip(rng: np.random.Generator, n_groups: int) -> np.ndarray:
    """Odd lines 1, 3, 5, … with one randomly skipped per group of 3 (detection lines)."""
    odd = np.arange(1, 6 * n_groups, 2).reshape(n_groups, 3)
    skip = rng.integers(0, 3, n_groups)
    keep = np.ones_like(odd, dtype=bool)
    keep[np.arange(n_groups), skip] = False
    return odd[keep]


def simulate(
    rng: np.random.Generator,
    lines: np.ndarray,
    static: Callable[[np.ndarray], np.ndarray],
    sigma: float,
) -> PeriodicData:
    """Wiener system: linear filter, static map, white output noise; steady state only."""
    u = np.empty((N, P, M))
    y = np.empty((N, P, M))
    for m in range(M):
        period = random_phase_period(rng, N, lines)
        period /= period.std()
        record = np.tile(period, P + 2)
        out = static(lfilter(B, A, record))[2 * N :]  # discard two periods of transient
        u[:, :, m] = record[2 * N :].reshape(P, N).T
        y[:, :, m] = (out + sigma * rng.standard_normal(out.size)).reshape(P, N).T
    return PeriodicData(u, y, FS, lines)


def test_linear_system_recovers_frf_and_noise_variance() -> None:
    rng = np.random.default_rng(11)
    lines = odd_lines_random_skip(rng, 25)
    sigma = 0.02
    data = simulate(rng, lines, lambda x: x, sigma)
    bla = estimate_bla(data)
    assert bla.method == "robust" and (bla.M, bla.P, bla.N) == (M, P, N)
    _, G_true = freqz(B, A, worN=2 * np.pi * lines / N)
    np.testing.assert_allclose(bla.freq, lines * FS / N)
    z = np.abs(bla.G - G_true) / np.sqrt(bla.var_noise)
    assert np.mean(z < 3) >= 0.95
    # True noise variance of the mean G: noise variance per DFT bin is σ² (1/√N scaling),
    # divided by |U|² per period, averaged over P periods and M realizations.
    var_true = np.sum(sigma**2 / (P * np.abs(bla.U_mean) ** 2), axis=1) / M**2
    assert np.mean(bla.var_noise) / np.mean(var_true) == pytest.approx(1.0, abs=0.2)
    # Linear system: realizations differ by noise only, no stochastic nonlinear variance.
    assert np.mean(bla.var_total) / np.mean(bla.var_noise) == pytest.approx(1.0, abs=0.25)
    assert np.mean(bla.var_nl) < 0.4 * np.mean(bla.var_noise)  # E[max(χ² excess, 0)] ≈ 0.2
    # No nonlinear distortion: var_total exceeds var_noise only by chance, so var_nl, their
    # difference clamped at 0 (bla.py), is 0 on about half the lines.
    assert 0.3 <= np.mean(bla.var_nl == 0) <= 0.8
    # Non-excited lines hold noise only: their level matches the noise level.
    noise_at = dict(zip(bla.noise_lines, bla.noise_level, strict=True))
    for lines_nl, level in ((bla.odd_lines, bla.odd_nl_level), (bla.even_lines, bla.even_nl_level)):
        noise = np.array([noise_at[k] for k in lines_nl])
        assert np.mean(level**2) / np.mean(noise**2) == pytest.approx(1.0, abs=0.35)
    # SNR per line is |G|² over the noise variance of the mean.
    np.testing.assert_allclose(bla.snr, np.abs(bla.G) ** 2 / bla.var_noise)


def level_over_noise(bla: BLA, which: str) -> float:
    lines = getattr(bla, f"{which}_lines")
    level = getattr(bla, f"{which}_nl_level")
    noise = bla.noise_level[np.searchsorted(bla.noise_lines, lines)]
    return float(np.mean(level**2) / np.mean(noise**2))


def test_wiener_cubic_shows_odd_not_even_distortion_and_square_adds_even() -> None:
    rng = np.random.default_rng(5)
    lines = odd_lines_random_skip(rng, 25)
    cubic = estimate_bla(simulate(rng, lines, lambda x: x + 0.5 * x**3, 0.01))
    assert level_over_noise(cubic, "odd") > 30.0
    assert level_over_noise(cubic, "even") == pytest.approx(1.0, abs=0.4)
    # Stochastic nonlinear distortions make realizations differ: var_nl well above noise.
    assert np.mean(cubic.var_nl) > 10 * np.mean(cubic.var_noise)
    assert np.median(cubic.snr_nl) < np.median(cubic.snr)
    square = estimate_bla(simulate(rng, lines, lambda x: x + 0.5 * x**3 + 0.3 * x**2, 0.01))
    assert level_over_noise(square, "even") > 30.0


def test_detection_lines_of_odd_multisine() -> None:
    odd, even = detection_lines(np.array([1, 5, 7, 11]), 12)
    np.testing.assert_array_equal(odd, [3, 9])
    np.testing.assert_array_equal(even, [2, 4, 6, 8, 10, 12])
    # Lines on a grid of 2 (two signal periods per record): off-grid bins are noise only.
    odd, even = detection_lines(np.array([2, 6, 10]), 12)
    np.testing.assert_array_equal(odd, [])
    np.testing.assert_array_equal(even, [4, 8, 12])


def test_robust_needs_two_periods_and_realizations() -> None:
    rng = np.random.default_rng(0)
    data = PeriodicData(rng.standard_normal((64, 3, 1)), rng.standard_normal((64, 3, 1)), 1.0, [1])
    with pytest.raises(ValueError, match="2 realizations"):
        estimate_bla(data, method="robust")
    with pytest.raises(ValueError, match="method must be"):
        estimate_bla(data, method="welch")


def test_line_without_input_power_is_refused() -> None:
    rng = np.random.default_rng(1)
    lines = np.array([1, 3, 5])
    data = simulate(rng, lines, lambda x: x, 0.01)
    wrong = PeriodicData(data.u, data.y, FS, [1, 3, 5, 7])  # 7 is not excited
    with pytest.raises(ValueError, match=r"no power at excited line\(s\) \[7\]"):
        estimate_bla(wrong)
    with pytest.raises(ValueError, match=r"no power at excited line\(s\) \[7\]"):
        estimate_bla(wrong, method="lpm")


def test_realizations_with_different_period_counts_use_all_their_periods() -> None:
    """A periods mask with P_m periods in realization m (e.g. a dominant cluster that holds 2
    periods of one realization and 4 of another): G[m] and its noise variance come from all of
    realization m's P_m periods (Pintelon & Schoukens 2012 §4.3.1 with P per realization)."""
    rng = np.random.default_rng(5)
    lines = odd_lines_random_skip(rng, 25)
    sigma = 0.02
    data = simulate(rng, lines, lambda x: x, sigma)
    mask = np.ones((P, M), dtype=bool)
    mask[:2, ::2] = False  # even realizations keep their last 2 periods, odd ones all 4
    bla = estimate_bla(data, periods=mask)
    counts = mask.sum(axis=0)
    assert bla.period_counts == tuple(counts.tolist()) and bla.P == 2
    assert bla.periods_text == "+".join(map(str, counts))
    np.testing.assert_allclose(bla.U_mean[:, 0], data.U[lines][:, 2:, 0].mean(axis=1))
    np.testing.assert_allclose(bla.U_mean[:, 1], data.U[lines][:, :, 1].mean(axis=1))
    # Noise variance of the mean G: realization m contributes σ²/(P_m |U_m|²), over M².
    var_true = np.sum(sigma**2 / (counts * np.abs(bla.U_mean) ** 2), axis=1) / M**2
    assert np.mean(bla.var_noise) / np.mean(var_true) == pytest.approx(1.0, abs=0.2)
    # Truncating every realization to 2 periods (the equal-count estimate) is noisier: in
    # expectation by Σ 1/2 against Σ 1/P_m over the realizations, 4/3 here.
    truncated = estimate_bla(data.select(mask))
    assert truncated.P == 2 and truncated.period_counts == ()
    assert 1.1 < np.mean(truncated.var_noise) / np.mean(bla.var_noise) < 1.6
    _, G_true = freqz(B, A, worN=2 * np.pi * lines / N)
    assert np.mean(np.abs(bla.G - G_true) / np.sqrt(bla.var_noise) < 3) >= 0.95


def test_a_mask_with_equal_counts_is_the_estimate_of_those_periods() -> None:
    rng = np.random.default_rng(6)
    lines = odd_lines_random_skip(rng, 25)
    data = simulate(rng, lines, lambda x: x + 0.3 * x**3, 0.02)
    mask = np.zeros((P, M), dtype=bool)
    mask[1:, :] = True
    mask[0, 3], mask[1, 3] = True, False  # not the same positions in every realization
    bla, alone = estimate_bla(data, periods=mask), estimate_bla(data.select(mask))
    for name in ("G", "var_noise", "var_total", "U_mean", "noise_level", "odd_nl_level"):
        np.testing.assert_array_equal(getattr(bla, name), getattr(alone, name))
    assert bla.period_counts == () and bla.P == 3


def test_a_periods_mask_is_checked() -> None:
    rng = np.random.default_rng(7)
    lines = odd_lines_random_skip(rng, 10)
    data = simulate(rng, lines, lambda x: x, 0.02)
    one = np.ones((P, M), dtype=bool)
    one[1:, 0] = False  # realization 0 keeps one period: no noise estimate
    with pytest.raises(ValueError, match=r"at least 2 periods in every realization"):
        estimate_bla(data, periods=one)
    with pytest.raises(ValueError, match=r"boolean \(P, M\)"):
        estimate_bla(data, periods=np.ones((P, M + 1), dtype=bool))
    with pytest.raises(ValueError, match=r"robust method"):
        estimate_bla(data, method="lpm", periods=np.ones((P, M), dtype=bool))

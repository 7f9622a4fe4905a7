"""Validation metrics and the nonparametric BLA's prediction of single-sine responses."""

from typing import Any

import numpy as np

from aero_identification.bla import BLA


def relative_rms_error(y_true: np.ndarray, y_hat: np.ndarray) -> float:
    """Relative RMS error rms(y − ŷ) / rms(y − mean y) (docs/design.md §7, the paper's Table 1).

    Args:
        y_true: measured output, any shape.
        y_hat: predicted output, same shape.

    Returns:
        The ratio: 0 for a perfect prediction, 1 for predicting the mean.

    Raises:
        ValueError: for different shapes, empty or non-finite data, or a constant y_true.
    """
    y_true = np.asarray(y_true, dtype=float)
    y_hat = np.asarray(y_hat, dtype=float)
    if y_true.shape != y_hat.shape:
        raise ValueError(
            f"y_true and y_hat must have the same shape; got {y_true.shape} and {y_hat.shape}"
        )
    if y_true.size == 0:
        raise ValueError("y_true is empty")
    if not (np.all(np.isfinite(y_true)) and np.all(np.isfinite(y_hat))):
        raise ValueError("y_true or y_hat contains NaN or inf (a diverged simulation?)")
    spread = np.sqrt(np.mean((y_true - y_true.mean()) ** 2))
    if spread == 0:
        raise ValueError("y_true is constant: the relative RMS error is undefined")
    return float(np.sqrt(np.mean((y_true - y_hat) ** 2)) / spread)


def relative_rms_error_spread(
    y_true: np.ndarray, y_hat: np.ndarray, samples_per_period: int
) -> float:
    """Spread of the relative RMS error over the periods of a periodic record (Table 1's ±).

    The record is cut into its P periods of ``samples_per_period`` samples; for each period p
    the relative RMS error e_p = rms(y_p − ŷ_p) / rms(y_p − mean y_p) (`relative_rms_error`
    applied to that period alone, centred on the period's own mean); the spread is their sample
    standard deviation (ddof = 1) over the P periods. It measures the cycle-to-cycle variation
    and noise of the measured record, not the variability of the model's training. The error
    itself (Table 1's value) stays `relative_rms_error` over the whole record.

    Args:
        y_true: (P·samples_per_period,) measured output, whole periods.
        y_hat: predicted output, same shape.
        samples_per_period: samples in one period (≥ 1).

    Returns:
        std over the periods of e_p (ddof = 1); NaN for a single period (undefined).

    Raises:
        ValueError: for different shapes, a record that is not 1-D or not whole periods, a
            non-positive ``samples_per_period``, or a period that `relative_rms_error` rejects
            (empty, non-finite, constant).
    """
    y_true = np.asarray(y_true, dtype=float)
    y_hat = np.asarray(y_hat, dtype=float)
    if y_true.shape != y_hat.shape:
        raise ValueError(
            f"y_true and y_hat must have the same shape; got {y_true.shape} and {y_hat.shape}"
        )
    if y_true.ndim != 1:
        raise ValueError(f"expected 1-D records; got shape {y_true.shape}")
    n = int(samples_per_period)
    if n < 1 or n != samples_per_period:
        raise ValueError(f"samples_per_period must be a positive integer; got {samples_per_period}")
    if y_true.size == 0 or y_true.size % n:
        raise ValueError(f"the record's {y_true.size} samples are not whole periods of {n} samples")
    periods = y_true.size // n
    errors = [
        relative_rms_error(y_true[p * n : (p + 1) * n], y_hat[p * n : (p + 1) * n])
        for p in range(periods)
    ]
    if periods < 2:
        return float("nan")
    return float(np.std(errors, ddof=1))


def noise_floor(y_true: np.ndarray, samples_per_period: int) -> float:
    """The lowest relative RMS error a deterministic model of the input can reach on a periodic
    record: its periods' scatter about their own mean period, in Table 1's units.

    With y_p = g + n_p (p = 1 … P; g the periodic response to the periodic input, n_p the noise
    and the cycle-to-cycle variation, independent over the periods with variance σ²), the
    residual of the sample mean period ȳ = (1/P) Σ y_p has E[(y_p − ȳ)²] = σ² (P − 1)/P, so

        floor = √(P/(P − 1)) · rms(y − ȳ) / rms(y − mean y)

    estimates σ / rms(y − mean y): the relative RMS error of the true periodic response g itself
    (the sample variance over the periods of a periodic measurement, [Pintelon2012]). Its
    denominator is `relative_rms_error`'s, over the whole record.

    Args:
        y_true: (P·samples_per_period,) measured output, whole periods, P ≥ 2.
        samples_per_period: samples in one period.

    Returns:
        The floor, ≥ 0.

    Raises:
        ValueError: for a record that is not 1-D or not whole periods, fewer than 2 periods,
            non-finite data or a constant record.
    """
    y = np.asarray(y_true, dtype=float)
    n = int(samples_per_period)
    if y.ndim != 1 or n < 1 or n != samples_per_period or y.size == 0 or y.size % n:
        raise ValueError(
            f"expected a 1-D record of whole periods of {samples_per_period} samples; got shape "
            f"{y.shape}"
        )
    periods = y.size // n
    if periods < 2:
        raise ValueError("the noise floor needs at least 2 periods")
    if not np.all(np.isfinite(y)):
        raise ValueError("y_true contains NaN or inf")
    by_period = y.reshape(periods, n)
    residual = by_period - by_period.mean(axis=0)
    spread = np.sqrt(np.mean((y - y.mean()) ** 2))
    if spread == 0:
        raise ValueError("y_true is constant: the relative RMS error is undefined")
    return float(np.sqrt(np.mean(residual**2) * periods / (periods - 1)) / spread)


def interpolate_frf(bla: BLA, freq_hz: float | np.ndarray) -> np.ndarray:
    """BLA at arbitrary frequencies inside the excited band.

    Magnitude and unwrapped phase are interpolated linearly between the excited lines
    (interpolating the complex value would shrink the magnitude between lines where the phase
    turns).

    Raises:
        ValueError: for a frequency outside [first, last] excited line (no extrapolation).
    """
    f = np.asarray(freq_hz, dtype=float)
    lo, hi = float(bla.freq[0]), float(bla.freq[-1])
    if np.any(f < lo * (1 - 1e-12)) or np.any(f > hi * (1 + 1e-12)):
        raise ValueError(
            f"frequency {freq_hz} Hz lies outside the excited band {lo:g} … {hi:g} Hz of the "
            "BLA; the nonparametric FRF cannot be extrapolated (use a parametric model)"
        )
    magnitude = np.interp(f, bla.freq, np.abs(bla.G))
    phase = np.interp(f, bla.freq, np.unwrap(np.angle(bla.G)))
    return magnitude * np.exp(1j * phase)


def sine_component(u: np.ndarray, fs: float, freq_hz: float) -> tuple[complex, float]:
    """Least-squares fit u[t] ≈ c + Re(A exp(j2πf t/fs)); returns (A, c).

    Exact (the DFT bin) for a record of whole sine periods; also fine otherwise.
    """
    u = np.asarray(u, dtype=float).reshape(-1)
    if u.size < 3:
        raise ValueError(f"need at least 3 samples to fit a sine; got {u.size}")
    t = np.arange(u.size) / fs
    w = 2 * np.pi * freq_hz
    basis = np.column_stack([np.ones_like(t), np.cos(w * t), np.sin(w * t)])
    (c, a, b), *_ = np.linalg.lstsq(basis, u, rcond=None)
    return complex(a, -b), float(c)


def predict_bla_sine(
    bla: BLA, freq_hz: float, u: np.ndarray, y_mean: float, fs: float | None = None
) -> np.ndarray:
    """Response of the nonparametric BLA to a measured single-sine input record.

    The sine component of `u` at `freq_hz` (least squares, `sine_component`) is multiplied by
    the BLA interpolated at that frequency (`interpolate_frf`). The BLA maps deviations around
    the operating point, so the static offset of the prediction is the measured mean of y over
    the record, passed as `y_mean` (the paper's Table 1 treats all three model kinds alike).
    Harmonics in u other than the sine are ignored.

    Args:
        bla: the BLA estimate.
        freq_hz: the sine frequency [Hz], inside the excited band.
        u: (T,) measured input record, whole sine periods, sampled at `fs`.
        y_mean: measured mean of the output over the same record.
        fs: sampling frequency of u [Hz]; default bla.fs.

    Returns:
        (T,) predicted output ŷ[t] = y_mean + Re(G(f)·A·exp(j2πf t/fs)).
    """
    fs = bla.fs if fs is None else float(fs)
    amplitude, _ = sine_component(u, fs, freq_hz)
    G = complex(interpolate_frf(bla, freq_hz))
    t = np.arange(np.asarray(u).size) / fs
    return y_mean + np.real(G * amplitude * np.exp(2j * np.pi * freq_hz * t))


def steady_state_response(model: Any, u: np.ndarray, samples_per_period: int) -> np.ndarray:
    """A model's periodic steady-state output to the periodic record ``u``: the record's last
    period is simulated first (the start-up transient) and dropped from the output."""
    u_ext = np.concatenate([u[-samples_per_period:], u])
    return np.asarray(model.simulate(u_ext))[samples_per_period:]

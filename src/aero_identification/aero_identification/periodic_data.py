"""Periodic input/output records: samples × periods × realizations, period-wise spectra.

A multisine experiment yields, per phase realization m, P consecutive periods of N samples of
input u (pitch angle) and output y (lift coefficient). `PeriodicData` holds them as arrays of
shape (N, P, M) and provides what the nonparametric methods need: the period-wise DFTs, selection
of periods (after clustering) and of realizations, and a transient check.

DFT convention (the 1/√N scaling of Pintelon & Schoukens 2012):

    U[k, p, m] = (1/√N) Σ_{t=0}^{N-1} u[t, p, m] exp(-j 2π k t / N),   k = 0 … N/2

so white noise of variance σ² has E|U[k]|² = σ² at every bin, and a sine of amplitude A on bin k
has |U[k]| = A √N / 2. Bin k is the frequency k·fs/N Hz.
"""

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np


@dataclass(frozen=True, eq=False)
class PeriodicData:
    """Steady-state periodic records of one SISO experiment.

    Attributes:
        u: (N, P, M) input samples (N per period, P periods, M phase realizations).
        y: (N, P, M) output samples, same layout as `u`.
        fs: sampling frequency [Hz].
        excited_lines: (F,) DFT bin indices of the excited frequencies, each in 1 … ⌈N/2⌉-1
            (the frequency of line k is k·fs/N).
        period_index: (P, M) index of each held period in the original record (bookkeeping
            after `select` / `drop_leading`, for plots and status messages). Defaults to
            0 … P-1 in every realization.
        realization_index: (M,) index of each held realization in the original record.
    """

    u: np.ndarray
    y: np.ndarray
    fs: float
    excited_lines: np.ndarray
    # None = the default layout, filled in by __post_init__ (never None afterwards).
    period_index: np.ndarray = field(default=None)  # type: ignore[arg-type]  # see above
    realization_index: np.ndarray = field(default=None)  # type: ignore[arg-type]  # see above

    def __post_init__(self) -> None:
        u = np.asarray(self.u, dtype=float)
        y = np.asarray(self.y, dtype=float)
        if u.ndim == 2:
            raise ValueError(
                f"u has shape {u.shape}; PeriodicData needs (N, P, M) = samples × periods × "
                "realizations. For a single realization use u[:, :, None]."
            )
        if u.ndim != 3 or y.ndim != 3:
            raise ValueError(
                f"u and y must be 3-D arrays (N, P, M) = samples × periods × realizations; "
                f"got u.shape={u.shape}, y.shape={y.shape}"
            )
        if u.shape != y.shape:
            raise ValueError(
                f"u and y must have the same shape (N, P, M); got u.shape={u.shape}, "
                f"y.shape={y.shape}. Cut both records to the same whole periods."
            )
        N, P, M = u.shape
        if N < 4 or P < 1 or M < 1:
            raise ValueError(f"need N >= 4 samples per period, P >= 1, M >= 1; got {u.shape}")
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise ValueError(
                "u or y contains NaN or inf; exclude the affected periods before building "
                "PeriodicData (a period with a missing sample must not be patched)"
            )
        fs = float(self.fs)
        if not np.isfinite(fs) or fs <= 0:
            raise ValueError(f"fs must be a positive sampling frequency in Hz; got {self.fs}")
        lines = np.asarray(self.excited_lines)
        if lines.ndim != 1 or lines.size == 0:
            raise ValueError(
                f"excited_lines must be a non-empty 1-D array of DFT bin indices; got shape "
                f"{lines.shape}"
            )
        if not np.issubdtype(lines.dtype, np.integer):
            if not np.all(lines == np.round(lines)):
                raise ValueError(
                    "excited_lines must be integer DFT bin indices (frequency / (fs/N)), not Hz"
                )
            lines = lines.astype(np.int64)
        lines = lines.astype(np.int64)
        if np.any(lines < 1) or np.any(2 * lines >= N):
            raise ValueError(
                f"excited_lines must lie in 1 … {(N - 1) // 2} (above DC, below Nyquist N/2 "
                f"with N={N}); got min {lines.min()}, max {lines.max()}"
            )
        if np.any(np.diff(lines) <= 0):
            raise ValueError("excited_lines must be strictly increasing and without duplicates")
        if self.period_index is None:
            period_index = np.repeat(np.arange(P)[:, None], M, axis=1)
        else:
            period_index = np.asarray(self.period_index, dtype=np.int64)
            if period_index.shape != (P, M):
                raise ValueError(
                    f"period_index must have shape (P, M)={(P, M)}; got {period_index.shape}"
                )
        if self.realization_index is None:
            realization_index = np.arange(M)
        else:
            realization_index = np.asarray(self.realization_index, dtype=np.int64)
            if realization_index.shape != (M,):
                raise ValueError(
                    f"realization_index must have shape (M,)={(M,)}; got {realization_index.shape}"
                )
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "y", y)
        object.__setattr__(self, "fs", fs)
        object.__setattr__(self, "excited_lines", lines)
        object.__setattr__(self, "period_index", period_index)
        object.__setattr__(self, "realization_index", realization_index)

    # --- sizes -------------------------------------------------------------------------------
    @property
    def N(self) -> int:
        """Samples per period."""
        return int(self.u.shape[0])

    @property
    def P(self) -> int:
        """Periods per realization."""
        return int(self.u.shape[1])

    @property
    def M(self) -> int:
        """Phase realizations."""
        return int(self.u.shape[2])

    @property
    def freq(self) -> np.ndarray:
        """(N//2+1,) frequency of every DFT bin [Hz]."""
        return np.arange(self.N // 2 + 1) * self.fs / self.N

    @property
    def excited_freq(self) -> np.ndarray:
        """(F,) frequencies of the excited lines [Hz]."""
        return self.excited_lines * self.fs / self.N

    # --- spectra -----------------------------------------------------------------------------
    @cached_property
    def U(self) -> np.ndarray:
        """(N//2+1, P, M) complex period-wise input DFT, 1/√N scaling (module docstring)."""
        return np.fft.rfft(self.u, axis=0) / np.sqrt(self.N)

    @cached_property
    def Y(self) -> np.ndarray:
        """(N//2+1, P, M) complex period-wise output DFT, 1/√N scaling (module docstring)."""
        return np.fft.rfft(self.y, axis=0) / np.sqrt(self.N)

    # --- selection ---------------------------------------------------------------------------
    def select(self, keep: np.ndarray, min_periods: int = 2) -> "PeriodicData":
        """Keep only the periods marked in `keep` (e.g. the dominant cluster).

        The (N, P, M) layout holds the same number of periods in every realization, so:
        realizations with fewer than `min_periods` kept periods are dropped, and the others are
        truncated to the smallest kept count, retaining the LATEST kept periods of each (they are
        the furthest from any start-up transient). Kept periods need not be consecutive: in
        periodic steady state every period is a valid period. To use every kept period of
        realizations that keep different counts, pass the mask to `bla.estimate_bla(periods=)`
        instead (what the pipeline does).

        Args:
            keep: (P, M) boolean mask, True = keep (what `cluster_periods` returns).
            min_periods: fewest kept periods for a realization to be retained.

        Returns:
            A new PeriodicData of shape (N, P', M'); `period_index` and `realization_index`
            record which original periods and realizations it holds.

        Raises:
            ValueError: if `keep` has the wrong shape or no realization keeps `min_periods`.
        """
        keep = np.asarray(keep)
        if keep.shape != (self.P, self.M) or keep.dtype != bool:
            raise ValueError(
                f"keep must be a boolean (P, M)={(self.P, self.M)} mask; got dtype {keep.dtype} "
                f"and shape {keep.shape}"
            )
        if min_periods < 1:
            raise ValueError(f"min_periods must be >= 1; got {min_periods}")
        counts = keep.sum(axis=0)
        retained = np.flatnonzero(counts >= min_periods)
        if retained.size == 0:
            raise ValueError(
                f"no realization keeps at least {min_periods} periods (kept per realization: "
                f"{counts.tolist()}); record more periods or lower min_periods"
            )
        P_new = int(counts[retained].min())
        cols = [np.flatnonzero(keep[:, m])[-P_new:] for m in retained]
        idx_p = np.stack(cols, axis=1)  # (P_new, M_new) positions within this record
        idx_m = retained[None, :]
        return PeriodicData(
            u=self.u[:, idx_p, idx_m],
            y=self.y[:, idx_p, idx_m],
            fs=self.fs,
            excited_lines=self.excited_lines,
            period_index=self.period_index[idx_p, idx_m],
            realization_index=self.realization_index[retained],
        )

    def select_realizations(self, realizations: np.ndarray | list[int]) -> "PeriodicData":
        """Keep the realizations at the given positions (0 … M-1), in the given order."""
        idx = np.asarray(realizations, dtype=np.int64).reshape(-1)
        if idx.size == 0 or np.any(idx < 0) or np.any(idx >= self.M):
            raise ValueError(
                f"realizations must be a non-empty list of indices in 0 … {self.M - 1}; got "
                f"{idx.tolist()}"
            )
        return PeriodicData(
            u=self.u[:, :, idx],
            y=self.y[:, :, idx],
            fs=self.fs,
            excited_lines=self.excited_lines,
            period_index=self.period_index[:, idx],
            realization_index=self.realization_index[idx],
        )

    def drop_leading(self, n_periods: int) -> "PeriodicData":
        """Drop the first `n_periods` periods of every realization (e.g. a transient)."""
        if not 0 <= n_periods < self.P:
            raise ValueError(
                f"n_periods must be in 0 … P-1 = {self.P - 1} to leave at least one period; got "
                f"{n_periods}"
            )
        return PeriodicData(
            u=self.u[:, n_periods:, :],
            y=self.y[:, n_periods:, :],
            fs=self.fs,
            excited_lines=self.excited_lines,
            period_index=self.period_index[n_periods:, :],
            realization_index=self.realization_index,
        )


def transient_ratio(data: PeriodicData, n_ref: int = 2) -> np.ndarray:
    """Power of each period's difference from the steady state, relative to the noise.

    The last `n_ref` periods of each realization are taken as steady state: their mean is the
    reference waveform and their period-to-period variance the noise variance σ² (pooled over
    the samples of the period). For an earlier period p the ratio is

        mean_t (x[t, p, m] − ref[t, m])² / (σ² (1 + 1/n_ref)),

    whose expectation is 1 in steady state (the denominator is the variance of the difference of
    a noisy period and the mean of n_ref noisy periods) and larger with a transient. It is
    evaluated for the input and the output and the larger is returned.

    Returns:
        (P, M) ratios; the last `n_ref` rows (the reference periods) are NaN.

    Raises:
        ValueError: if there are fewer than n_ref + 1 periods or n_ref < 2.
    """
    if n_ref < 2:
        raise ValueError(f"n_ref must be >= 2 to estimate the noise variance; got {n_ref}")
    if data.P < n_ref + 1:
        raise ValueError(
            f"the transient check needs more periods than the {n_ref} reference periods; got "
            f"P={data.P}. Record more periods or lower n_ref."
        )
    ratios = np.full((data.P, data.M), np.nan)
    for x in (data.u, data.y):
        tail = x[:, -n_ref:, :]
        ref = tail.mean(axis=1)  # (N, M)
        var_noise = np.var(tail, axis=1, ddof=1).mean(axis=0)  # (M,)
        # Noise-free records (simulations) would divide by zero: floor at round-off level.
        floor = 1e-24 * np.maximum(np.mean(x**2, axis=(0, 1)), 1e-300)
        var_noise = np.maximum(var_noise, floor)
        head = x[:, :-n_ref, :]
        diff_power = np.mean((head - ref[:, None, :]) ** 2, axis=0)  # (P - n_ref, M)
        r = diff_power / (var_noise * (1.0 + 1.0 / n_ref))
        ratios[:-n_ref] = np.fmax(ratios[:-n_ref], r)
    return ratios


def transient_periods(data: PeriodicData, n_ref: int = 2, threshold: float = 2.0) -> int:
    """Number of leading periods to drop because they still hold a start-up transient.

    A period is transient when its `transient_ratio` exceeds `threshold` (default 2: the
    difference from steady state carries as much power again as the noise; far above the
    ≈ √(2/N) relative scatter of the ratio in steady state). The count returned is, over all
    realizations, the first period index from which no earlier-than-reference period is
    flagged any more, so dropping it (`PeriodicData.drop_leading`) leaves steady-state periods.

    Returns:
        int in 0 … P − n_ref.
    """
    if threshold <= 1.0:
        raise ValueError(
            f"threshold must exceed 1 (the expected ratio in steady state); got {threshold}"
        )
    flagged = transient_ratio(data, n_ref)[:-n_ref] > threshold  # (P - n_ref, M)
    n_drop = 0
    for m in range(data.M):
        idx = np.flatnonzero(flagged[:, m])
        if idx.size:
            n_drop = max(n_drop, int(idx[-1]) + 1)
    return n_drop


def random_phase_period(rng: np.random.Generator, N: int, lines: np.ndarray) -> np.ndarray:
    """One period (N,) of a random-phase multisine: unit amplitude on the DFT bins ``lines``,
    phases uniform in [0, 2π) drawn from ``rng``, nothing elsewhere (scale it as needed).
    For test signals and warm-ups; experiment plans come from multisine_gen."""
    X = np.zeros(N // 2 + 1, complex)
    X[lines] = np.exp(2j * np.pi * rng.random(len(lines)))
    return np.fft.irfft(X, N)

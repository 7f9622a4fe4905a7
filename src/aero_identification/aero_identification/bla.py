"""Best linear approximation (BLA) of a SISO system from periodic multisine data.

The robust method (Pintelon & Schoukens, System Identification: A Frequency Domain Approach,
2nd ed., 2012, §4.3.1; Pintelon et al., MSSP 24(3), 2010) over M random-phase realizations of
P periods each separates, per excited line, the noise variance from the variance due to the
stochastic nonlinear distortions. The non-excited (detection) lines of an odd multisine show the
level of odd and even nonlinear distortions in the output spectrum.
"""

from dataclasses import dataclass

import numpy as np

from aero_identification.lpm import frf_variance, lpm_periodic
from aero_identification.periodic_data import PeriodicData


@dataclass(frozen=True, eq=False)
class BLA:
    """Nonparametric BLA estimate with its variances and output-spectrum levels (SISO).

    Variance convention (docs/design.md §7): every variance below is of the MEAN estimate `G` as
    returned, i.e. averaged over M realizations and P periods. To get the variance of the FRF of
    one realization G[m] (averaged over its P periods) multiply by M; of the FRF of one period
    of one realization G[m, p] multiply the noise part by M·P. `var_total` includes the
    stochastic nonlinear distortions (they differ between realizations, not between periods),
    `var_noise` only the disturbing noise.

    Attributes:
        fs: sampling frequency [Hz].
        N: samples per period.
        lines: (F,) int DFT bin indices of the excited lines (frequency = lines·fs/N).
        freq: (F,) frequencies of the excited lines [Hz].
        G: (F,) complex BLA at the excited lines (output units per input unit).
        var_noise: (F,) noise variance of G (of the mean over M·P periods).
        var_total: (F,) total variance of G (noise + stochastic nonlinear distortions), of the
            mean over M realizations. With method "lpm" and M == 1 it cannot be told from the
            noise and equals `var_noise` (see `estimate_bla`).
        var_nl: (F,) max(var_total - var_noise, 0): variance of G due to the stochastic
            nonlinear distortions, of the mean.
        M: number of realizations used.
        P: number of periods per realization used (the fewest, when `period_counts` differ).
        U_mean: (F, M) complex input spectrum at the excited lines, averaged over the periods of
            each realization (1/√N DFT scaling, see periodic_data.py).
        Y_mean: (F, M) complex output spectrum at the excited lines, same averaging.
        excited_level: (F,) RMS over realizations of |Y_mean| at the excited lines (Fig. 6).
        odd_lines, odd_freq: (F_o,) non-excited odd detection lines in the band, and their Hz.
        odd_nl_level: (F_o,) RMS over realizations of the period-averaged |Y| at the odd
            detection lines: odd nonlinear distortions (plus noise at `noise_level`).
        even_lines, even_freq: (F_e,) non-excited even lines in the band, and their Hz.
        even_nl_level: (F_e,) same as `odd_nl_level` at the even lines: even distortions.
        noise_lines, noise_freq: (F_n,) lines where the noise level is given, and their Hz:
            every line 1 … max_line (only the excited lines for the LPM with P == 1).
        noise_level: (F_n,) standard deviation of the period-averaged Y due to noise (robust:
            √(mean_m var_p(Y[k, p, m]) / P); LPM: from the local-polynomial residuals);
            comparable with the three levels above (a line with only noise has an expected
            level equal to `noise_level`).
        method: "robust" or "lpm".
        period_counts: periods used in each realization when they differ (`estimate_bla`'s
            ``periods``); empty when every realization used `P`.
    """

    fs: float
    N: int
    lines: np.ndarray
    freq: np.ndarray
    G: np.ndarray
    var_noise: np.ndarray
    var_total: np.ndarray
    var_nl: np.ndarray
    M: int
    P: int
    U_mean: np.ndarray
    Y_mean: np.ndarray
    excited_level: np.ndarray
    odd_lines: np.ndarray
    odd_freq: np.ndarray
    odd_nl_level: np.ndarray
    even_lines: np.ndarray
    even_freq: np.ndarray
    even_nl_level: np.ndarray
    noise_lines: np.ndarray
    noise_freq: np.ndarray
    noise_level: np.ndarray
    method: str = "robust"
    period_counts: tuple[int, ...] = ()

    @property
    def periods_per_realization(self) -> tuple[int, ...]:
        """(M,) periods used in each realization."""
        return self.period_counts or (self.P,) * self.M

    @property
    def periods_text(self) -> str:
        """Periods per realization for reports: "6", or "2+5" when they differ."""
        return "+".join(map(str, self.period_counts)) if self.period_counts else str(self.P)

    @property
    def snr(self) -> np.ndarray:
        """(F,) signal-to-noise ratio |G|²/var_noise per excited line (power ratio)."""
        with np.errstate(divide="ignore"):
            return np.abs(self.G) ** 2 / self.var_noise

    @property
    def snr_nl(self) -> np.ndarray:
        """(F,) signal-to-nonlinear-distortion ratio |G|²/var_nl per excited line (inf where no
        nonlinear distortion is detected)."""
        with np.errstate(divide="ignore"):
            return np.abs(self.G) ** 2 / self.var_nl


def detection_lines(excited_lines: np.ndarray, max_line: int) -> tuple[np.ndarray, np.ndarray]:
    """Odd and even non-excited lines of the excitation grid up to `max_line`.

    The grid is the greatest common divisor g of the excited lines (g = 1 for the usual odd
    multisine on odd bins). Harmonic h = k/g of a line k on the grid is odd or even; an odd
    nonlinearity driven by odd harmonics only produces odd harmonics, an even one only even
    harmonics (Pintelon & Schoukens 2012 §4.3.2), so non-excited odd-h lines show the odd
    distortions and even-h lines the even ones. Lines off the grid carry noise only.

    Returns:
        (odd_lines, even_lines): int arrays of DFT bin indices, ascending.
    """
    excited = np.asarray(excited_lines, dtype=np.int64)
    g = int(np.gcd.reduce(excited))
    grid = np.arange(g, max_line + 1, g)
    grid = grid[~np.isin(grid, excited)]
    h = grid // g
    return grid[h % 2 == 1], grid[h % 2 == 0]


def weak_lines(U_abs: np.ndarray) -> np.ndarray:
    """(F,) bool: lines without input power in some column of the (F, ...) |U|, more than
    120 dB below the strongest (Y/U would be inf or noise over noise there)."""
    U_abs = U_abs.reshape(U_abs.shape[0], -1)
    if U_abs.size == 0 or U_abs.max() <= 0:
        return np.ones(U_abs.shape[0], dtype=bool)
    return np.any(U_abs <= 1e-6 * U_abs.max(), axis=1)


def _check_input_power(U_abs: np.ndarray, lines: np.ndarray) -> None:
    """Refuse lines without input power (`weak_lines`)."""
    weak = weak_lines(U_abs)
    if np.any(weak):
        raise ValueError(
            f"the input has (almost) no power at excited line(s) {lines[weak][:10]}"
            " (more than 120 dB below the strongest line); check excited_lines against the "
            "excitation plan (they are DFT bins of one period: frequency·N/fs)"
        )


def frf_noise_variance(G_mp: np.ndarray) -> np.ndarray:
    """Noise variance of the robust BLA from the (F, P, M) per-period FRFs, P >= 2: the sample
    variance over the periods of each realization, divided by P for the period average and by M
    for the realization average (Pintelon & Schoukens 2012 §4.3.1; docs/design.md §7). With
    M = 1 it is the noise variance of one realization's FRF (the adaptive rules' figure)."""
    _, P, M = G_mp.shape
    G_m = G_mp.mean(axis=1, keepdims=True)
    return np.sum(np.abs(G_mp - G_m) ** 2, axis=(1, 2)) / (M**2 * P * (P - 1))


def estimate_bla(
    data: PeriodicData,
    method: str = "auto",
    degree: int = 2,
    n_per_side: int | None = None,
    max_line: int | None = None,
    periods: np.ndarray | None = None,
) -> BLA:
    """Estimate the BLA, its noise and nonlinear-distortion variances and the output levels.

    Methods:
        "robust": Pintelon & Schoukens 2012 §4.3.1, formulas of docs/design.md §7. Per period
            G[m, p] = Y/U at the excited lines; G[m] = mean_p G[m, p]; G = mean_m G[m];
            var_noise = (1/M²) Σ_m Σ_p |G[m,p] − G[m]|² / (P(P−1));
            var_total = Σ_m |G[m] − G|² / (M(M−1)). Needs P ≥ 2 and M ≥ 2 and steady state
            (drop transient periods first, see `transient_periods`).
        "lpm": the Local Polynomial Method per realization (lpm.py) removes the transient and
            estimates the noise variance from the non-periodic DFT bins of the whole record;
            G[m] = Ȳ_m / Ū_m (transient-corrected period means) with its errors-in-variables
            noise variance; G and var_total over realizations as above. With M == 1,
            var_total = var_noise (nonlinear distortions cannot be told from one realization)
            and var_nl = 0. Works with P == 1 (then the "noise" includes the nonlinear
            distortions at the neighbouring non-excited lines).
        "auto": "robust" when M ≥ 2 and P ≥ 2, otherwise "lpm".

    Args:
        data: periodic records (N, P, M).
        method: "auto", "robust" or "lpm".
        degree, n_per_side: LPM polynomial degree and neighbours per side (see lpm.py).
        max_line: highest DFT line of the band for the odd/even/noise levels; default the
            highest excited line.
        periods: (P, M) boolean mask of the periods to use (e.g. the dominant cluster's), at
            least 2 in every realization; robust method only. Realizations may use different
            numbers of periods P_m: G[m] is the mean over its P_m periods and its noise
            variance Σ_p |G[m,p] − G[m]|² / (P_m(P_m−1)), so var_noise = (1/M²) Σ_m of those
            (the formulas above with P per realization). With equal counts this is the
            estimate of those periods alone (`PeriodicData.select`).

    Returns:
        BLA (variances of the mean estimate; see the BLA docstring for the M, P factors).

    Raises:
        ValueError: for an unknown method, or "robust" with P < 2 or M < 2, or a ``periods``
            mask of the wrong shape or with fewer than 2 periods in a realization.
    """
    if periods is not None:
        periods = np.asarray(periods)
        if periods.shape != (data.P, data.M) or periods.dtype != bool:
            raise ValueError(
                f"periods must be a boolean (P, M)={(data.P, data.M)} mask; got dtype "
                f"{periods.dtype} and shape {periods.shape}"
            )
        counts = periods.sum(axis=0)
        if counts.min() < 2 or method == "lpm":
            raise ValueError(
                "a periods mask needs the robust method and at least 2 periods in every "
                f"realization (periods per realization: {counts.tolist()})"
            )
        if np.all(counts == counts[0]):  # equal counts: the estimate of those periods alone
            return estimate_bla(data.select(periods), "robust", degree, n_per_side, max_line)
    N, P, M = data.N, data.P, data.M
    lines = data.excited_lines
    if max_line is None:
        max_line = int(lines.max())
    if not int(lines.max()) <= max_line < (N + 1) // 2:
        raise ValueError(
            f"max_line must lie between the highest excited line {lines.max()} and "
            f"{(N - 1) // 2}; got {max_line}"
        )
    if method == "auto":
        method = "robust" if (M >= 2 and P >= 2) else "lpm"
    if method not in ("robust", "lpm"):
        raise ValueError(f'method must be "auto", "robust" or "lpm"; got {method!r}')
    odd_lines, even_lines = detection_lines(lines, max_line)
    band = np.arange(1, max_line + 1)

    if method == "robust":
        if P < 2 or M < 2:
            raise ValueError(
                f"the robust BLA needs at least 2 periods and 2 realizations (got P={P}, "
                f'M={M}); use method="lpm" for a single realization or a single period'
            )
        U = data.U[lines]  # (F, P, M)
        Y = data.Y[lines]
        Y_band = data.Y[band]  # (K, P, M)
        if periods is None:
            _check_input_power(np.abs(U).min(axis=1), lines)
            G_mp = Y / U
            G_m = G_mp.mean(axis=1)  # (F, M)
            var_noise = frf_noise_variance(G_mp)
            U_mean = U.mean(axis=1)
            Y_mean = Y.mean(axis=1)
            # Levels of the period-averaged output spectrum over the band (Fig. 6 of the paper).
            Y_band_mean = Y_band.mean(axis=1)
            var_Y_band_mean = np.var(Y_band, axis=1, ddof=1).mean(axis=1) / P
        else:  # P_m periods in realization m (docstring)
            U_mean = np.empty((lines.size, M), dtype=complex)
            Y_mean = np.empty_like(U_mean)
            G_m = np.empty_like(U_mean)
            var_noise = np.zeros(lines.size)
            Y_band_mean = np.empty((band.size, M), dtype=complex)
            var_Y_band_mean = np.zeros(band.size)
            for m in range(M):
                use = np.flatnonzero(periods[:, m])
                U_m, Y_m = U[:, use, m], Y[:, use, m]
                _check_input_power(np.abs(U_m).min(axis=1), lines)
                G_mp = Y_m / U_m
                G_m[:, m] = G_mp.mean(axis=1)
                var_noise += frf_noise_variance(G_mp[:, :, None])  # of G[m]
                U_mean[:, m], Y_mean[:, m] = U_m.mean(axis=1), Y_m.mean(axis=1)
                Y_band_mean[:, m] = Y_band[:, use, m].mean(axis=1)
                var_Y_band_mean += np.var(Y_band[:, use, m], axis=1, ddof=1) / use.size / M
            var_noise /= M**2
            P = int(periods.sum(axis=0).min())
        noise_lines = band
    else:
        if P >= 2:
            targets = band
        else:
            targets = lines  # single period: LPM only at the excited lines (see lpm.py)
        res = lpm_periodic(data.u, data.y, targets, lines, degree=degree, n_per_side=n_per_side)
        at_exc = np.searchsorted(targets, lines)
        U_mean = res.U[at_exc]
        Y_mean = res.Y[at_exc]
        _check_input_power(np.abs(U_mean), lines)
        G_m = Y_mean / U_mean
        var_G_m = frf_variance(
            G_m, U_mean, res.var_U[at_exc], res.var_Y[at_exc], res.cov_YU[at_exc]
        )
        var_noise = var_G_m.sum(axis=1) / M**2
        if P >= 2:
            Y_band_mean = res.Y
        else:
            Y_band_mean = data.Y[band].mean(axis=1)
        var_Y_band_mean = res.var_Y.mean(axis=1)
        noise_lines = targets

    G = G_m.mean(axis=1)
    if M >= 2:
        var_total = np.sum(np.abs(G_m - G[:, None]) ** 2, axis=1) / (M * (M - 1))
    else:
        var_total = var_noise.copy()
    var_nl = np.maximum(var_total - var_noise, 0.0)

    def level(k: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean(np.abs(Y_band_mean[k - 1]) ** 2, axis=1))

    f0 = data.fs / N
    return BLA(
        fs=data.fs,
        N=N,
        lines=lines.copy(),
        freq=lines * f0,
        G=G,
        var_noise=var_noise,
        var_total=var_total,
        var_nl=var_nl,
        M=M,
        P=P,
        U_mean=U_mean,
        Y_mean=Y_mean,
        excited_level=np.sqrt(np.mean(np.abs(Y_mean) ** 2, axis=1)),
        odd_lines=odd_lines,
        odd_freq=odd_lines * f0,
        odd_nl_level=level(odd_lines),
        even_lines=even_lines,
        even_freq=even_lines * f0,
        even_nl_level=level(even_lines),
        noise_lines=noise_lines,
        noise_freq=noise_lines * f0,
        noise_level=np.sqrt(var_Y_band_mean),
        method=method,
        period_counts=() if periods is None else tuple(int(c) for c in periods.sum(axis=0)),
    )


def bla_levels_db(bla: BLA, freq_hz: float = 1.02, half_band_hz: float = 0.1) -> dict[str, float]:
    """The paper's §3.3 figures of a BLA, in dB: SNR and SNLR near `freq_hz`, distortion levels.

    snr_db = 10 log10(mean |G|² / mean var_noise) and snlr_db = 10 log10(mean |G|² / mean
    var_nl) over the excited lines within `half_band_hz` of `freq_hz` (the FRF against its noise
    and nonlinearity curves, paper Fig. 7; variances of the mean estimate G, as in BLA).
    odd_db, even_db, noise_db: RMS level of the odd and even detection lines and of the noise
    (over the band), relative to the RMS excited-line output level (paper Fig. 6). Values are
    NaN where a quantity is absent (no line in the band, var_nl = 0: +inf).
    """
    near = np.abs(bla.freq - freq_hz) <= half_band_hz
    if not near.any():
        raise ValueError(f"no excited line within {half_band_hz} Hz of {freq_hz} Hz")
    g2 = float(np.mean(np.abs(bla.G[near]) ** 2))

    def ratio_db(num: float, den: float) -> float:
        if den <= 0.0:
            return float("inf")
        return float(10.0 * np.log10(num / den))

    def level_db(level: np.ndarray) -> float:
        if level.size == 0:
            return float("nan")
        return float(20.0 * np.log10(np.sqrt(np.mean(level**2)) / reference))

    reference = float(np.sqrt(np.mean(bla.excited_level**2)))
    return {
        "freq_hz": float(np.mean(bla.freq[near])),
        "snr_db": ratio_db(g2, float(np.mean(bla.var_noise[near]))),
        "snlr_db": ratio_db(g2, float(np.mean(bla.var_nl[near]))),
        "odd_db": level_db(bla.odd_nl_level),
        "even_db": level_db(bla.even_nl_level),
        "noise_db": level_db(bla.noise_level),
    }

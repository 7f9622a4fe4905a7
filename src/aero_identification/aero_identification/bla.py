"""Best linear approximation (BLA) of a SISO system from periodic multisine data.

The robust method (Pintelon & Schoukens, System Identification: A Frequency Domain Approach,
2nd ed., 2012, §4.3.1; Pintelon et al., MSSP 24(3), 2010) over M random-phase realizations of
P periods each separates, per excited line, the noise variance from the variance due to the
stochastic nonlinear distortions. The non-excited (detection) lines of an odd multisine show the
level of odd and even nonlinear distortions in the output spectrum.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class BLA:
    """Nonparametric BLA estimate with its variances and output-spectrum levels (SISO).

    Variance convention (DESIGN.md §7): every variance below is of the MEAN estimate `G` as
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
        P: number of periods per realization used.
        U_mean: (F, M) complex input spectrum at the excited lines, averaged over the periods of
            each realization (1/√N DFT scaling, see data.py).
        Y_mean: (F, M) complex output spectrum at the excited lines, same averaging.
        excited_level: (F,) RMS over realizations of |Y_mean| at the excited lines (Fig. 6).
        odd_lines, odd_freq: (F_o,) non-excited odd detection lines in the band, and their Hz.
        odd_nl_level: (F_o,) RMS over realizations of the period-averaged |Y| at the odd
            detection lines: odd nonlinear distortions (plus noise at `noise_level`).
        even_lines, even_freq: (F_e,) non-excited even lines in the band, and their Hz.
        even_nl_level: (F_e,) same as `odd_nl_level` at the even lines: even distortions.
        noise_lines, noise_freq: (F_n,) every line 1 … max(lines) and its Hz.
        noise_level: (F_n,) standard deviation of the period-averaged Y due to noise,
            √(mean_m var_p(Y[k, p, m]) / P); comparable with the three levels above (a line
            with only noise has an expected level equal to `noise_level`).
        method: "robust" or "lpm".
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

"""Local Polynomial Method (LPM) for periodic excitation: transient removal and noise variance.

Pintelon, Schoukens, Vandersteen, Barbé, "Estimation of nonparametric noise and FRF models for
multivariable systems — Part I: Theory", MSSP 24(3), 2010, 573–595; applied to periodic signals
as in Pintelon et al., "Improved (non-)parametric identification of dynamic systems excited by
periodic signals", MSSP 25(7), 2011, and Pintelon & Schoukens 2012, §7.2.

The DFT of the whole record of P periods (N·P samples) puts the steady-state periodic response
only on the bins that are multiples of P. The other bins hold only the transient (a smooth
function of frequency: a rational function of exp(jω_k), Pintelon & Schoukens 2012 ch. 6)
plus noise. Around each target bin we fit a polynomial of degree R in the bin offset to
the nearest non-periodic bins: its value at the target estimates the transient there, and its
residuals estimate the local noise variance (and input/output covariance).

With P == 1 there are no such bins; the nearest non-excited lines are used instead. They carry
the nonlinear distortions too, so the estimated "noise" variance then includes them.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class LPMResult:
    """Transient-corrected period-mean spectra with their noise (co)variances.

    All spectra are on the per-period 1/√N DFT scale of periodic_data.py, i.e. comparable with
    the mean over periods of PeriodicData.U / .Y; variances are of that period mean.

    Attributes:
        lines: (L,) per-period DFT bin indices at which the LPM was evaluated.
        U, Y: (L, M) complex transient-corrected period-mean input and output spectra.
        T_U, T_Y: (L, M) complex estimated transient contributions that were removed.
        var_U, var_Y: (L, M) noise variance of U and Y (of the period mean, including the
            uncertainty of the subtracted transient estimate).
        cov_YU: (L, M) complex noise covariance E[N_Y conj(N_U)] of the period means.
        degree: polynomial degree R.
        dof: residual degrees of freedom per line (neighbours − (R+1)).
    """

    lines: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    T_U: np.ndarray
    T_Y: np.ndarray
    var_U: np.ndarray
    var_Y: np.ndarray
    cov_YU: np.ndarray
    degree: int
    dof: int


def lpm_periodic(
    u: np.ndarray,
    y: np.ndarray,
    lines: np.ndarray,
    excited_lines: np.ndarray,
    degree: int = 2,
    n_per_side: int | None = None,
) -> LPMResult:
    """Estimate and remove the transient at the given lines of periodic records by the LPM.

    Args:
        u, y: (N, P, M) input and output, P consecutive periods per realization.
        lines: (L,) per-period bin indices where corrected spectra are wanted (for P == 1 these
            must not be non-excited lines, which serve as the neighbours).
        excited_lines: (F,) excited per-period bin indices (used only when P == 1).
        degree: degree R of the local polynomial (Pintelon 2010 use R = 2).
        n_per_side: neighbouring bins per side of each line (total 2·n_per_side); default
            R + 2, giving R + 3 residual degrees of freedom.

    Returns:
        LPMResult at `lines`.

    Raises:
        ValueError: if the degrees of freedom are below 1 or there are too few neighbours.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.ndim != 3 or u.shape != y.shape:
        raise ValueError(f"u and y must both be (N, P, M); got {u.shape} and {y.shape}")
    N, P, M = u.shape
    if degree < 0:
        raise ValueError(f"degree must be >= 0; got {degree}")
    if n_per_side is None:
        n_per_side = degree + 2
    q = 2 * n_per_side
    dof = q - (degree + 1)
    if dof < 1:
        raise ValueError(
            f"LPM needs more neighbours than polynomial coefficients: 2·n_per_side={q} lines "
            f"for degree {degree} leaves {dof} degrees of freedom; raise n_per_side to at "
            f"least {(degree + 2 + 1) // 2} or lower the degree"
        )
    lines = np.asarray(lines, dtype=np.int64)
    n_long = N * P
    # Record of all periods in time order: (N·P, M); 1/√(NP) scaling keeps white-noise
    # variance per bin equal to the sample variance, as for the per-period DFT.
    u_long = u.transpose(1, 0, 2).reshape(n_long, M)
    y_long = y.transpose(1, 0, 2).reshape(n_long, M)
    U_long = np.fft.rfft(u_long, axis=0) / np.sqrt(n_long)
    Y_long = np.fft.rfft(y_long, axis=0) / np.sqrt(n_long)
    n_bins = U_long.shape[0]
    all_bins = np.arange(1, n_bins - 1)  # neither DC nor Nyquist
    if P >= 2:
        # Only transient and noise live off the multiples of P (Pintelon et al. 2011).
        candidates = all_bins[all_bins % P != 0]
    else:
        excited = np.asarray(excited_lines, dtype=np.int64)
        if np.setdiff1d(lines, excited).size:
            raise ValueError(
                "with a single period the LPM uses the non-excited lines as neighbours, so it "
                "can only be evaluated at excited lines"
            )
        candidates = np.setdiff1d(all_bins, excited)
    if candidates.size < q:
        raise ValueError(
            f"only {candidates.size} non-periodic bins available but the LPM needs {q} "
            "neighbours per line; record more samples or lower n_per_side"
        )
    targets = lines * P
    pos = np.searchsorted(candidates, targets)
    # Symmetric window where possible, shifted inwards at the band edges.
    start = np.clip(pos - n_per_side, 0, candidates.size - q)
    neighbours = candidates[start[:, None] + np.arange(q)]  # (L, q)
    r = (neighbours - targets[:, None]) / float(P)  # offsets in per-period lines
    K = r[..., None] ** np.arange(degree + 1)  # (L, q, R+1)
    K_pinv = np.linalg.pinv(K)  # (L, R+1, q)
    # Polynomial value at offset 0 is its constant coefficient: T̂ = w · Y_neighbours.
    w = K_pinv[:, 0, :]  # (L, q)
    hat = K @ K_pinv  # (L, q, q)

    def correct(X_long: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        X_nb = X_long[neighbours]  # (L, q, M)
        T = np.einsum("lq,lqm->lm", w, X_nb)
        resid = X_nb - hat @ X_nb
        return X_long[targets] - T, T, resid

    Uc, T_U, res_U = correct(U_long)
    Yc, T_Y, res_Y = correct(Y_long)
    # Residual (co)variances are unbiased with dof = q − (R+1) (least-squares residuals,
    # Pintelon et al. 2010 §3); the corrected value also carries the variance of the
    # transient estimate, factor (1 + ‖w‖²).
    inflate = (1.0 + np.sum(w**2, axis=1))[:, None]
    var_U_long = np.sum(np.abs(res_U) ** 2, axis=1) / dof * inflate
    var_Y_long = np.sum(np.abs(res_Y) ** 2, axis=1) / dof * inflate
    cov_long = np.sum(res_Y * np.conj(res_U), axis=1) / dof * inflate
    # Long-record bin P·k equals √P times the period mean at line k (1/√N vs 1/√(NP) scaling).
    sq = np.sqrt(P)
    return LPMResult(
        lines=lines,
        U=Uc / sq,
        Y=Yc / sq,
        T_U=T_U / sq,
        T_Y=T_Y / sq,
        var_U=var_U_long / P,
        var_Y=var_Y_long / P,
        cov_YU=cov_long / P,
        degree=degree,
        dof=dof,
    )


def frf_variance(
    G: np.ndarray, U: np.ndarray, var_U: np.ndarray, var_Y: np.ndarray, cov_YU: np.ndarray
) -> np.ndarray:
    """First-order noise variance of G = Y/U with noisy input and output.

    var(G) ≈ (σ²_Y + |G|²σ²_U − 2 Re(conj(G)·σ²_YU)) / |U|²
    (first-order linearisation of Y/U with correlated input/output noise, as in Pintelon &
    Schoukens 2012 ch. 2). Shapes broadcast; returns a non-negative array.
    """
    num = var_Y + np.abs(G) ** 2 * var_U - 2.0 * np.real(np.conj(G) * cov_YU)
    return np.maximum(num, 0.0) / np.abs(U) ** 2

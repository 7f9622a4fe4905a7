"""Crest factor of an excitation and its reduction by iterative clipping.

The crest factor max|u − ū| / std(u) sets how far the peaks of a signal go for a given power
(P&S 2012 §3.2): a lower one lets the same standard deviation stay further from the actuator
limits and the stall angle. Reduction by clipping (Van der Ouderaa, Schoukens & Renneboog,
IEEE Trans. Instrum. Meas. 37(1), 1988): clip the period in time, take the phases of its
spectrum at the excited lines, restore the amplitudes there and zero elsewhere; repeat and keep
the best. Only the phases change, so the excited lines, detection lines, amplitudes and the
standard deviation are exactly those of the input multisine.
"""

import numpy as np

from multisine_gen.multisine import ExcitationError, Multisine

__all__ = ["reduce_crest_factor"]


def reduce_crest_factor(
    multisine: Multisine, iterations: int = 200, clip_fraction: float = 0.8
) -> Multisine:
    """The multisine with phases that lower its crest factor (never raise it).

    Args:
        multisine: the starting realization (its random phases seed the search).
        iterations: clipping/projection rounds; cost ≈ 2 FFTs of N per round.
        clip_fraction: each round clips at this fraction of the current peak (0 < c < 1).

    Returns a Multisine with the same lines, amplitudes, offset, std and seed and new phases.
    """
    if not 0.0 < clip_fraction < 1.0:
        raise ExcitationError(f"clip_fraction must be in (0, 1), got {clip_fraction}")
    if iterations < 1:
        raise ExcitationError(f"iterations must be >= 1, got {iterations}")
    N, lines = multisine.N, multisine.excited_lines
    line_spectrum = 0.5 * N * multisine.amplitudes  # rfft scaling of a_k cos(·)
    phases = multisine.phases.copy()
    best_phases, best_peak = phases, np.inf
    X = np.zeros(N // 2 + 1, dtype=complex)
    for _ in range(iterations):
        X[lines] = line_spectrum * np.exp(1j * phases)
        x = np.fft.irfft(X, n=N)
        peak = float(np.max(np.abs(x)))
        if peak < best_peak:
            best_peak, best_phases = peak, phases
        level = clip_fraction * peak
        phases = np.angle(np.fft.rfft(np.clip(x, -level, level))[lines])
    return multisine.with_phases(best_phases, seed=multisine.seed)

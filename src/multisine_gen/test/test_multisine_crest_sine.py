"""Crest-factor reduction keeps lines and amplitudes exactly and lowers the crest factor; single
sines sit on the sample grid."""

import math

import numpy as np
import pytest

from multisine_gen.crest import reduce_crest_factor
from multisine_gen.multisine import ExcitationError, crest_factor, odd_random_phase_multisine
from multisine_gen.sine import design_sine


def test_crest_factor_reduction_keeps_lines_and_amplitudes_and_lowers_the_crest_factor() -> None:
    ms = odd_random_phase_multisine(200.0, 10_000, 0.02, 1.98, std_deg=2.4, offset_deg=19.9, seed=8)
    reduced = reduce_crest_factor(ms, iterations=100)
    np.testing.assert_array_equal(reduced.excited_lines, ms.excited_lines)
    np.testing.assert_array_equal(reduced.detection_lines, ms.detection_lines)
    np.testing.assert_array_equal(reduced.amplitudes, ms.amplitudes)
    assert reduced.offset_deg == ms.offset_deg and reduced.std_deg == ms.std_deg
    X = np.fft.rfft(reduced.period() - reduced.offset_deg)
    A = 2.0 * np.abs(X) / ms.N
    np.testing.assert_allclose(A[ms.excited_lines], ms.amplitudes, rtol=1e-10)
    assert np.all(np.delete(A, ms.excited_lines) < 1e-10 * A.max())
    assert np.std(reduced.period()) == pytest.approx(2.4, rel=1e-12)
    # Random phases over 38 lines give a crest factor ≈ 2.7–4; clipping brings it near 1.7.
    assert reduced.crest_factor() < 0.8 * ms.crest_factor()
    assert reduced.crest_factor() < 2.0
    assert reduced.crest_factor() == pytest.approx(crest_factor(reduced.period()), rel=1e-12)


def test_crest_factor_of_known_waveforms() -> None:
    n = np.arange(400)
    assert crest_factor(np.sin(2 * np.pi * n / 400 + 0.3)) == pytest.approx(math.sqrt(2), rel=1e-4)
    assert crest_factor(np.sign(np.sin(2 * np.pi * (n + 0.5) / 400))) == pytest.approx(1.0)
    with pytest.raises(ExcitationError, match="constant"):
        crest_factor(np.ones(10))


def test_sine_has_whole_samples_per_period_and_a_single_line() -> None:
    sine = design_sine(200.0, 1.6, amplitude_deg=4.7, offset_deg=5.9)
    assert sine.samples_per_period == 125 and sine.frequency_hz == 1.6
    u = sine.samples(4)
    assert u.shape == (500,) and u[0] == 5.9 and u[1] > u[0]  # starts at the offset, going up
    A = 2.0 * np.abs(np.fft.rfft(u - 5.9)) / u.size
    assert A[4] == pytest.approx(4.7, rel=1e-12)
    assert np.all(np.delete(A, 4) < 1e-12)
    assert np.mean(u) == pytest.approx(5.9, abs=1e-12)


def test_sine_frequency_that_does_not_fit_is_adjusted_or_refused() -> None:
    adjusted = design_sine(200.0, 0.3, 1.0)  # 666.7 samples per period
    assert adjusted.samples_per_period == 667
    assert adjusted.frequency_hz == pytest.approx(200.0 / 667)
    assert adjusted.requested_frequency_hz == 0.3
    with pytest.raises(ExcitationError, match=r"0\.29985 Hz and 0\.3003 Hz"):
        design_sine(200.0, 0.3, 1.0, on_mismatch="refuse")
    assert design_sine(200.0, 0.4, 1.0, on_mismatch="refuse").samples_per_period == 500


def test_sine_at_or_above_nyquist_is_refused() -> None:
    with pytest.raises(ExcitationError, match="at or above fs/2"):
        design_sine(200.0, 100.0, 1.0)
    with pytest.raises(ExcitationError, match="at or above fs/2"):
        design_sine(200.0, 99.0, 1.0)  # rounds to 2 samples per period

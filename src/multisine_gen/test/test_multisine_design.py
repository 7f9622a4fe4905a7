"""Odd random-phase multisines: energy only at the chosen lines, exact std and offset,
realizations that differ only in phases, seeded reproducibility, clear errors."""

import numpy as np
import pytest

from multisine_gen.multisine import (
    ExcitationError,
    Multisine,
    design_line_grid,
    odd_random_phase_multisine,
    random_phase_multisine,
)

FS, N = 200.0, 10_000  # the paper: 0.02 Hz resolution


def _line_spectrum(ms: Multisine) -> np.ndarray:
    """|DFT| of one period without offset, as amplitudes a_k (2|X|/N)."""
    return 2.0 * np.abs(np.fft.rfft(ms.period() - ms.offset_deg)) / ms.N


def test_period_has_energy_only_at_the_excited_odd_lines() -> None:
    ms = odd_random_phase_multisine(FS, N, 0.02, 1.98, std_deg=2.4, offset_deg=6.6, seed=1)
    A = _line_spectrum(ms)
    excited = np.flatnonzero(A > 1e-10 * A.max())
    np.testing.assert_array_equal(excited, ms.excited_lines)
    assert np.all(A[np.setdiff1d(np.arange(A.size), ms.excited_lines)] < 1e-10 * A.max())
    np.testing.assert_allclose(A[ms.excited_lines], ms.amplitudes, rtol=1e-10)
    X = np.fft.rfft(ms.period())[ms.excited_lines]
    np.testing.assert_allclose(np.exp(1j * np.angle(X)), np.exp(1j * ms.phases), atol=1e-10)


def test_odd_random_grid_skips_one_odd_line_per_group_of_four() -> None:
    grid = design_line_grid(FS, N, 0.02, 1.98, "odd_random", group_size=4, seed=7)
    odd_in_band = np.arange(1, 100, 2)  # 0.02 … 1.98 Hz are bins 1 … 99
    assert np.all(grid.excited_lines % 2 == 1)
    np.testing.assert_array_equal(np.union1d(grid.excited_lines, grid.detection_lines), odd_in_band)
    assert np.intersect1d(grid.excited_lines, grid.detection_lines).size == 0
    groups = odd_in_band[:48].reshape(12, 4)  # 12 complete groups; 97 and 99 stay excited
    for group in groups:
        assert np.isin(group, grid.detection_lines).sum() == 1
    assert {97, 99} <= set(grid.excited_lines.tolist())
    assert grid.excited_lines.size == 38 and grid.detection_lines.size == 12
    np.testing.assert_allclose(grid.frequencies_hz[[0, -1]], [0.02, 1.98])


def test_detection_lines_are_random_but_seeded() -> None:
    a = design_line_grid(FS, N, 0.02, 1.98, seed=1).detection_lines
    b = design_line_grid(FS, N, 0.02, 1.98, seed=1).detection_lines
    c = design_line_grid(FS, N, 0.02, 1.98, seed=2).detection_lines
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # Not a fixed position in the group (a fixed skip hides some nonlinearities, paper §2.2).
    position = ((a - 1) // 2) % 4
    assert len(set(position.tolist())) > 1


def test_std_and_offset_are_as_asked() -> None:
    ms = odd_random_phase_multisine(FS, N, 0.02, 1.98, std_deg=2.4, offset_deg=15.7, seed=3)
    u = ms.period()
    assert u.shape == (N,)
    assert np.mean(u) == pytest.approx(15.7, abs=1e-12)
    assert np.std(u) == pytest.approx(2.4, rel=1e-12)
    assert ms.std_deg == pytest.approx(2.4, rel=1e-12)


def test_realizations_on_one_grid_differ_only_in_phases() -> None:
    grid = design_line_grid(FS, N, 0.02, 1.98, seed=5)
    r0 = random_phase_multisine(grid, 2.4, 6.6, seed=10)
    r1 = random_phase_multisine(grid, 2.4, 6.6, seed=11)
    np.testing.assert_array_equal(r0.excited_lines, r1.excited_lines)
    np.testing.assert_array_equal(r0.detection_lines, r1.detection_lines)
    np.testing.assert_array_equal(r0.amplitudes, r1.amplitudes)
    assert r0.offset_deg == r1.offset_deg and r0.std_deg == r1.std_deg
    assert np.all(r0.phases != r1.phases)
    assert not np.allclose(r0.period(), r1.period())
    same = random_phase_multisine(grid, 2.4, 6.6, seed=10)
    np.testing.assert_array_equal(same.phases, r0.phases)
    np.testing.assert_array_equal(same.period(), r0.period())


def test_phases_are_uniform_on_the_circle() -> None:
    grid = design_line_grid(1000.0, 100_000, 0.01, 499.0, "full")
    phases = random_phase_multisine(grid, 1.0, seed=4).phases
    assert np.all((phases >= 0.0) & (phases < 2 * np.pi))
    # Mean resultant length of F uniform phases is ~ 1/√F; a bias would show far above.
    assert abs(np.mean(np.exp(1j * phases))) < 4.0 / np.sqrt(phases.size)
    counts, _ = np.histogram(phases, bins=8, range=(0, 2 * np.pi))
    expected = phases.size / 8
    assert np.all(np.abs(counts - expected) < 5 * np.sqrt(expected))


@pytest.mark.parametrize(
    ("kind", "expected"),
    [
        ("full", np.arange(5, 100)),
        ("odd", np.arange(5, 100)[np.arange(5, 100) % 2 == 1]),
        ("even", np.arange(5, 100)[np.arange(5, 100) % 2 == 0]),
    ],
)
def test_full_odd_and_even_variants(kind: str, expected: np.ndarray) -> None:
    grid = design_line_grid(FS, N, 0.1, 1.98, kind)  # type: ignore[arg-type]
    np.testing.assert_array_equal(grid.excited_lines, expected)
    assert grid.detection_lines.size == 0
    ms = random_phase_multisine(grid, 1.0, seed=0)
    A = _line_spectrum(ms)
    assert np.all(np.delete(A, expected) < 1e-10 * A.max())


def test_user_amplitude_spectrum_shape_is_kept_and_scaled_to_std() -> None:
    grid = design_line_grid(FS, N, 0.02, 1.98, seed=0)
    ms = random_phase_multisine(grid, 2.0, seed=0, relative_amplitudes=lambda f: 1.0 / (1 + f))
    expected_shape = 1.0 / (1 + grid.frequencies_hz)
    np.testing.assert_allclose(
        ms.amplitudes / ms.amplitudes[0], expected_shape / expected_shape[0], rtol=1e-12
    )
    assert np.std(ms.period()) == pytest.approx(2.0, rel=1e-12)
    with pytest.raises(ExcitationError, match=r"one value per excited line, shape \(38,\)"):
        random_phase_multisine(grid, 2.0, relative_amplitudes=np.ones(5))


def test_band_at_or_above_nyquist_is_refused() -> None:
    with pytest.raises(ExcitationError, match=r"at or above fs/2 = 100"):
        design_line_grid(FS, N, 0.02, 100.0)
    with pytest.raises(ExcitationError, match="no odd_random DFT line"):
        design_line_grid(FS, 100, 0.5, 1.0)  # resolution 2 Hz
    with pytest.raises(ExcitationError, match=r"0 < k < N/2"):
        Multisine(FS, 100, np.array([10, 50]), np.array([], int), np.ones(2), np.zeros(2), 0.0, 1.0)


def test_record_is_read_only() -> None:
    ms = odd_random_phase_multisine(FS, 2000, 0.1, 1.98, std_deg=1.0, seed=0)
    with pytest.raises(ValueError, match="read-only"):
        ms.phases[0] = 0.0

"""Table 1's estimation bootstrap: the period resampling and the spread over replicates."""

import math

import numpy as np
import pytest

from aero_identification.bootstrap import replicate_spreads, resample_periods
from aero_identification.identification_result import EstimationSpread
from aero_identification.periodic_data import PeriodicData


def _data(P: int = 6, M: int = 2, N: int = 8) -> PeriodicData:
    # Each period is recognisable: its samples all equal 100·m + p (plus a small ramp).
    u = np.zeros((N, P, M))
    y = np.zeros((N, P, M))
    for m in range(M):
        for p in range(P):
            u[:, p, m] = 100 * m + p
            y[:, p, m] = 100 * m + p + 0.01 * np.arange(N)
    return PeriodicData(u, y, fs=10.0, excited_lines=np.array([1]))


def _labels(d: PeriodicData) -> np.ndarray:
    return d.u[0].astype(int)  # (P, M) the label of the period now in each place


def test_kept_periods_are_drawn_from_the_kept_periods_of_their_own_realization() -> None:
    data = _data()
    keep = np.ones((6, 2), dtype=bool)
    keep[[1, 4], 0] = False  # realization 0 keeps 0, 2, 3, 5
    keep[0, 1] = False  # realization 1 keeps 1 … 5
    rng = np.random.default_rng(1)
    seen: set[int] = set()
    for _ in range(50):
        rep = resample_periods(data, keep, rng)
        labels = _labels(rep)
        # The periods the clustering left out stay where they were (no fit uses them).
        assert labels[1, 0] == 1 and labels[4, 0] == 4 and labels[0, 1] == 100
        assert set(labels[keep[:, 0], 0]) <= {0, 2, 3, 5}
        assert set(labels[keep[:, 1], 1]) <= {101, 102, 103, 104, 105}
        # u and y move together, and a period is never a mix of two.
        np.testing.assert_allclose(rep.y - 0.01 * np.arange(8)[:, None, None], rep.u, atol=1e-12)
        # Never one period repeated in every place (the BLA's noise estimate would be 0).
        assert len(set(labels[keep[:, 0], 0])) >= 2
        seen |= set(labels[keep].ravel())
    assert seen == {0, 2, 3, 5, 101, 102, 103, 104, 105}  # with replacement, over all kept
    np.testing.assert_array_equal(rep.period_index, data.period_index)
    np.testing.assert_array_equal(data.u[0].astype(int)[:, 0], np.arange(6))  # input untouched


def test_without_a_mask_every_period_is_resampled_and_a_wrong_mask_is_an_error() -> None:
    data = _data(P=3, M=1)
    labels = {tuple(_labels(resample_periods(data, None, np.random.default_rng(s)))[:, 0])
              for s in range(40)}  # fmt: skip
    assert all(len(set(lab)) >= 2 and set(lab) <= {0, 1, 2} for lab in labels)
    assert len(labels) > 5
    with pytest.raises(ValueError, match="keep mask"):
        resample_periods(data, np.ones((2, 1), dtype=bool), np.random.default_rng(0))


def test_the_bootstrap_std_of_a_period_mean_is_its_standard_error() -> None:
    """Efron & Tibshirani 1993 §6.2: the bootstrap std of a mean of P iid draws tends to
    σ̂·sqrt((P − 1)/P)/sqrt(P), σ̂ the sample std (ddof 1) of the draws."""
    rng = np.random.default_rng(3)
    P, N = 8, 4
    y = rng.normal(size=(N, P, 1))
    data = PeriodicData(np.zeros_like(y), y, fs=1.0, excited_lines=np.array([1]))
    means = [resample_periods(data, None, rng).y[0, :, 0].mean() for _ in range(4000)]
    sigma = y[0, :, 0].std(ddof=1)
    expected = sigma * math.sqrt((P - 1) / P) / math.sqrt(P)
    assert np.std(means, ddof=1) == pytest.approx(expected, rel=0.06)


def test_replicate_spreads_count_failures_and_need_two_values() -> None:
    a, b, c = ("PNLSS", "low", 0.4), ("PNLSS", "high", 1.6), ("BLA SS", "high", 1.0)
    reps = [{a: 0.10, b: 0.5, c: 0.2}, {a: 0.12, b: math.inf}, {a: 0.14, c: 0.3}]
    spreads, means, failed = replicate_spreads(reps, [a, b, c])
    assert spreads[a] == pytest.approx(0.02) and failed[a] == 0
    assert means[a] == pytest.approx(0.12)
    assert math.isnan(spreads[b]) and failed[b] == 2  # one finite value: undefined
    assert means[b] == pytest.approx(0.5)  # the mean of the one finite value
    assert spreads[c] == pytest.approx(np.std([0.2, 0.3], ddof=1)) and failed[c] == 1
    assert means[c] == pytest.approx(0.25)
    _, none, _ = replicate_spreads([{a: math.inf}], [a])
    assert math.isnan(none[a])


def test_the_replicates_mean_estimates_the_plug_in_variances_bias() -> None:
    """Efron & Tibshirani 1993 §10.2: for the plug-in variance (ddof 0) of P draws, the
    bootstrap bias estimate, mean over replicates minus the estimate, tends to −σ̂²/P with σ̂²
    the plug-in variance itself; for the sample mean it tends to 0."""
    rng = np.random.default_rng(5)
    P = 6
    y = rng.normal(size=(4, P, 1))  # the statistic reads the first sample of each period
    data = PeriodicData(np.zeros_like(y), y, fs=1.0, excited_lines=np.array([1]))
    var, mean = ("var", "low", 0.4), ("mean", "low", 0.4)
    reps = []
    for _ in range(4000):
        draw = resample_periods(data, None, rng).y[0, :, 0]
        reps.append({var: float(draw.var()), mean: float(draw.mean())})
    _, means, _ = replicate_spreads(reps, [var, mean])
    theta = float(y[0, :, 0].var())
    # resample_periods redraws a draw of one period repeated everywhere (P^(1-P), negligible).
    assert means[var] - theta == pytest.approx(-theta / P, rel=0.08)
    assert means[mean] - float(y[0, :, 0].mean()) == pytest.approx(0.0, abs=0.03 * y[0].std())


def test_the_note_names_cells_whose_estimate_is_off_the_replicates_mean() -> None:
    """EstimationSpread.off_mean / note: a cell whose error is more than 2 estimation spreads
    from the refits' mean is counted, with its side; the others, and cells without a finite
    mean or spread, are not."""
    a, b, c, d = (("PNLSS", "low", f) for f in (0.4, 1.0, 1.6, 2.0))
    errors = {a: 0.07, b: 0.10, c: 0.30, d: 0.10}
    boot = EstimationSpread(
        replicates=10,
        spreads_all={a: 0.01, b: 0.01, c: 0.02, d: math.nan},
        means_all={a: 0.10, b: 0.115, c: 0.20, d: 0.5},
    )
    off = boot.off_mean(errors)
    assert set(off) == {a, c}  # b: 1.5 spreads; d: no spread
    assert off[a] == pytest.approx(3.0) and off[c] == pytest.approx(-5.0)
    note = boot.note(errors)
    assert "In 2 of 4 cells the error lies more than 2 estimation spreads" in note
    assert "(1 below it, 1 above)" in note
    assert boot.off_mean(errors, level1=True) == {}  # level 1's means: none given
    assert "cells the error lies" not in boot.note(errors, level1=True)

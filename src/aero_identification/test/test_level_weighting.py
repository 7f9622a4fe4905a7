"""The levels' weights in the all-levels PNLSS cost (config.level_weighting, pipeline.py)."""

import dataclasses

import numpy as np
import pytest

from aero_identification.config import IdentificationConfig
from aero_identification.data import PeriodicData
from aero_identification.dataset import LevelRecord
from aero_identification.pipeline import _set_weights, noise_variance, pnlss_sets
from aero_identification.results import LevelResult

N, P, M = 64, 5, 3


def _level(name: str, noise_std: float, seed: int, periods: int = P) -> LevelResult:
    """A level whose output is one periodic signal plus white noise of a known std."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / N
    u = np.broadcast_to(np.sin(2 * np.pi * t)[:, None, None], (N, periods, M)).copy()
    y = 3.0 * u + noise_std * rng.standard_normal((N, periods, M))
    return LevelResult(LevelRecord(name, PeriodicData(u, y, 10.0, np.array([1]))))


def test_noise_variance_is_that_of_the_mean_period() -> None:
    """σ²/P of the simulated noise, within the estimate's scatter (N·P·M = 960 samples)."""
    res = _level("low", noise_std=0.2, seed=1)
    assert noise_variance(res) == pytest.approx(0.04 / P, rel=0.15)


def test_noise_weighting_follows_pnlss_sets_records() -> None:
    """Each training and held-out record gets 1 / its level's noise variance, in the order
    `pnlss_sets` builds them; the quiet level outweighs the noisy one by their variance ratio."""
    levels = [_level("low", 0.05, seed=2), _level("high", 0.5, seed=3)]
    config = dataclasses.replace(IdentificationConfig(), level_weighting="noise")
    data, validation, _ = pnlss_sets(levels, config)
    assert validation is not None
    train, held = _set_weights(levels, config, data, validation)
    assert train is not None and held is not None
    assert train.shape == (data.y.shape[2],) == (2 * (M - 1),)  # M - 1 training realizations
    assert held.shape == (validation.y.shape[2],) == (2,)
    low, high = 1 / noise_variance(levels[0]), 1 / noise_variance(levels[1])
    np.testing.assert_allclose(train, [low, low, high, high])
    np.testing.assert_allclose(held, [low, high])
    assert low / high == pytest.approx(100, rel=0.3)  # (0.5 / 0.05)²


def test_other_weightings_unchanged() -> None:
    """'none' weighs nothing; 'relative' gives 1 / var(each record's output)."""
    levels = [_level("low", 0.05, seed=4), _level("high", 0.5, seed=5)]
    base = IdentificationConfig()
    data, validation, _ = pnlss_sets(levels, base)
    assert _set_weights(levels, base, data, validation) == (None, None)
    rel = dataclasses.replace(base, level_weighting="relative")
    train, _ = _set_weights(levels, rel, data, validation)
    assert train is not None
    np.testing.assert_allclose(train, 1 / np.var(data.y, axis=0).T.reshape(-1))


def test_noise_weighting_needs_two_periods() -> None:
    """One period per realization: no noise estimate, a clear error naming the level."""
    res = _level("medium", 0.1, seed=6, periods=1)
    with pytest.raises(ValueError, match="level medium: level_weighting 'noise' needs two"):
        noise_variance(res)

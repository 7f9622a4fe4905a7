"""The levels' weights in the all-levels PNLSS cost (config.level_weighting, pnlss_training.py)."""

import dataclasses

import numpy as np
import pytest

from aero_identification import pnlss_training
from aero_identification.dataset import Dataset, LevelRecord
from aero_identification.estimation_sets import estimation_sets
from aero_identification.hyperparameters import IdentificationConfig
from aero_identification.identification_result import LevelResult
from aero_identification.periodic_data import PeriodicData, random_phase_period
from aero_identification.pipeline import identify
from aero_identification.pnlss_training import level_weights, noise_variance

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


def test_noise_weighting_follows_estimation_sets_records() -> None:
    """Each training and held-out record gets 1 / its level's noise variance, in the order
    `estimation_sets` builds them; the quiet level outweighs the noisy one by their variance
    ratio."""
    levels = [_level("low", 0.05, seed=2), _level("high", 0.5, seed=3)]
    config = dataclasses.replace(IdentificationConfig(), level_weighting="noise")
    data, validation, _ = estimation_sets(levels, config)
    assert validation is not None
    train, held = level_weights(levels, config, data, validation)
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
    data, validation, _ = estimation_sets(levels, base)
    assert level_weights(levels, base, data, validation) == (None, None)
    rel = dataclasses.replace(base, level_weighting="relative")
    train, _ = level_weights(levels, rel, data, validation)
    assert train is not None
    np.testing.assert_allclose(train, 1 / np.var(data.y, axis=0).T.reshape(-1))


def test_noise_weighting_needs_two_periods() -> None:
    """One period per realization: no noise estimate, a clear error naming the level."""
    res = _level("medium", 0.1, seed=6, periods=1)
    with pytest.raises(ValueError, match="level medium: level_weighting 'noise' needs two"):
        noise_variance(res)


def _dataset(noise_std: tuple[float, float]) -> Dataset:
    """Two levels of a first-order system with a quadratic output term, driven by odd
    random-phase multisines (N 256, 4 periods, 3 realizations), each with its own noise."""
    rng = np.random.default_rng(7)
    n, p, m = 256, 4, 3
    lines = np.arange(1, 40, 2)
    levels = []
    for k, (offset, std) in enumerate(zip((2.0, 6.0), noise_std, strict=True)):
        u = np.empty((n, p, m))
        y = np.empty((n, p, m))
        for r in range(m):
            period = offset + random_phase_period(rng, n, lines) / 0.1
            x = 0.0
            for _ in range(3):  # steady state: the last period of three
                xs = np.empty(n)
                for t in range(n):
                    xs[t] = x
                    x = 0.8 * x + 0.2 * period[t]
            u[:, :, r] = period[:, None]
            y[:, :, r] = (xs + 0.05 * xs**2)[:, None] + std * rng.standard_normal((n, p))
        levels.append(LevelRecord(str(k + 1), PeriodicData(u, y, 10.0, lines), offset_deg=offset))
    return Dataset(fs=10.0, levels=levels)


@pytest.mark.parametrize("scan", [False, True])
def test_identify_passes_noise_weights_to_the_fit(
    scan: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The all-levels fit (single structure or scan) gets 1 / each level's noise variance:
    the quiet level's records outweigh the noisy one's by their variance ratio."""
    seen: list[dict[str, object]] = []

    def capture(*_args: object, **kwargs: object) -> None:
        seen.append(kwargs)
        raise ValueError("captured")  # the pipeline reports it and goes on

    monkeypatch.setattr(pnlss_training, "scan_pnlss" if scan else "fit_pnlss", capture)
    config = dataclasses.replace(
        IdentificationConfig(), level_weighting="noise", scan=scan, clustering=False,
        clustering_ablation=False, scan_nx=(1,), scan_degrees=((2,),), max_iter=2,
    )  # fmt: skip
    result = identify(_dataset((0.01, 0.1)), config, final=True)
    assert any("captured" in w for w in result.warnings)
    weights = [s for s in seen if s["record_weights"] is not None and len(s["record_weights"]) > 2]  # type: ignore[arg-type]
    assert weights, "the all-levels fit got no per-level weights"
    train = np.asarray(weights[-1]["record_weights"])
    held = np.asarray(weights[-1]["validation_weights"])
    expected = [1 / noise_variance(res) for res in result.levels.values()]
    np.testing.assert_allclose(train, np.repeat(expected, 2))  # M - 1 = 2 realizations each
    np.testing.assert_allclose(held, expected)
    assert train[0] / train[-1] == pytest.approx(100, rel=0.3)  # (0.1 / 0.01)²

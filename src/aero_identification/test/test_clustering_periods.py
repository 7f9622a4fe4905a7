"""k-means clustering of periods: two flow regimes split, homogeneous periods stay together."""

import numpy as np

from aero_identification import PeriodicData, cluster_periods
from aero_identification.clustering import common_regime, period_clusters, residual_features
from aero_identification.periodic_data import random_phase_period

N = 400


def regime_data(
    rng: np.random.Generator, P: int, M: int, other_regime: set[tuple[int, int]], sigma: float
) -> PeriodicData:
    """Periodic lift-like output; periods (p, m) in `other_regime` follow a 'stalled' map."""
    lines = np.arange(1, 40, 2)
    u = np.empty((N, P, M))
    y = np.empty((N, P, M))
    for m in range(M):
        alpha = random_phase_period(rng, N, lines)
        alpha /= alpha.std()
        for p in range(P):
            if (p, m) in other_regime:
                cl = 0.6 * alpha - 0.5 + 0.3 * np.abs(alpha)  # lower slope, lift loss
            else:
                cl = alpha + 0.1 * alpha**3
            u[:, p, m] = alpha
            y[:, p, m] = cl + sigma * rng.standard_normal(N)
    return PeriodicData(u, y, 10.0, lines)


def test_two_regimes_split_and_dominant_kept() -> None:
    rng = np.random.default_rng(1)
    stalled = {(p, 0) for p in (1, 4, 6, 9, 10)}  # 5 of 12 periods, spread over time
    data = regime_data(rng, P=12, M=1, other_regime=stalled, sigma=0.05)
    labels, keep = cluster_periods(data)
    expected_keep = np.array([(p, 0) not in stalled for p in range(12)])[:, None]
    np.testing.assert_array_equal(keep, expected_keep)
    np.testing.assert_array_equal(labels, np.where(expected_keep, 0, 1))
    result = period_clusters(data)
    assert result.k == 2 and result.sizes.tolist() == [7, 5] and result.dominant == 0
    assert result.silhouette[2] == max(result.silhouette.values()) > 0.5
    # Deterministic for the seed: the same call gives the same answer.
    labels_again, _ = cluster_periods(data)
    np.testing.assert_array_equal(labels_again, labels)
    # keep is what select accepts: the model data are the 7 attached periods.
    kept = data.select(keep)
    assert kept.P == 7
    np.testing.assert_array_equal(kept.period_index[:, 0], [0, 2, 3, 5, 7, 8, 11])


def test_homogeneous_periods_stay_one_cluster() -> None:
    rng = np.random.default_rng(2)
    data = regime_data(rng, P=6, M=2, other_regime=set(), sigma=0.05)
    result = period_clusters(data)
    assert result.k == 1
    assert np.all(result.keep) and np.all(result.labels == 0)
    assert result.sizes.tolist() == [12]
    # k-means did split (k = 2 … 6 were tried) but no split was real.
    assert result.silhouette and max(result.silhouette.values()) < 0.5


def test_regimes_across_realizations_are_matched_not_split_by_realization() -> None:
    rng = np.random.default_rng(3)
    stalled = {(4, 0), (5, 0), (1, 1)}
    data = regime_data(rng, P=6, M=2, other_regime=stalled, sigma=0.05)
    _, keep = cluster_periods(data)
    expected = np.ones((6, 2), dtype=bool)
    for p, m in stalled:
        expected[p, m] = False
    np.testing.assert_array_equal(keep, expected)
    kept = data.select(keep)
    assert (kept.P, kept.M) == (4, 2)  # truncated to the same count per realization


def test_a_regime_that_is_one_realizations_majority_and_the_others_minority_is_not_kept() -> None:
    # Realization 0 stalls in 4 of its 6 periods, realization 1 in 1 of 6 (plant seed 1 of the
    # default campaign at 19.9°). Each realization's own median lift curve is then a different
    # regime; the kept periods must still be one regime in both realizations.
    rng = np.random.default_rng(5)
    stalled = {(2, 0), (3, 0), (4, 0), (5, 0), (0, 1)}
    data = regime_data(rng, P=6, M=2, other_regime=stalled, sigma=0.05)
    result = period_clusters(data)
    expected = np.ones((6, 2), dtype=bool)
    for p, m in stalled:
        expected[p, m] = False
    np.testing.assert_array_equal(result.keep, expected)
    assert result.k == 2 and result.sizes.tolist() == [7, 5]


def test_the_common_regime_never_is_one_realization_alone() -> None:
    # Homogeneous periods whose realizations differ by a signature (an offset per realization,
    # larger than the noise): the residual features split them by realization, which
    # common_regime must not take as a regime.
    rng = np.random.default_rng(6)
    data = regime_data(rng, P=6, M=2, other_regime=set(), sigma=0.02)
    shifted = data.y.copy()
    shifted[:, :, 1] += 0.2 * np.abs(data.u[:, :, 1])
    data = PeriodicData(data.u, shifted, data.fs, data.excited_lines)
    assert np.all(common_regime(data))
    assert period_clusters(data).k == 1


def test_a_listed_line_without_input_power_stays_out_of_the_residuals_linear_model() -> None:
    # Records may list an excited line the input does not carry (here an even line of an
    # odd multisine): it must not enter the linear model of the residual features.
    rng = np.random.default_rng(7)
    stalled = {(2, 0), (3, 0), (4, 0), (5, 0), (0, 1)}
    data = regime_data(rng, P=6, M=2, other_regime=stalled, sigma=0.05)
    listed = PeriodicData(data.u, data.y, data.fs, np.sort(np.append(data.excited_lines, 2)))
    np.testing.assert_allclose(residual_features(listed), residual_features(data), atol=1e-9)
    keep = period_clusters(listed).keep
    assert not any(keep[p, m] for p, m in stalled) and keep.sum() == 7


def test_identical_periods_without_noise_are_one_cluster() -> None:
    rng = np.random.default_rng(4)
    data = regime_data(rng, P=4, M=1, other_regime=set(), sigma=0.0)
    result = period_clusters(data)
    assert result.k == 1 and np.all(result.keep)

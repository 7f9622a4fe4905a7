"""The adaptive experiment's stop and extend rules (aero_identification.adaptive) on plain
periodic data of a known linear system: converged, not converged, periods split into regimes,
a dominant cluster too small, a model still improving, and the floors."""

from typing import Any

import numpy as np
import pytest

from aero_identification.adaptive import (
    AdaptiveRules,
    Bounds,
    PeriodPosition,
    Verdict,
    judge_period,
)
from aero_identification.periodic_data import PeriodicData

N = 256
LINES = np.arange(1, 60, 2)
RULES = AdaptiveRules(noise_db=(-20.0,), total_db=(-20.0,), min_cluster_periods=8)
BOUNDS = Bounds(min_periods=2, min_realizations=2, max_realizations=3)
LOW = (0, 1)  # offset rank 0 of 1 level


def _records(
    P: int,
    M: int,
    noise: float,
    seed: int = 0,
    gains: list[float] | None = None,
    shift: list[float] | None = None,
    square: float = 0.0,
) -> PeriodicData:
    """(N, P, M) steady-state periods of G(s) = 1/(1 + s/10) driven by random-phase
    multisines: output noise of std ``noise``; realization m's gain ``gains[m]`` (stochastic
    nonlinear distortions: the realizations disagree); period p's output offset ``shift[p]``
    (two regimes, as dynamic stall's, that leave the FRF alone); ``square``: a static
    y + square·y² nonlinearity, whose distortion shows at the even detection lines."""
    rng = np.random.default_rng(seed)
    G = 1.0 / (1.0 + 1j * LINES / 10.0)
    u = np.zeros((N, P, M))
    y = np.zeros((N, P, M))
    for m in range(M):
        U = np.zeros(N // 2 + 1, complex)
        U[LINES] = np.exp(1j * rng.uniform(0, 2 * np.pi, LINES.size))
        one_u = np.fft.irfft(U, N) * np.sqrt(N)
        Y = np.zeros_like(U)
        Y[LINES] = G * U[LINES] * (gains[m] if gains else 1.0)
        one_y = np.fft.irfft(Y, N) * np.sqrt(N)
        one_y = one_y + square * one_y**2
        for p in range(P):
            u[:, p, m] = one_u
            y[:, p, m] = one_y + noise * rng.standard_normal(N) + (shift[p] if shift else 0.0)
    return PeriodicData(u, y, 1.0, LINES)


def _judge(
    current: PeriodicData,
    level: PeriodicData | None,
    rules: AdaptiveRules = RULES,
    errors: list[float] | None = None,
    **kw: Any,
) -> Verdict:
    where: dict[str, Any] = {
        "periods_done": current.P,
        "last_period": False,
        "realization": 0,
        "planned_realizations": 2,
        "rank": LOW,
    }
    position = PeriodPosition(**{**where, **kw})
    return judge_period(current, level, position, rules, BOUNDS, [] if errors is None else errors)


def test_a_converged_realization_ends_and_a_noisy_one_goes_on() -> None:
    quiet = _records(3, 1, noise=0.001)
    verdict = _judge(quiet, None)
    assert verdict.action == "end_realization" and verdict.figures["noise_db"] < -20
    noisy = _records(3, 1, noise=0.3)
    verdict = _judge(noisy, None)
    assert verdict.action == "go_on" and "noise" in verdict.reason
    assert verdict.figures["noise_db"] >= -20


def test_two_periods_of_a_strongly_nonlinear_realization_are_too_few_to_show_regimes() -> None:
    # k-means cannot split 2 periods: where the detection lines show distortion (stall's
    # nonlinearity), the realization goes on to CLUSTER_PERIODS; a linear one ends at 2.
    linear = _judge(_records(2, 1, noise=0.001), None)
    assert linear.action == "end_realization"
    assert linear.figures["distortion_db"] < RULES.distortion_db
    distorted = _records(2, 1, noise=0.001, square=0.3)
    verdict = _judge(distorted, None)
    assert verdict.action == "go_on" and "too few to show a split" in verdict.reason
    assert verdict.figures["distortion_db"] > RULES.distortion_db
    # With three periods the clustering judges, and one regime ends the realization.
    assert _judge(_records(3, 1, noise=0.001, square=0.3), None).action == "end_realization"
    # The threshold is the rules' parameter.
    lenient = AdaptiveRules(noise_db=(-20.0,), total_db=(-20.0,), distortion_db=200.0)
    assert _judge(distorted, None, rules=lenient).action == "end_realization"


def test_never_below_the_floor_of_periods() -> None:
    verdict = _judge(_records(1, 1, noise=0.001), None, periods_done=1)
    assert verdict.action == "go_on" and "at least 2 periods" in verdict.reason


def test_a_realization_whose_periods_split_into_regimes_goes_on() -> None:
    data = _records(6, 1, noise=0.001, shift=[0.0, 0.0, 0.0, 0.0, 3.0, 3.0])
    verdict = _judge(data, None)
    assert verdict.action == "go_on" and "split into regimes" in verdict.reason
    assert verdict.figures["cluster_periods"] == 4


def test_a_converged_level_finishes_or_goes_on_when_its_plan_ends_anyway() -> None:
    level = _records(4, 2, noise=0.001)
    newest = level.select_realizations([1])
    plan_has_more = _judge(newest, level, last_period=True, realization=1, planned_realizations=3)
    assert plan_has_more.action == "finish_level" and "converged" in plan_has_more.reason
    plan_ends = _judge(newest, level, last_period=True, realization=1, planned_realizations=2)
    assert plan_ends.action == "go_on" and "converged" in plan_ends.reason


def test_a_level_whose_realizations_disagree_gets_another_until_the_budget() -> None:
    level = _records(4, 2, noise=0.001, gains=[1.0, 1.6])
    newest = level.select_realizations([1])
    verdict = _judge(newest, level, last_period=True, realization=1, planned_realizations=2)
    assert verdict.action == "add_realization" and "total variance" in verdict.reason
    spent = _records(4, 3, noise=0.001, gains=[1.0, 1.6, 0.7])
    verdict = _judge(
        spent.select_realizations([2]), spent, last_period=True, realization=2,
        planned_realizations=3,
    )  # fmt: skip
    assert verdict.action == "go_on" and "budget (3) is spent" in verdict.reason


def test_a_level_with_too_small_a_dominant_cluster_gets_another_realization() -> None:
    level = _records(4, 2, noise=0.001, shift=[0.0, 0.0, 0.0, 3.0])
    verdict = _judge(
        level.select_realizations([1]), level, last_period=True, realization=1,
        planned_realizations=2,
    )  # fmt: skip
    assert verdict.action == "add_realization"
    assert "dominant cluster 6 < 8" in verdict.reason


def test_a_model_still_improving_on_the_newest_realization_gets_another() -> None:
    level = _records(4, 2, noise=0.001)
    errors = [0.5]  # the previous realization's BLA error: far worse than this one's
    verdict = _judge(
        level.select_realizations([1]), level, last_period=True, realization=1,
        planned_realizations=2, errors=errors,
    )  # fmt: skip
    assert verdict.action == "add_realization" and "still improving" in verdict.reason
    assert len(errors) == 2 and errors[1] < 0.01


def test_never_below_the_floor_of_realizations() -> None:
    one = _records(4, 1, noise=0.001)
    verdict = _judge(one, None, last_period=True, realization=0, planned_realizations=1)
    assert verdict.action == "go_on" and "the floor is 2" in verdict.reason


@pytest.mark.parametrize(("levels", "rank", "value"), [(1, 0, -1.0), (2, 1, -3.0), (3, 1, -2.0)])
def test_thresholds_follow_the_levels_names(levels: int, rank: int, value: float) -> None:
    assert AdaptiveRules.at((-1.0, -2.0, -3.0), rank, levels) == value
    assert AdaptiveRules.at((-5.0,), rank, levels) == -5.0


def test_a_realization_never_ends_below_the_periods_of_the_earlier_ones() -> None:
    quiet = _records(3, 1, noise=0.001)
    verdict = _judge(quiet, None, realization=1, earlier_periods=6)
    assert verdict.action == "go_on" and "3 of the 6 periods" in verdict.reason
    assert _judge(quiet, None, realization=1, earlier_periods=3).action == "end_realization"


def test_a_realization_ends_once_it_has_as_many_periods_as_the_earlier_ones() -> None:
    noisy = _records(3, 1, noise=0.3)  # not converged, but more periods would be discarded
    verdict = _judge(noisy, None, realization=1, earlier_periods=3)
    assert verdict.action == "end_realization" and "as many as the earlier" in verdict.reason

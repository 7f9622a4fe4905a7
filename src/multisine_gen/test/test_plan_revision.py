"""Plan revisions of an adaptive run (multisine_gen.revision): each request changes only what
has not started, keeps every published sample, respects the floors, the budget and the limits,
and a request that cannot be carried out is refused with its reason."""

from typing import Any

import numpy as np
import pytest

from multisine_gen.campaigns import build_plan, short_plan
from multisine_gen.plan import ExperimentPlan, Segment
from multisine_gen.plan_format import plan_from_json, plan_to_json
from multisine_gen.revision import (
    Action,
    Adaptation,
    PlanRequest,
    RefusedRequestError,
    RequestError,
    request_from_fields,
    revise,
)
from rig_runtime.interface import ActuatorLimits

BOUNDS = Adaptation(min_periods=2, min_realizations=2, max_realizations=3)


@pytest.fixture(scope="module")
def short() -> ExperimentPlan:
    return short_plan(seed=3)


def _period(plan: ExperimentPlan, level: int, realization: int, period: int) -> Segment:
    return next(
        s
        for s in plan.segments
        if s.kind == "multisine"
        and (s.level, s.realization, s.period) == (level, realization, period)
    )


def _measured(plan: ExperimentPlan, level: int, realization: int) -> int:
    return sum(
        1
        for s in plan.segments
        if s.kind == "multisine" and (s.level, s.realization) == (level, realization)
    )


def _same_before(old: ExperimentPlan, new: ExperimentPlan, k: int) -> None:
    np.testing.assert_array_equal(old.command_deg()[:k], new.command_deg()[:k])


def test_end_realization_keeps_the_started_periods_and_every_published_sample(
    short: ExperimentPlan,
) -> None:
    p2 = _period(short, 0, 0, 2)
    next_k = p2.start_k + 5  # period 2 of realization 0 is streaming
    rev = revise(short, next_k, PlanRequest("end_realization", 0, p2.start_k - 1), BOUNDS)
    plan = rev.plan
    assert plan.revision == 1 and rev.from_k == p2.stop_k  # a period boundary
    assert _measured(plan, 0, 0) == 3 and _measured(plan, 0, 1) == 4
    assert plan.levels[0].realization_periods == (3, 4)
    _same_before(short, plan, rev.from_k)
    # One period shorter: the next segment is the ramp to the next realization's settling.
    assert plan.total_samples == short.total_samples - p2.length
    after = plan.segment_at(rev.from_k)
    assert after.kind == "ramp"
    assert plan.segment_at(after.stop_k).kind == "settle"  # the settling period stays
    # The revision travels as JSON and rebuilds every sample.
    again = plan_from_json(plan_to_json(plan))
    assert again.revision == 1 and again.levels[0].realization_periods == (3, 4)
    np.testing.assert_array_equal(again.command_deg(), plan.command_deg())


def test_end_realization_never_goes_below_min_periods(short: ExperimentPlan) -> None:
    p0 = _period(short, 1, 0, 0)
    rev = revise(short, p0.start_k + 1, PlanRequest("end_realization", 1, p0.start_k), BOUNDS)
    assert _measured(rev.plan, 1, 0) == 2  # min_periods, although only period 0 started
    with pytest.raises(RefusedRequestError, match="ends after 2 periods already"):
        revise(rev.plan, p0.start_k + 1, PlanRequest("end_realization", 1, 0), BOUNDS)


def test_finish_level_keeps_the_floor_of_realizations() -> None:
    plan = build_plan(N=400, offsets_deg=(6.6, 19.9), realizations=4, periods=3, seed=2)
    p = _period(plan, 0, 0, 1)
    rev = revise(plan, p.start_k + 1, PlanRequest("finish_level", 0, p.start_k), BOUNDS)
    assert len(rev.plan.levels[0].realizations) == 2  # min_realizations, not 1
    _same_before(plan, rev.plan, rev.from_k)
    p = _period(rev.plan, 0, 1, 0)
    with pytest.raises(RefusedRequestError, match="min_realizations 2"):
        revise(rev.plan, p.start_k + 1, PlanRequest("finish_level", 0, p.start_k), BOUNDS)


def test_an_added_realization_is_the_one_a_larger_plan_would_have_drawn(
    short: ExperimentPlan,
) -> None:
    p = _period(short, 1, 1, 3)
    rev = revise(short, p.start_k + 1, PlanRequest("add_realization", 1, p.start_k), BOUNDS)
    plan = rev.plan
    assert len(plan.levels[1].realizations) == 3 and _measured(plan, 1, 2) == 4
    _same_before(short, plan, rev.from_k)
    designed = short_plan(seed=3)
    larger = build_plan(
        N=2_000,
        f_min_hz=0.1,
        offsets_deg=(6.6, 19.9),
        realizations=3,
        periods=4,
        sine_frequencies_hz=(1.0, 1.6),
        sine_offsets_deg=(5.9, 19.3),
        sine_min_periods=5,
        sine_min_duration_s=0.0,
        sine_settle_s=0.0,
        ramp_rate_deg_s=10.0,
        seed=3,
    )
    assert designed.seed == larger.seed
    np.testing.assert_array_equal(
        plan.levels[1].realizations[2].phases, larger.levels[1].realizations[2].phases
    )
    # The budget: max_realizations 3.
    with pytest.raises(RefusedRequestError, match="max_realizations 3"):
        revise(plan, p.start_k + 1, PlanRequest("add_realization", 1, p.start_k), BOUNDS)


def test_an_added_realization_is_crest_factor_reduced_when_the_plans_were() -> None:
    """A plan designed with crest-factor reduction gets an added realization reduced the same
    way (the one a plan designed with one more realization has; its crest factor that low),
    also after the plan went through its JSON message; a plan without keeps random phases."""
    design = dict(
        N=2_000, f_min_hz=0.1, offsets_deg=(6.6, 19.9), periods=4,
        sine_frequencies_hz=(1.0, 1.6), sine_offsets_deg=(5.9, 19.3), sine_min_periods=5,
        sine_min_duration_s=0.0, sine_settle_s=0.0, ramp_rate_deg_s=10.0, seed=3,
    )  # fmt: skip
    for reduced in (True, False):
        plan = build_plan(realizations=2, crest_factor_reduction=reduced, **design)  # type: ignore[arg-type]
        larger = build_plan(realizations=3, crest_factor_reduction=reduced, **design)  # type: ignore[arg-type]
        plan = plan_from_json(plan_to_json(plan))  # what the generator reads from a file
        p = _period(plan, 1, 1, 3)
        rev = revise(plan, p.start_k + 1, PlanRequest("add_realization", 1, p.start_k), BOUNDS)
        added = rev.plan.levels[1].realizations[2]
        expected = larger.levels[1].realizations[2]
        np.testing.assert_allclose(added.phases, expected.phases, rtol=0, atol=1e-12)
        crest = [r.crest_factor() for r in plan.levels[1].realizations]
        if reduced:
            assert added.crest_factor() < 1.8 and added.crest_factor() <= max(crest) + 0.1
        else:
            assert added.crest_factor() > 2.0  # a random-phase draw: about 2.4-3.2


def test_requests_on_a_level_that_ended_or_is_not_streaming_are_refused(
    short: ExperimentPlan,
) -> None:
    p = _period(short, 1, 0, 1)  # the high level streams; the low one has ended
    actions: tuple[Action, ...] = ("end_realization", "finish_level", "add_realization")
    for action in actions:
        with pytest.raises(RefusedRequestError, match="has ended"):
            revise(short, p.start_k + 1, PlanRequest(action, 0, p.start_k), BOUNDS)
    early = _period(short, 0, 0, 1)  # the low level streams; the high one has not started
    with pytest.raises(RefusedRequestError, match="not streaming"):
        revise(short, early.start_k + 1, PlanRequest("end_realization", 1, 0), BOUNDS)
    with pytest.raises(RequestError, match="level 7 is not a multisine level"):
        revise(short, early.start_k + 1, PlanRequest("add_realization", 7, 0), BOUNDS)


def test_a_revision_beyond_the_actuator_limits_is_refused(short: ExperimentPlan) -> None:
    p = _period(short, 1, 1, 3)
    tight = ActuatorLimits(min_deg=-5.0, max_deg=20.0, max_rate_deg_s=200.0)
    with pytest.raises(RefusedRequestError, match=r"revised plan is refused.*above max_deg"):
        revise(short, p.start_k + 1, PlanRequest("add_realization", 1, p.start_k), BOUNDS, tight)


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        (("stop_all", 0, 5), "not one of"),
        (("go_on", -1, 5), "level must be >= 0"),
        (("go_on", 0, -3), "after_k must be >= 0"),
        (("go_on", "low", 5), "level must be an integer"),
        (("go_on", True, 5), "level must be an integer"),
        (("go_on", 0, 5, 7), "reason must be a string"),
        (("go_on", 0, 5, "", "yes"), "more must be"),
    ],
)
def test_malformed_control_requests_are_named(fields: tuple[Any, ...], match: str) -> None:
    with pytest.raises(RequestError, match=match):
        request_from_fields(*fields)


def test_a_request_round_trips_through_its_fields() -> None:
    request = PlanRequest("finish_level", 2, 12345, "converged")
    assert request_from_fields(**request.to_fields()) == request

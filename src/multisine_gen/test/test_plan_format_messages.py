"""The typed messages of /experiment/plan and /experiment/segment (multisine_gen.plan_format):
every event payload the generator writes (generator_node.py) comes back unchanged from a
SegmentEvent through its CDR bytes, and the plan and t0 from an ExperimentPlan's ``plan_json``.
The messages are the runtime's (rig_runtime.messages: the rosbags typestore with
aero_rig_interfaces' .msg files registered), as the recorder and the offline fit read them."""

import json
import math
from typing import Any

import numpy as np
import pytest

from aero_rig_interfaces.msg import ExperimentPlan as ExperimentPlanMsg
from multisine_gen.campaigns import build_plan
from multisine_gen.plan import BaselineSweep, ExperimentPlan
from multisine_gen.plan_format import (
    plan_message,
    plan_to_json,
    read_plan_message,
    segment_event,
    segment_event_fields,
    segment_event_from_message,
)
from multisine_gen.revision import (
    Adaptation,
    PlanRequest,
    RefusedRequestError,
    RequestError,
    request_from_fields,
    revise,
)
from rig_runtime.interface import EXPERIMENT_PLAN, EXPERIMENT_SEGMENT
from rig_runtime.messages import deserialize, new_message, serialize, set_stamp, stamp_to_ns

T0 = 1_700_000_000_123_456_789
# A small plan of every segment kind: a baseline sweep up and down, ramps, settling periods,
# two multisine levels of two realizations and a validation sine.
PLAN = build_plan(
    N=400,
    f_min_hz=0.5,
    f_max_hz=2.0,
    std_deg=1.0,
    offsets_deg=(6.6, 15.0),
    realizations=2,
    periods=2,
    sine_frequencies_hz=(1.0,),
    sine_offsets_deg=(5.9,),
    sine_amplitude_deg=2.0,
    sine_min_duration_s=2.0,
    sine_min_periods=2,
    sine_settle_s=1.0,
    baseline=BaselineSweep(peak_deg=12.0, rate_deg_s=4.0),
    seed=3,
)
BOUNDS = Adaptation(min_periods=1, min_realizations=1, max_realizations=2)


def _period(plan: ExperimentPlan, level: int, realization: int, period: int) -> Any:
    return next(
        s
        for s in plan.segments
        if s.kind == "multisine"
        and (s.level, s.realization, s.period) == (level, realization, period)
    )


def _request_record(at_k: int, request: PlanRequest, t0_ns: int | None = T0) -> dict[str, Any]:
    """What generator_node.control records of a request it parsed, before its decision."""
    return {
        "t0_ns": t0_ns,
        "at_k": at_k,
        "request": request.action,
        "level": request.level,
        "after_k": request.after_k,
        "reason": request.reason,
    }


def _payloads() -> list[tuple[str, dict[str, Any]]]:
    """(id, payload) of every kind of event the generator publishes (generator_node.py)."""
    out: list[tuple[str, dict[str, Any]]] = []
    for segment in PLAN.segments:
        for edge in ("start", "end"):
            payload = segment_event(segment, edge, T0 / 1e9, PLAN.fs) | {"t0_ns": T0}
            out.append((f"{edge} {segment.index} {segment.kind}", payload))
    out.append(
        (
            "plan_end",
            {
                "event": "plan_end",
                "samples": PLAN.total_samples,
                "fs": PLAN.fs,
                "planned_samples": PLAN.total_samples,
                "revision": 0,
                "t0_ns": T0,
            },
        )
    )
    out.append(("plan_aborted", {"event": "plan_aborted", "samples": 1234, "t0_ns": T0}))
    p0 = _period(PLAN, 0, 0, 0)
    at_k = p0.start_k + 1  # level 0's first measured period streams
    go_on = PlanRequest("go_on", 0, p0.start_k - 1, "1 of at least 2 periods")
    out.append(
        ("decision go_on", _request_record(at_k, go_on) | {"event": "decision", "change": ""})
    )
    end = PlanRequest("end_realization", 0, p0.start_k - 1, "noise -31 dB", more=True)
    revision = revise(PLAN, at_k, end, BOUNDS)
    decision = {
        "event": "decision",
        "change": revision.change,
        "revision": revision.plan.revision,
        "from_k": revision.from_k,
        "samples": revision.plan.total_samples,
    }
    out.append(("decision revised", _request_record(at_k, end) | decision))
    add = PlanRequest("add_realization", 1, p0.start_k - 1, "total variance -8 dB")
    with pytest.raises(RefusedRequestError) as refused:
        revise(PLAN, at_k, add, BOUNDS)  # level 1 has max_realizations already
    why = {"event": "refused", "why": str(refused.value)}
    out.append(("refused", _request_record(at_k, add) | why))
    not_started = {"event": "refused", "why": "the plan has not started"}
    out.append(("refused before t0", _request_record(0, go_on, t0_ns=None) | not_started))
    with pytest.raises(RequestError) as bad:
        request_from_fields("explode", 1, 4)
    unparsed = {"t0_ns": T0, "at_k": at_k, "request": "explode", "reason": ""}
    out.append(("refused unparsed", unparsed | {"event": "refused", "why": str(bad.value)}))
    return out


PAYLOADS = _payloads()


def _through_cdr(payload: dict[str, Any]) -> Any:
    msg = new_message(EXPERIMENT_SEGMENT.type, **segment_event_fields(payload))
    return deserialize(serialize(msg), EXPERIMENT_SEGMENT.type)


def test_the_plan_has_every_segment_kind_and_edge() -> None:
    kinds = {p["kind"] for _, p in PAYLOADS if p["event"] in ("start", "end")}
    assert kinds == {"baseline", "ramp", "settle", "multisine", "sine"}
    assert {p["direction"] for _, p in PAYLOADS if p.get("kind") == "baseline"} == {"up", "down"}


@pytest.mark.parametrize("payload", [p for _, p in PAYLOADS], ids=[i for i, _ in PAYLOADS])
def test_every_event_payload_round_trips_through_a_segment_event(payload: dict[str, Any]) -> None:
    back = segment_event_from_message(_through_cdr(payload))
    assert back == payload
    assert list(back) == list(payload)  # in the order the generator writes the keys


def test_absent_fields_travel_as_minus_one_nan_or_empty() -> None:
    ramp = next(p for _, p in PAYLOADS if p["event"] == "start" and p["kind"] == "ramp")
    msg = _through_cdr(ramp)
    assert (msg.level, msg.realization, msg.period, msg.sine_test) == (-1, -1, -1, -1)
    assert math.isnan(msg.offset_deg) and math.isnan(msg.frequency_hz)
    assert (msg.excitation, msg.direction, msg.request) == ("", "", "")
    assert (msg.at_k, msg.after_k, msg.from_k, msg.revision) == (-1, -1, -1, -1)
    decision = dict(PAYLOADS)["decision revised"]
    msg = _through_cdr(decision)
    assert (msg.request, msg.from_k, msg.kind) == ("end_realization", decision["from_k"], "")


def test_an_old_string_event_is_read_as_its_json() -> None:
    payload = dict(PAYLOADS)["decision revised"]
    old = new_message("std_msgs/msg/String", data=json.dumps(payload))
    assert segment_event_from_message(old) == payload


@pytest.mark.parametrize("adaptive", [False, True])
def test_the_plan_message_round_trips_through_an_experiment_plan(adaptive: bool) -> None:
    adaptation = BOUNDS.to_dict() if adaptive else None
    fields = plan_message(PLAN, T0, adaptation=adaptation, plan_id="tiny")
    msg = new_message(EXPERIMENT_PLAN.type, **fields)
    set_stamp(msg.header.stamp, T0)
    back = deserialize(serialize(msg), EXPERIMENT_PLAN.type)
    plan, t0_ns = read_plan_message(back)
    assert t0_ns == T0 and stamp_to_ns(back.header.stamp) == T0
    assert plan_to_json(plan) == plan_to_json(PLAN)
    np.testing.assert_array_equal(plan.command_deg(), PLAN.command_deg())
    assert (back.plan_id, back.revision, back.t0_ns, back.fs) == ("tiny", 0, T0, PLAN.fs)
    assert (back.samples, back.levels, back.adaptive) == (PLAN.total_samples, 2, adaptive)
    assert list(back.realizations) == [2, 2] and list(back.offsets_deg) == [6.6, 15.0]
    assert json.loads(back.plan_json).get("adaptation") == adaptation
    # The same from rclpy's class (the nodes'), from an old std_msgs/String and from its text.
    for carrier in (
        ExperimentPlanMsg(**fields),
        new_message("std_msgs/msg/String", data=fields["plan_json"]),
        fields["plan_json"],
    ):
        plan, t0_ns = read_plan_message(carrier)
        assert t0_ns == T0 and plan_to_json(plan) == plan_to_json(PLAN)

"""The generator node's handling of an adaptive run's requests (the /experiment/control
service): a request it carries out becomes a published plan revision and a decision event, and
is answered accepted with the change; one it cannot, or a malformed one, is logged, recorded as
refused, answered with the reason and changes nothing; outside an adaptive run every request is
refused; in an adaptive simulation the stream holds at a measured period's end until that
period's request, while a client of the service is in the graph. Its credit (flow control) comes
from the lift's progress stamps."""

import json
from collections.abc import Iterator
from typing import Any

import pytest
from std_msgs.msg import Header

from aero_rig_interfaces.srv import ControlExperiment
from multisine_gen.generator_node import NOT_ADAPTIVE, GeneratorNode
from multisine_gen.plan_format import read_plan_message, segment_event_from_message
from multisine_gen.revision import PlanRequest
from rig_runtime import Node
from rig_runtime.interface import EXPERIMENT_CONTROL, WING_COEFFICIENTS, WING_PROGRESS
from rig_runtime.messages import set_stamp, stamp_to_ns
from rig_testing.processes import graph_env, join_graph


class _Endpoint:
    """What one of the node's endpoints sent, and how many peers it is told it has."""

    def __init__(self) -> None:
        self.sent: list[Any] = []
        self.matched = 0

    def publish(self, msg: Any) -> None:
        self.sent.append(msg)

    def publisher_count(self) -> int:
        return self.matched


class _Recorded:
    """A real GeneratorNode's publishers recorded instead of sent (``endpoints[topic]``), and
    its readers' matched counts set by the test (``endpoints["sub " + topic]``)."""

    def __init__(self, gen: GeneratorNode) -> None:
        self.endpoints: dict[str, _Endpoint] = {}
        for pub in gen.rig_publishers:
            pub.publish = self.endpoints.setdefault(pub.topic, _Endpoint()).publish  # type: ignore[method-assign]
        for sub in gen.rig_subscriptions:
            endpoint = self.endpoints.setdefault(f"sub {sub.topic}", _Endpoint())
            sub.publisher_count = endpoint.publisher_count  # type: ignore[method-assign]


_made: list[Node] = []


@pytest.fixture(autouse=True)
def _graph(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Each node on this test's own DDS domain, closed at its end."""
    join_graph(graph_env(), monkeypatch.setenv)
    yield
    while _made:
        _made.pop().close()


def _started(**params: Any) -> tuple[GeneratorNode, _Recorded]:
    settings = {"plan": "short", "seed": 5, "flow_control": True, "adaptive": True} | params
    args = ["--ros-args"]
    for name, value in settings.items():
        args += ["-p", f"{name}:={json.dumps(value)}"]
    gen = GeneratorNode(args)
    _made.append(gen)
    node = _Recorded(gen)
    gen.t0_ns = 10**18
    gen.pacer.start(0.0)
    return gen, node


def _events(node: _Recorded) -> list[dict[str, Any]]:
    return [segment_event_from_message(m) for m in node.endpoints["/experiment/segment"].sent]


def _send(gen: GeneratorNode, request: PlanRequest) -> Any:
    """The service's callback on the request; its response."""
    return gen.on_control(
        ControlExperiment.Request(**request.to_fields()), ControlExperiment.Response()
    )


def _clients(gen: GeneratorNode, count: int) -> None:
    """Tell the node it has ``count`` clients of /experiment/control (the hold's condition)."""
    gen.count_clients = (  # type: ignore[method-assign]
        lambda service_name: count if service_name == EXPERIMENT_CONTROL.name else 0
    )


def _period(gen: GeneratorNode, level: int, realization: int, period: int) -> Any:
    return next(
        s
        for s in gen.plan.segments
        if s.kind == "multisine"
        and (s.level, s.realization, s.period) == (level, realization, period)
    )


def test_a_request_carried_out_is_published_as_a_revision_with_its_decision() -> None:
    gen, node = _started()
    p1 = _period(gen, 0, 0, 1)
    gen.k = p1.stop_k  # period 1 published in full: the stream is at its end
    total = gen.total
    response = _send(gen, PlanRequest("end_realization", 0, p1.stop_k - 1, "noise -31 dB"))
    assert gen.plan.revision == 1 and gen.total == total - 2 * p1.length
    msg = node.endpoints["/experiment/plan"].sent[-1]
    plan, t0 = read_plan_message(msg)
    assert plan.revision == 1 and t0 == gen.t0_ns and plan.total_samples == gen.total
    assert (msg.plan_id, msg.revision, msg.samples, msg.adaptive) == ("short", 1, gen.total, True)
    assert stamp_to_ns(msg.header.stamp) == gen.t0_ns
    decision = _events(node)[-1]
    assert decision["event"] == "decision" and decision["request"] == "end_realization"
    assert decision["reason"] == "noise -31 dB" and decision["from_k"] == p1.stop_k
    assert "2 measured periods instead of 4" in decision["change"]
    event_msg = node.endpoints["/experiment/segment"].sent[-1]
    assert stamp_to_ns(event_msg.header.stamp) == gen.stamp_ns(p1.stop_k)  # at_k
    assert (response.accepted, response.message) == (True, decision["change"])
    assert (response.revision, response.from_k) == (1, p1.stop_k)
    assert json.loads(msg.plan_json)["adaptation"] == {
        "min_periods": 2,
        "min_realizations": 2,
        "max_realizations": 4,
    }


@pytest.mark.parametrize(
    ("action", "level", "after_k", "why"),
    [
        ("end_realization", 0, 0, "has ended"),
        ("add_realization", 9, 0, "level 9"),
        ("finish_level", 1, -4, "after_k must be >= 0"),
        ("finish_level", -1, 4, "level must be >= 0"),
        ("explode", 1, 4, "not one of"),
    ],
)
def test_refused_and_malformed_requests_are_recorded_and_change_nothing(
    action: str, level: int, after_k: int, why: str, capfd: pytest.CaptureFixture[str]
) -> None:
    gen, node = _started()
    gen.k = _period(gen, 1, 0, 1).start_k + 3  # the high level streams
    plan = gen.plan
    request = ControlExperiment.Request(action=action, level=level, after_k=after_k, reason="r")
    response = gen.on_control(request, ControlExperiment.Response())
    assert gen.plan is plan and not node.endpoints["/experiment/plan"].sent
    event = _events(node)[-1]
    assert event["event"] == "refused" and why in event["why"]
    assert event["request"] == action and event["reason"] == "r"
    assert (response.accepted, response.message) == (False, event["why"])
    assert (response.revision, response.from_k) == (0, -1)
    logged = [line for line in capfd.readouterr().err.splitlines() if "[generator]" in line]
    assert any(why in line and ("[WARN]" in line or "[ERROR]" in line) for line in logged)


def test_a_request_beyond_the_budget_is_refused() -> None:
    gen, node = _started(adaptive_max_realizations=2)
    p = _period(gen, 1, 1, 3)
    gen.k = p.stop_k
    response = _send(gen, PlanRequest("add_realization", 1, p.stop_k - 1, "total variance -8 dB"))
    assert gen.plan.revision == 0
    assert "max_realizations 2" in _events(node)[-1]["why"]
    assert not response.accepted and "max_realizations 2" in response.message


def test_outside_an_adaptive_run_every_request_is_refused_and_nothing_is_recorded(
    capfd: pytest.CaptureFixture[str],
) -> None:
    gen, node = _started(adaptive=False)
    p1 = _period(gen, 0, 0, 1)
    gen.k = p1.stop_k
    for action in ("end_realization", "go_on", "explode"):
        response = _send(gen, PlanRequest(action, 0, p1.stop_k - 1, "noise -31 dB"))  # type: ignore[arg-type]
        assert (response.accepted, response.message) == (False, NOT_ADAPTIVE)
        assert (response.revision, response.from_k) == (0, -1)
    assert gen.plan.revision == 0 and not node.endpoints["/experiment/segment"].sent
    logged = [line for line in capfd.readouterr().err.splitlines() if "[generator]" in line]
    assert sum(NOT_ADAPTIVE in line and "[WARN]" in line for line in logged) == 3
    _clients(gen, 1)  # a client in the graph: a fixed-plan run still never holds
    assert not gen._holds(p1.stop_k)


@pytest.mark.parametrize("adaptive", [False, True])
def test_the_service_answers_a_client_in_every_run(adaptive: bool) -> None:
    """A real client (as ``ros2 service call`` is) gets the generator's answer over DDS."""
    gen, _ = _started(adaptive=adaptive)
    client_node = Node("control_client", argv=[])
    _made.append(client_node)
    client = client_node.create_client(ControlExperiment, EXPERIMENT_CONTROL.name)

    def spin_both() -> None:
        gen.spin_once(0.01)
        client_node.spin_once(0.01)

    assert client_node.spin_until(client.service_is_ready, 20.0)
    p0 = _period(gen, 0, 0, 0)
    gen.k = p0.stop_k
    future = client.call_async(
        ControlExperiment.Request(action="go_on", level=0, after_k=p0.stop_k - 1)
    )
    for _ in range(2000):
        if future.done():
            break
        spin_both()
    response = future.result()
    assert response is not None
    expected = (True, "") if adaptive else (False, NOT_ADAPTIVE)
    assert (response.accepted, response.message) == expected
    assert (response.revision, response.from_k) == (0, -1)
    assert gen.count_clients(EXPERIMENT_CONTROL.name) == 1


def test_the_stream_holds_at_a_period_end_until_its_request_while_a_client_is_there() -> None:
    gen, node = _started()
    p0 = _period(gen, 0, 0, 0)
    _clients(gen, 0)
    assert not gen._holds(p0.stop_k)  # no client of the service: never holds
    _clients(gen, 1)
    assert gen._holds(p0.stop_k)  # the period's last sample is out, its request is not in
    assert not gen._holds(p0.stop_k - 5)  # inside a period: never
    gen.k = p0.stop_k
    _send(gen, PlanRequest("go_on", 0, p0.stop_k - 1, "1 of at least 2 periods"))
    assert not gen._holds(p0.stop_k)
    assert _events(node)[-1]["event"] == "decision" and gen.plan.revision == 0


def test_a_realization_is_added_while_the_stream_holds_at_the_levels_last_period() -> None:
    gen, node = _started()
    p = _period(gen, 1, 1, 3)  # the high level's last period
    gen.k = p.stop_k  # held at its end: nothing after the level is out yet
    _send(gen, PlanRequest("add_realization", 1, p.stop_k - 1, "dominant cluster 6 < 8"))
    assert gen.plan.revision == 1 and len(gen.plan.levels[1].realizations) == 3
    ramp = gen.plan.segment_at(p.stop_k)  # to the new realization, which settles first
    assert ramp.kind == "ramp" and gen.plan.segment_at(ramp.stop_k).kind == "settle"
    assert _events(node)[-1]["change"].endswith("realization 2 added (3 realizations, 4 periods)")


def test_the_hold_waits_for_the_last_request_on_a_period() -> None:
    gen, _ = _started()
    _clients(gen, 1)
    p1 = _period(gen, 1, 1, 1)  # the high level's last realization, period 1
    gen.k = p1.stop_k
    assert gen._holds(p1.stop_k)
    _send(gen, PlanRequest("end_realization", 1, p1.stop_k - 1, "noise -28 dB", more=True))
    assert gen.plan.revision == 1 and gen._holds(p1.stop_k)  # the level's verdict follows
    _send(gen, PlanRequest("add_realization", 1, p1.stop_k - 1, "total variance -6 dB"))
    assert gen.plan.revision == 2 and not gen._holds(p1.stop_k)
    assert next(lv for lv in gen.plan.levels if lv.level == 1).realization_periods == (4, 2, 4)


def test_the_credit_comes_from_the_lifts_progress_stamps() -> None:
    gen, node = _started(max_lead_samples=50)
    assert f"sub {WING_PROGRESS.name}" in node.endpoints
    assert f"sub {WING_COEFFICIENTS.name}" not in node.endpoints  # not every sample
    commands = node.endpoints["/pitch/command"].sent
    gen.tick()
    assert len(commands) == 50  # nothing came back yet: the lead alone
    progress = Header(frame_id="wing")
    set_stamp(progress.stamp, gen.stamp_ns(29))
    gen.on_progress(progress)
    gen.tick()
    assert len(commands) == 80  # samples 0..29 published by the lift, and 50 ahead
    set_stamp(progress.stamp, gen.stamp_ns(10))  # an older report takes nothing back
    gen.on_progress(progress)
    gen.tick()
    assert len(commands) == 80


def test_each_event_is_stamped_with_its_sample_and_the_plan_with_t0() -> None:
    gen, node = _started(flow_control=False, real_time_factor=0.0, adaptive=False)
    gen._publish_plan()
    gen.tick()  # as fast as the graph takes, no credit: the whole plan at once
    assert gen.finished
    (plan_msg,) = node.endpoints["/experiment/plan"].sent
    assert stamp_to_ns(plan_msg.header.stamp) == gen.t0_ns
    assert (plan_msg.adaptive, json.loads(plan_msg.plan_json).get("adaptation")) == (False, None)
    sent = node.endpoints["/experiment/segment"].sent
    assert len(sent) == 2 * len(gen.plan.segments) + 1
    for msg in sent:
        event = segment_event_from_message(msg)
        if event["event"] == "start":
            k = event["start_k"]
        elif event["event"] == "end":
            k = event["start_k"] + event["length"] - 1
        else:
            assert event["event"] == "plan_end" and event["samples"] == gen.total
            k = gen.total - 1
        assert stamp_to_ns(msg.header.stamp) == gen.stamp_ns(k), event

"""The generator node's handling of an adaptive run's requests (/experiment/control): a
request it carries out becomes a published plan revision and a decision event; one it cannot,
or a malformed message, is logged and recorded as refused and changes nothing; in simulation
the stream holds at a measured period's end until that period's request, while a controller is
matched. Its credit (flow control) comes from the lift's progress stamps."""

import json
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any

import pytest
from std_msgs.msg import Header

from multisine_gen.generator_node import GeneratorNode
from multisine_gen.plan_format import read_plan_message
from multisine_gen.revision import PlanRequest
from rig_runtime.interface import WING_COEFFICIENTS, WING_PROGRESS
from rig_runtime.messages import set_stamp
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


_made: list[GeneratorNode] = []


@pytest.fixture(autouse=True)
def _graph(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Each node on this test's own DDS domain, closed at its end."""
    join_graph(graph_env(), monkeypatch.setenv)
    yield
    while _made:
        _made.pop().close()


def _started(**params: Any) -> tuple[GeneratorNode, _Recorded]:
    settings = {"plan": "short", "seed": 5, "flow_control": True} | params
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
    return [json.loads(m.data) for m in node.endpoints["/experiment/segment"].sent]


def _send(gen: GeneratorNode, request: PlanRequest | str) -> None:
    text = request if isinstance(request, str) else request.to_json()
    gen.on_control(SimpleNamespace(data=text))


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
    _send(gen, PlanRequest("end_realization", 0, p1.stop_k - 1, "noise -31 dB"))
    assert gen.plan.revision == 1 and gen.total == total - 2 * p1.length
    plan, t0 = read_plan_message(node.endpoints["/experiment/plan"].sent[-1].data)
    assert plan.revision == 1 and t0 == gen.t0_ns and plan.total_samples == gen.total
    decision = _events(node)[-1]
    assert decision["event"] == "decision" and decision["request"] == "end_realization"
    assert decision["reason"] == "noise -31 dB" and decision["from_k"] == p1.stop_k
    assert "2 measured periods instead of 4" in decision["change"]
    assert json.loads(node.endpoints["/experiment/plan"].sent[-1].data)["adaptation"] == {
        "min_periods": 2,
        "min_realizations": 2,
        "max_realizations": 4,
    }


@pytest.mark.parametrize(
    ("request_text", "why"),
    [
        ('{"action": "end_realization", "level": 0, "after_k": 0, "reason": ""}', "has ended"),
        ('{"action": "add_realization", "level": 9, "after_k": 0, "reason": ""}', "level 9"),
        ('{"action": "finish_level", "level": 1, "after_k": -4}', "after_k must be >= 0"),
        ('{"action": "explode", "level": 1, "after_k": 4}', "not one of"),
        ("{oops", "not JSON"),
    ],
)
def test_refused_and_malformed_requests_are_recorded_and_change_nothing(
    request_text: str, why: str, capfd: pytest.CaptureFixture[str]
) -> None:
    gen, node = _started()
    gen.k = _period(gen, 1, 0, 1).start_k + 3  # the high level streams
    plan = gen.plan
    _send(gen, request_text)
    assert gen.plan is plan and not node.endpoints["/experiment/plan"].sent
    event = _events(node)[-1]
    assert event["event"] == "refused" and why in event["why"]
    logged = [line for line in capfd.readouterr().err.splitlines() if "[generator]" in line]
    assert any(why in line and ("[WARN]" in line or "[ERROR]" in line) for line in logged)


def test_a_request_beyond_the_budget_is_refused() -> None:
    gen, node = _started(adaptive_max_realizations=2)
    p = _period(gen, 1, 1, 3)
    gen.k = p.stop_k
    _send(gen, PlanRequest("add_realization", 1, p.stop_k - 1, "total variance -8 dB"))
    assert gen.plan.revision == 0
    assert "max_realizations 2" in _events(node)[-1]["why"]


def test_the_stream_holds_at_a_period_end_until_its_request_while_a_controller_is_matched() -> None:
    gen, node = _started()
    p0 = _period(gen, 0, 0, 0)
    control = node.endpoints["sub /experiment/control"]
    assert not gen._holds(p0.stop_k)  # no controller: a fixed-plan run never holds
    control.matched = 1
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
    gen, node = _started()
    node.endpoints["sub /experiment/control"].matched = 1
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

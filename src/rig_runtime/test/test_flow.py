"""The streams' flow reports and their judge (rig_runtime.flow): stuck readers, partitions;
and a node's counts and its take of what its executor was not woken for (rig_runtime.node)."""

import time

import pytest
from rclpy.duration import Duration

from rig_runtime import Node
from rig_runtime.diagnostics import OK, diagnostic_array
from rig_runtime.flow import (
    FLOW_PERIOD_S,
    FLOW_STATUS_SUFFIX,
    SILENT_S,
    STUCK_S,
    EndpointFlow,
    FlowWatch,
    flow_reports,
    flow_values,
    parse_flow,
)
from rig_runtime.interface import PITCH_STATE
from rig_runtime.messages import set_stamp, stamp_to_ns
from rig_testing.processes import graph_env, join_graph, wait_for

STATE = "/pitch/state"
MS = 1_000_000  # ns


def _writer(stamp: int, count: int = 1) -> dict[tuple[str, str], EndpointFlow]:
    return {("writer", STATE): EndpointFlow(count, stamp)}


def _reader(stamp: int, count: int = 1) -> dict[tuple[str, str], EndpointFlow]:
    return {("reader", STATE): EndpointFlow(count, stamp)}


Stream = tuple[int, bool] | None  # (stamp ns, advancing 1 ms per report) or silent


def _run(watch: FlowWatch, t0: float, t1: float, writer: Stream, reader: Stream) -> list[str]:
    """Both nodes report every period from t0 to t1 (None: that node is silent); the kinds of
    the events concluded."""
    kinds = []
    t = t0
    while t < t1:
        step = round((t - t0) / FLOW_PERIOD_S) * MS
        for node, stream, flows in (("/sim_actuator", writer, _writer),
                                    ("/recorder", reader, _reader)):  # fmt: skip
            if stream is not None:
                stamp, moving = stream
                watch.report(t, node, flows(stamp + step if moving else stamp))
        kinds += [e.kind for e in watch.check(t)]
        t += FLOW_PERIOD_S
    return kinds


def test_a_report_reads_back_from_a_diagnostic_array() -> None:
    values = flow_values([("writer", STATE, 12, 345, 4), ("reader", "/pitch/command", 3, 0, 1)])
    values["state"] = "streaming"  # other values of the status are not flow
    msg = diagnostic_array("/sim_actuator" + FLOW_STATUS_SUFFIX, OK, "", "/sim_actuator", values)
    ((node, flows),) = list(flow_reports(msg))
    assert node == "/sim_actuator"
    assert flows == {
        ("writer", STATE): EndpointFlow(12, 345, 4),
        ("reader", "/pitch/command"): EndpointFlow(3, 0, 1),
    }
    assert parse_flow({"writer /x": "not numbers", "reader y": "1 2", "writer /z": "1"}) == {}
    assert parse_flow({"reader /x": "1 2"}) == {("reader", "/x"): EndpointFlow(1, 2, -1)}


def test_a_reader_that_stops_while_its_writer_goes_on_is_named_within_two_seconds() -> None:
    watch = FlowWatch(describe_stamp=lambda ns: f"stamp {ns // MS} ms")
    assert (
        _run(watch, 0.0, 5.0, writer=(1000 * MS, True), reader=(1000 * MS, True)) == []
    )  # both advance
    stopped_at = 5.0
    kinds = _run(watch, stopped_at, 5.0 + STUCK_S + 2 * FLOW_PERIOD_S, writer=(1010 * MS, True),
                 reader=(1009 * MS, False))  # fmt: skip
    assert kinds == ["stuck"]
    (event,) = watch.events
    assert event.at - stopped_at <= 2.0
    assert event.detail["topic"] == STATE and event.detail["node"] == "/recorder"
    assert event.detail["writer"] == "/sim_actuator"
    assert event.detail["last_stamp_ns"] == 1009 * MS
    assert "reader stuck: /pitch/state at /recorder" in event.text
    assert "stamp 1009 ms" in event.text
    assert watch.stuck_readers() == [("/recorder", STATE)]
    # it is named once, and again when it receives
    assert _run(watch, 8.0, 9.0, writer=(2000 * MS, True), reader=(1009 * MS, False)) == []
    assert _run(watch, 9.0, 9.5, writer=(2000 * MS, True), reader=(2000 * MS, True)) == [
        "receiving"
    ]
    assert watch.stuck_readers() == []


def test_paused_slow_and_idle_readers_and_writers_are_not_stuck() -> None:
    # a reader that has received nothing yet, long before the stream starts
    watch = FlowWatch()
    assert _run(watch, 0.0, 10.0, writer=(0, False), reader=(0, False)) == []
    assert (
        _run(watch, 10.0, 11.0, writer=(1 * MS, True), reader=(0, False)) == []
    )  # the stream just started
    # a paused reader reports nothing; the writer goes on
    watch = FlowWatch()
    _run(watch, 0.0, 2.0, writer=(1 * MS, True), reader=(1 * MS, True))
    assert _run(watch, 2.0, 10.0, writer=(10 * MS, True), reader=None) == []
    # ... and resumes: its first report still holds the old stamp, then it catches up
    assert _run(watch, 10.0, 10.5, writer=(30 * MS, True), reader=(1 * MS, False)) == []
    assert _run(watch, 10.5, 15.0, writer=(31 * MS, True), reader=(31 * MS, True)) == []
    # a writer paused right after its report: the reader stands behind it, the writer is silent
    watch = FlowWatch()
    _run(watch, 0.0, 2.0, writer=(1 * MS, True), reader=(1 * MS, True))
    watch.report(2.0, "/sim_actuator", _writer(50 * MS))
    assert _run(watch, 2.1, 10.0, writer=None, reader=(40 * MS, False)) == []
    # a slow reader behind its writer, but moving
    watch = FlowWatch()
    assert _run(watch, 0.0, 10.0, writer=(100 * MS, True), reader=(1 * MS, True)) == []
    # a stream that ended: the reader holds the writer's last sample
    assert _run(watch, 10.0, 20.0, writer=(500 * MS, False), reader=(500 * MS, False)) == []


def _hosts(watch: FlowWatch, t0: float, t1: float, rig: bool) -> list[str]:
    kinds, t = [], t0
    while t < t1:
        if rig:
            watch.report(t, "/generator", {})
            watch.report(t, "/lift", {})
        watch.report(t, "/identifier", {})
        kinds += [e.kind for e in watch.check(t)]
        t += FLOW_PERIOD_S
    return kinds


def test_a_host_whose_nodes_all_fall_silent_is_named_cut_off_and_rejoined() -> None:
    watch = FlowWatch({"/generator": "rig", "/lift": "rig"})
    assert _hosts(watch, 0.0, 5.0, rig=True) == []
    kinds = _hosts(watch, 5.0, 5.0 + SILENT_S + 0.6, rig=False)
    assert kinds == ["partition"]
    (event,) = watch.events
    assert event.detail["host"] == "rig" and event.detail["nodes"] == ["/generator", "/lift"]
    assert event.at - 5.0 <= SILENT_S + FLOW_PERIOD_S + 0.5
    assert list(watch.partitioned()) == ["rig"]
    assert _hosts(watch, 10.0, 20.0, rig=False) == []  # named once
    assert _hosts(watch, 20.0, 21.0, rig=True) == ["rejoined"]
    assert watch.events[-1].detail["silent_s"] > 14
    assert watch.partitioned() == {}


def test_one_silent_node_or_a_silent_machine_is_no_partition() -> None:
    watch = FlowWatch({"/generator": "rig", "/lift": "rig"})
    _hosts(watch, 0.0, 5.0, rig=True)
    t = 5.0
    while t < 10.0:  # the generator paused: the lift on the same host goes on
        watch.report(t, "/lift", {})
        watch.report(t, "/identifier", {})
        assert watch.check(t) == []
        t += FLOW_PERIOD_S
    # nothing heard from anyone (this host starved too): nothing to compare with
    assert [e.kind for e in watch.check(30.0)] == []
    # a node of another graph on the domain is not this host: with the local nodes named,
    # only they count
    watch = FlowWatch({"/generator": "rig"}, {"/identifier"})
    watch.report(0.0, "/generator", {})
    watch.report(0.0, "/identifier", {})
    watch.report(3.0, "/someone_elses_node", {})
    assert watch.check(3.0) == []
    watch.report(3.0, "/identifier", {})
    assert [e.kind for e in watch.check(3.0)] == ["partition"]
    # one machine: no remote host, no partition
    watch = FlowWatch()
    watch.report(0.0, "/generator", {})
    assert watch.check(10.0) == []


def test_the_graph_state_says_what_each_node_last_reported_and_who_fell_silent() -> None:
    """The record of a stall: each node's last report (how long ago, per endpoint its count,
    last sample and matched peers) and the nodes not heard within two report periods."""
    watch = FlowWatch(
        {"/sim_actuator": "rig"},
        {"/recorder", "/identifier"},
        describe_stamp=lambda ns: f"sample {ns // MS}",
    )
    watch.report(0.0, "/sim_actuator", {("writer", STATE): EndpointFlow(2800, 2800 * MS, 2)})
    watch.report(9.5, "/recorder", {("reader", STATE): EndpointFlow(2800, 2800 * MS, 1)})
    state = watch.graph_state(10.0)
    assert state == {
        "/recorder": {
            "heard_s_ago": 0.5,
            "endpoints": {f"reader {STATE}": {"count": 2800, "last": "sample 2800", "matched": 1}},
        },
        "/sim_actuator": {
            "heard_s_ago": 10.0,
            "endpoints": {f"writer {STATE}": {"count": 2800, "last": "sample 2800", "matched": 2}},
        },
    }
    # the actuator fell silent 10 s ago; the identifier was never heard; the recorder reports
    assert watch.silent(10.0) == {"/identifier": None, "/sim_actuator": 10.0}


@pytest.mark.slow  # two rclpy nodes talking DDS
def test_a_node_counts_its_streams_and_takes_what_its_executor_was_not_woken_for(
    monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    """Writers and readers count what they pass and keep the last header stamp (the flow
    report's values); a stream reader whose executor is never spun, as if it were not woken,
    gets its samples from the flow report's take, in order, and says so in the log."""
    join_graph(graph_env(), monkeypatch.setenv)
    writer, reader = Node("flow_writer", argv=[]), Node("flow_reader", argv=[])
    got: list[int] = []
    try:
        pub = writer.create_publisher(PITCH_STATE.type, PITCH_STATE.name, "stream")
        sub = reader.create_subscription(
            PITCH_STATE.type, PITCH_STATE.name, lambda m: got.append(stamp_to_ns(m.header.stamp)),
            "stream",
        )  # fmt: skip
        assert wait_for(lambda: pub.subscription_count() == 1 and sub.publisher_count() == 1, 30)
        stamps = [1_000 * MS + k * MS for k in range(50)]
        for stamp in stamps:
            msg = writer.new_message(PITCH_STATE.type, name=["pitch"], position=[0.0])
            set_stamp(msg.header.stamp, stamp)
            pub.publish(msg)
        assert (pub.count, pub.stamp_ns) == (50, stamps[-1])
        values = flow_values([("writer", pub.topic, pub.count, pub.stamp_ns, pub.matched_count())])
        assert parse_flow(values) == {("writer", PITCH_STATE.name): EndpointFlow(50, stamps[-1], 1)}
        # every sample is in the reader's DDS history once the writer has its acknowledgement
        assert pub.handle.wait_for_all_acked(Duration(seconds=30))
        # the reader's executor is never spun: only the flow report's take can deliver
        reader.start_flow_report(period_s=0.2)
        reader.flow_report.take_undelivered()  # the first tick: nothing judged yet
        assert got == []
        # What is judged: every sample (all received before now) is held a whole period.
        aged_ns = time.time_ns() + 200 * MS
        assert wait_for(lambda: time.time_ns() > aged_ns, 30)

        def judged() -> bool:  # two ticks a period apart at most (a starved pair is retried)
            reader.flow_report.take_undelivered()
            reader.flow_report.take_undelivered()
            return bool(got)

        assert wait_for(judged, 30)
        assert got == stamps
        assert (sub.count, sub.stamp_ns, sub.undelivered) == (50, stamps[-1], 50)
        logged = capfd.readouterr().err
        assert f"reader of {PITCH_STATE.name}: 50 sample(s) were held undelivered" in logged
        # a reader whose executor delivers is left to it: nothing more is taken or logged
        for stamp in stamps[:5]:
            msg = writer.new_message(PITCH_STATE.type, name=["pitch"], position=[0.0])
            set_stamp(msg.header.stamp, stamp + 1_000 * MS)
            pub.publish(msg)
        assert wait_for(lambda: (reader.spin_once(0.05), len(got) == 55)[1], 30), len(got)
        reader.flow_report.take_undelivered()
        reader.flow_report.take_undelivered()
        assert sub.undelivered == 50 and len(got) == 55
        assert "held undelivered" not in capfd.readouterr().err
    finally:
        writer.close()
        reader.close()

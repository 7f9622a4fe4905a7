"""The start barrier's decision (barrier.py), in-process: reports in, problems out."""

from rig_runtime.barrier import Endpoint, ReadinessReport, StartBarrier, compatible
from rig_runtime.interface import GRAPH_READY
from rig_runtime.messages import deserialize, new_message, serialize


def _w(topic: str, gid: str, matched: tuple[str, ...] = (), **kw: bool) -> Endpoint:
    """A writer that has matched ``len(matched)`` readers (the names only document which)."""
    return Endpoint(topic, "writer", gid, matched_count=len(matched), **kw)


def _r(topic: str, gid: str, matched: tuple[str, ...] = (), **kw: bool) -> Endpoint:
    return Endpoint(topic, "reader", gid, matched_count=len(matched), **kw)


def _chain(matched: bool = True) -> tuple[ReadinessReport, list[ReadinessReport]]:
    """generator -> actuator -> lift, with the recorder recording both topics."""
    m = (lambda *g: g) if matched else (lambda *g: ())
    gen = ReadinessReport("/generator", True, endpoints=(_w("/cmd", "G1", m("A1", "R1")),))
    act = ReadinessReport(
        "/actuator",
        True,
        endpoints=(_r("/cmd", "A1", m("G1")), _w("/state", "A2", m("L1", "R2"))),
        required_inputs=("/cmd",),
    )
    lift = ReadinessReport(
        "/lift", True, endpoints=(_r("/state", "L1", m("A2")),), required_inputs=("/state",)
    )
    rec = ReadinessReport(
        "/recorder",
        True,
        endpoints=(_r("/cmd", "R1", m("G1")), _r("/state", "R2", m("A2"))),
        records=("*",),
    )
    return gen, [act, lift, rec]


def test_all_matched_on_both_sides_passes() -> None:
    own, members = _chain()
    barrier = StartBarrier(["actuator", "lift", "recorder"])
    for report in members:
        barrier.update(report)
    assert barrier.pending(own) == []


def test_missing_report_names_the_node() -> None:
    own, members = _chain()
    barrier = StartBarrier(["actuator", "lift", "recorder", "identifier"])
    for report in members:
        barrier.update(report)
    problems = barrier.pending(own)
    assert len(problems) == 1 and problems[0].startswith("/identifier: no readiness report")


def test_not_ready_node_gives_its_reason() -> None:
    own, members = _chain()
    members[0] = ReadinessReport(
        "/actuator", False, "no feedback from the controller", members[0].endpoints
    )
    barrier = StartBarrier(["actuator", "lift", "recorder"])
    for report in members:
        barrier.update(report)
    assert barrier.pending(own) == ["/actuator: no feedback from the controller"]


def test_one_sided_match_waits_for_the_other_side() -> None:
    """The reader has discovered the writer, but the writer not yet the reader: a sample
    written now would not reach it. The barrier names the writer's node."""
    own, members = _chain()
    act, lift, rec = members
    act = ReadinessReport(
        "/actuator",
        True,
        endpoints=(_r("/cmd", "A1", ("G1",)), _w("/state", "A2", ("R2",))),  # L1 not matched
        required_inputs=("/cmd",),
    )
    barrier = StartBarrier(["actuator", "lift", "recorder"])
    for report in (act, lift, rec):
        barrier.update(report)
    problems = barrier.pending(own)
    assert problems == ["/actuator: its writer of /state has matched 1 of 2 member endpoints"]
    # ...and the other way round: the writer matched, the reader not yet.
    lift = ReadinessReport("/lift", True, endpoints=(_r("/state", "L1", ()),))
    act = members[0]
    barrier.update(act)
    barrier.update(lift)
    assert barrier.pending(own) == [
        "/lift: its reader of /state has matched 0 of 1 member endpoints"
    ]


def test_required_input_without_publisher() -> None:
    barrier = StartBarrier(["lift"])
    barrier.update(
        ReadinessReport(
            "/lift", True, endpoints=(_r("/taps", "L2", ()),), required_inputs=("/taps",)
        )
    )
    assert barrier.pending() == ["/lift: no publisher of its input /taps yet"]


def test_recorder_must_have_a_reader_on_every_recorded_topic() -> None:
    own, members = _chain()
    act, lift, _ = members
    rec = ReadinessReport("/recorder", True, endpoints=(_r("/cmd", "R1", ("G1",)),), records=("*",))
    own = ReadinessReport("/generator", True, endpoints=(_w("/cmd", "G1", ("A1", "R1")),))
    act = ReadinessReport(
        "/actuator", True, endpoints=(_r("/cmd", "A1", ("G1",)), _w("/state", "A2", ("L1",)))
    )
    barrier = StartBarrier(["actuator", "lift", "recorder"])
    for report in (act, lift, rec):
        barrier.update(report)
    assert barrier.pending(own) == ["/recorder: not recording /state yet"]
    # A recorder of a topic list only waits for those topics; excluded topics never.
    barrier.update(
        ReadinessReport(
            "/recorder", True, endpoints=(_r("/cmd", "R1", ("G1",)),), records=("/cmd",)
        )
    )
    assert barrier.pending(own) == []
    barrier.update(
        ReadinessReport(
            "/recorder",
            True,
            endpoints=(_r("/cmd", "R1", ("G1",)),),
            records=("*",),
            excluded=("/state",),
        )
    )
    assert barrier.pending(own) == []


def test_incompatible_qos_pairs_are_not_required_to_match() -> None:
    best_effort = _w("/x", "W", (), reliable=False)
    reliable_reader = _r("/x", "R", ())
    assert not compatible(best_effort, reliable_reader)
    volatile = _w("/y", "W2", ())
    latched_reader = _r("/y", "R2", (), transient_local=True)
    assert not compatible(volatile, latched_reader)
    assert compatible(_w("/y", "W3", (), transient_local=True), _r("/y", "R3", ()))
    barrier = StartBarrier(["a", "b"])
    barrier.update(ReadinessReport("/a", True, endpoints=(best_effort, volatile)))
    barrier.update(ReadinessReport("/b", True, endpoints=(reliable_reader, latched_reader)))
    assert barrier.pending() == []


def test_each_endpoint_counts_every_compatible_member_endpoint() -> None:
    barrier = StartBarrier(["a", "b", "c"])
    barrier.update(ReadinessReport("/a", True, endpoints=(_w("/x", "a#w0", ("b#r0",)),)))
    barrier.update(ReadinessReport("/b", True, endpoints=(_r("/x", "b#r0", ("a#w0",)),)))
    barrier.update(ReadinessReport("/c", True, endpoints=(_r("/x", "c#r0", ()),)))
    assert barrier.pending() == [
        "/a: its writer of /x has matched 1 of 2 member endpoints",
        "/c: its reader of /x has matched 0 of 1 member endpoints",
    ]


def test_the_readiness_topic_itself_is_not_checked() -> None:
    barrier = StartBarrier(["a"])
    barrier.update(ReadinessReport("/a", True, endpoints=(_w(GRAPH_READY.name, "W", ()),)))
    barrier.update(ReadinessReport("/b", True, endpoints=(_r(GRAPH_READY.name, "R", ()),)))
    assert barrier.pending() == []


def test_report_message_round_trip() -> None:
    """Every field survives aero_rig_interfaces/ReadinessReport (the typestore's classes, whose
    fields are the .msg file's)."""
    own, members = _chain()

    def report_cls(**fields: object) -> object:
        return new_message(GRAPH_READY.type, **fields)

    def endpoint_cls(**fields: object) -> object:
        return new_message("aero_rig_interfaces/msg/Endpoint", **fields)

    for report in (own, *members):
        msg = report.to_message(report_cls, endpoint_cls)
        assert ReadinessReport.from_message(deserialize(serialize(msg), GRAPH_READY.type)) == report

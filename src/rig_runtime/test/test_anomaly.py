"""Anomaly records (anomaly.py): episodes, points, the wire format."""

import pytest

from rig_runtime.anomaly import Anomaly, AnomalyLog


def _log() -> tuple[AnomalyLog, list[Anomaly]]:
    sent: list[Anomaly] = []
    return AnomalyLog("/sim_actuator", sent.append), sent


def test_episode_is_published_open_then_closed_under_the_same_id() -> None:
    log, sent = _log()
    log.mark("free_run", 100, "no commands")
    log.mark("free_run", 105)
    log.mark("free_run", 110)
    assert len(sent) == 1 and sent[0].last_ns is None and sent[0].first_ns == 100
    log.clear("free_run")
    assert len(sent) == 2
    assert sent[1].id == sent[0].id and (sent[1].first_ns, sent[1].last_ns) == (100, 110)
    assert sent[1].detail == "no commands" and sent[1].node == "sim_actuator"
    log.clear("free_run")  # nothing open: nothing sent
    log.mark("free_run", 200)
    assert len(sent) == 3 and sent[2].id != sent[0].id


def test_end_at_a_given_stamp_and_close_all() -> None:
    log, sent = _log()
    log.begin("watchdog", 50, "trip")
    log.end("watchdog", 80)
    assert (sent[-1].first_ns, sent[-1].last_ns) == (50, 80)
    log.mark("not_tracking", 10)
    log.mark("invalid", 20)
    log.close_all()
    closed = {a.kind: a for a in sent[-2:]}
    assert closed["not_tracking"].last_ns == 10 and closed["invalid"].last_ns == 20
    assert not log.open


def test_point_orders_its_range() -> None:
    log, sent = _log()
    log.point("time_discontinuity", 300, 200, "backwards")
    log.point("no_pitch", 7)
    assert (sent[0].first_ns, sent[0].last_ns) == (200, 300)
    assert (sent[1].first_ns, sent[1].last_ns) == (7, 7)


def test_wire_format_round_trip_and_bad_input() -> None:
    a = Anomaly("lift/invalid_coefficients/3", "lift", "invalid_coefficients", 1, None, "x")
    assert Anomaly.from_json(a.to_json()) == a
    assert a.label() == "lift invalid_coefficients: x"
    with pytest.raises(ValueError, match="not an anomaly record"):
        Anomaly.from_json('{"id": "x"}')
    with pytest.raises(ValueError, match="not an anomaly record"):
        Anomaly.from_json("not json")

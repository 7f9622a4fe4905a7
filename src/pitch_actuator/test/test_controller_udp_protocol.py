"""Wire format and sequence bookkeeping of the controller link (no sockets)."""

import math
import struct

import pytest

from pitch_actuator.controller_protocol import (
    FEEDBACK_SIZE,
    HEARTBEAT_SIZE,
    SETPOINT_SIZE,
    Arrival,
    CommandFlag,
    Feedback,
    Heartbeat,
    ProtocolError,
    SessionTracker,
    Setpoint,
    Status,
    pack,
    seq_delta,
    seq_newer,
    unpack,
)


def _feedback(**changes: object) -> Feedback:
    fields: dict[str, object] = {
        "session": 7,
        "seq": 4_000_000_000,
        "stamp_ns": 1_700_000_000_123_456_789,
        "status": Status.ENABLED | Status.LIMIT,
        "applied_session": 99,
        "applied_seq": 12,
        "rx_lost": 3,
        "rx_duplicated": 2,
        "rx_reordered": 1,
        "position_rad": 0.25,
        "velocity_rad_s": -1.5,
        "target_rad": 0.26,
    }
    fields.update(changes)
    return Feedback(**fields)  # type: ignore[arg-type]


def test_byte_layout_matches_the_documented_offsets() -> None:
    """docs/protocols.md gives these offsets to controller implementers; they must hold."""
    sp = pack(
        Setpoint(
            0xA1B2C3D4,
            0x01020304,
            123456789012,
            0.5,
            CommandFlag.ENABLE | CommandFlag.VELOCITY_FF,
            -2.0,
        )
    )
    assert len(sp) == SETPOINT_SIZE == 48
    assert sp[0:4] == b"PWAC" and sp[4] == 1 and sp[5] == 1
    assert struct.unpack_from("<H", sp, 6)[0] == 48
    assert struct.unpack_from("<IIQ", sp, 8) == (0xA1B2C3D4, 0x01020304, 123456789012)
    assert struct.unpack_from("<I", sp, 24)[0] == 0b101
    assert struct.unpack_from("<dd", sp, 32) == (0.5, -2.0)

    hb = pack(Heartbeat(1, 2, 3, CommandFlag.STOP))
    assert len(hb) == HEARTBEAT_SIZE == 32 and hb[5] == 2
    assert struct.unpack_from("<I", hb, 24)[0] == 0b10

    fb = pack(_feedback())
    assert len(fb) == FEEDBACK_SIZE == 72 and fb[5] == 3
    assert struct.unpack_from("<IIIIII", fb, 24) == (0b1001, 99, 12, 3, 2, 1)
    assert struct.unpack_from("<ddd", fb, 48) == (0.25, -1.5, 0.26)


def test_every_message_round_trips() -> None:
    for message in (
        Setpoint(5, 6, 7, -0.1, CommandFlag.ENABLE),
        Setpoint(5, 2**32 - 1, 2**64 - 1, 0.3, CommandFlag.ENABLE | CommandFlag.VELOCITY_FF, 0.2),
        Heartbeat(5, 8, 9, CommandFlag(0)),
        _feedback(),
    ):
        assert unpack(pack(message)) == message


def test_non_finite_values_survive_the_wire_for_the_controller_to_reject() -> None:
    decoded = unpack(pack(Setpoint(1, 1, 1, math.nan)))
    assert isinstance(decoded, Setpoint) and math.isnan(decoded.position_rad)


@pytest.mark.parametrize(
    ("datagram", "message_part"),
    [
        (b"PWAC\x01", "shorter than the 24-byte header"),
        (b"XXXX" + pack(Heartbeat(1, 2, 3))[4:], "bad magic"),
        (pack(Heartbeat(1, 2, 3))[:4] + b"\x02" + pack(Heartbeat(1, 2, 3))[5:], "version 2"),
        (pack(Heartbeat(1, 2, 3))[:5] + b"\x09" + pack(Heartbeat(1, 2, 3))[6:], "unknown message"),
        (pack(Heartbeat(1, 2, 3)) + b"\x00", "expected exactly 32"),
        (pack(_feedback())[:-8], "expected exactly 72"),
    ],
)
def test_malformed_datagrams_raise_a_clear_protocol_error(
    datagram: bytes, message_part: str
) -> None:
    with pytest.raises(ProtocolError, match=message_part):
        unpack(datagram)


def test_packing_refuses_fields_that_do_not_fit() -> None:
    with pytest.raises(ProtocolError, match="u32"):
        pack(Heartbeat(1, 2**32, 3))


def test_serial_number_comparison_is_wrap_around_safe() -> None:
    assert seq_newer(1, 0) and not seq_newer(0, 1) and not seq_newer(5, 5)
    assert seq_newer(0, 2**32 - 1)  # the wrap: 0 follows 4294967295
    assert seq_newer(10, 2**32 - 10) and not seq_newer(2**32 - 10, 10)
    # Exactly half the number space apart is undefined in RFC 1982: never "newer".
    assert not seq_newer(2**31, 0) and not seq_newer(0, 2**31)
    assert seq_delta(3, 2**32 - 2) == 5 and seq_delta(2**32 - 2, 3) == -5


def test_tracker_classifies_loss_duplicates_and_reordering() -> None:
    tracker = SessionTracker()
    start = 2**32 - 3  # cross the wrap inside the test
    order = [0, 1, 3, 2, 2, 5, 7, 6, 6, 9]  # 4 and 8 never arrive
    arrivals = [tracker.observe(42, (start + n) % 2**32) for n in order]
    assert arrivals == [
        Arrival.FRESH,
        Arrival.FRESH,
        Arrival.FRESH,
        Arrival.LATE,
        Arrival.DUPLICATE,
        Arrival.FRESH,
        Arrival.FRESH,
        Arrival.LATE,
        Arrival.DUPLICATE,
        Arrival.FRESH,
    ]
    c = tracker.counters
    assert (c.received, c.fresh, c.lost, c.duplicated, c.reordered) == (10, 6, 2, 2, 2)


def test_tracker_restarts_on_a_new_session_and_refuses_the_old_one() -> None:
    tracker = SessionTracker()
    for seq in range(100, 110):
        tracker.observe(1, seq)
    # A restarted peer starts again at 0: must be fresh, not "very late".
    assert tracker.observe(2, 0) is Arrival.FRESH
    assert tracker.observe(2, 1) is Arrival.FRESH
    # A straggler of the old session must not switch back.
    assert tracker.observe(1, 110) is Arrival.RETIRED_SESSION
    assert tracker.observe(2, 2) is Arrival.FRESH
    c = tracker.counters
    assert (c.session_changes, c.retired_session, c.lost) == (1, 1, 0)


def test_a_packet_older_than_the_first_arrival_is_late_but_not_a_recovered_loss() -> None:
    tracker = SessionTracker()
    assert tracker.observe(3, 11) is Arrival.FRESH
    assert tracker.observe(3, 10) is Arrival.LATE
    assert tracker.observe(3, 10) is Arrival.DUPLICATE
    assert tracker.counters.lost == 0 and tracker.counters.reordered == 1

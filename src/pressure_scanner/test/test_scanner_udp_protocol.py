"""Scanner frame layout, validation, channel map and frame-counter bookkeeping (no sockets)."""

import struct
from pathlib import Path

import numpy as np
import pytest

from pressure_scanner.scanner_protocol import (
    PA_PER_UNIT,
    ChannelMap,
    FrameArrival,
    FrameCounterTracker,
    ScannerFrame,
    ScannerProtocolError,
    ScannerStatus,
    Units,
    frame_size,
    pack_frame,
    unpack_frame,
)


def _frame(n: int = 3, counter: int = 7, units: Units = Units.KPA) -> ScannerFrame:
    return ScannerFrame(
        frame_counter=counter,
        stamp_s=1_700_000_000,
        stamp_subsec_ns=999_999_999,
        units=units,
        pressures=np.arange(n, dtype=np.float32) * 0.25 - 0.1,
        status=ScannerStatus.ZEROING,
        serial=123,
    )


def test_byte_layout_matches_the_documented_offsets() -> None:
    data = pack_frame(_frame())
    assert len(data) == frame_size(3) == 32 + 12
    assert data[:4] == b"PWSC" and data[4] == 1 and data[5] == 1
    assert struct.unpack_from("<HIIIHHI", data, 6) == (3, 7, 1_700_000_000, 999_999_999, 1, 2, 123)
    assert struct.unpack_from("<3f", data, 32) == pytest.approx((-0.1, 0.15, 0.4))


def test_frames_round_trip_with_their_stamp() -> None:
    frame = _frame(64, counter=2**32 - 1)
    back = unpack_frame(pack_frame(frame))
    assert back.frame_counter == 2**32 - 1 and back.n_channels == 64
    assert back.stamp_ns == 1_700_000_000_999_999_999
    assert back.units is Units.KPA and back.status is ScannerStatus.ZEROING and back.serial == 123
    np.testing.assert_array_equal(back.pressures, frame.pressures)


@pytest.mark.parametrize(
    ("mutate", "message_part"),
    [
        (lambda d: d[:20], "shorter than the 32-byte frame header"),
        (lambda d: b"DSA1" + d[4:], "bad magic"),
        (lambda d: d[:4] + b"\x07" + d[5:], "version 7"),
        (lambda d: d[:5] + b"\x02" + d[6:], "not a pressure frame"),
        (lambda d: d[:6] + struct.pack("<H", 65) + d[8:], "1..64"),
        (lambda d: d[:-2], "truncated or padded"),
        (lambda d: d + b"\x00\x00\x00\x00", "truncated or padded"),
        (lambda d: d[:16] + struct.pack("<I", 10**9) + d[20:], "nanoseconds"),
        (lambda d: d[:20] + struct.pack("<H", 99) + d[22:], "unknown units code 99"),
    ],
)
def test_malformed_frames_raise_a_clear_error(mutate: object, message_part: str) -> None:
    with pytest.raises(ScannerProtocolError, match=message_part):
        unpack_frame(mutate(pack_frame(_frame())))  # type: ignore[operator]


def test_units_table_converts_to_pascal() -> None:
    assert PA_PER_UNIT[Units.INH2O] == pytest.approx(249.08891)
    assert PA_PER_UNIT[Units.PSI] == pytest.approx(6894.757, rel=1e-6)
    assert PA_PER_UNIT[Units.TORR] == pytest.approx(133.3224, rel=1e-6)
    assert set(PA_PER_UNIT) == set(Units)


def test_channel_map_places_channels_in_tap_order_and_reports_missing_taps() -> None:
    cmap = ChannelMap((2, -1, 0, 3), n_taps=5)  # channel 1 unused, tap 1 and 4 not connected
    assert cmap.missing_taps == (1, 4) and cmap.required_channels == 4
    taps = cmap.taps_from_channels(np.array([10.0, 11.0, 12.0, 13.0]))
    np.testing.assert_array_equal(taps[[0, 2, 3]], [12.0, 10.0, 13.0])
    assert np.isnan(taps[[1, 4]]).all()
    channels = cmap.channels_from_taps(np.array([1.0, 2.0, 3.0, 4.0, 5.0]), n_channels=6)
    np.testing.assert_array_equal(channels, [3.0, 0.0, 1.0, 4.0, 0.0, 0.0])


@pytest.mark.parametrize(
    ("table", "message_part"),
    [
        ((0, 1, 1), "tap 1 is mapped from channels 1 and 2"),
        ((0, 5), "must be a tap index 0..4"),
        ((0, -2), "or -1"),
        ((), "one per scanner channel"),
    ],
)
def test_bad_channel_maps_are_refused(table: tuple[int, ...], message_part: str) -> None:
    with pytest.raises(ValueError, match=message_part):
        ChannelMap(table, n_taps=5)


def test_channel_map_reads_a_ros2_parameter_file(tmp_path: Path) -> None:
    path = tmp_path / "scanner.yaml"
    path.write_text(
        "scanner_driver:\n"
        "  ros__parameters:\n"
        "    port: 23456\n"
        "    n_taps: 3\n"
        "    channel_to_tap: [2, 0, -1, 1]\n"
    )
    cmap = ChannelMap.from_yaml(path, node_name="scanner_driver")
    assert cmap.channel_to_tap == (2, 0, -1, 1) and cmap.n_taps == 3
    with pytest.raises(ValueError, match="no channel_to_tap found for node 'other'"):
        ChannelMap.from_yaml(path, node_name="other")
    path.write_text("channel_to_tap: [0, 0]\nn_taps: 2\n")
    with pytest.raises(ValueError, match="tap 0 is mapped from channels 0 and 1"):
        ChannelMap.from_yaml(path)


def test_tracker_reports_gaps_duplicates_late_frames_and_wrap() -> None:
    tracker = FrameCounterTracker()
    start = 2**32 - 2
    order = [0, 1, 2, 5, 4, 4, 6, 9]  # 3, 7, 8 never arrive; 4 late; one duplicate
    arrivals = [tracker.observe((start + n) % 2**32, 1000 * n) for n in order]
    assert arrivals.count(FrameArrival.FRESH) == 6
    assert arrivals[4] is FrameArrival.LATE and arrivals[5] is FrameArrival.DUPLICATE
    c = tracker.counters
    assert (c.lost, c.late, c.duplicated) == (3, 1, 1)
    gaps = list(tracker.recent_gaps)
    # The gap before 5 was 2 frames (3, 4) when detected; 4 came late afterwards.
    assert [(g.after_frame, g.missing, g.detected_stamp_ns) for g in gaps] == [
        (start + 2 - 2**32, 2, 5000),
        (start + 6 - 2**32, 2, 9000),
    ]


def test_tracker_resynchronises_when_the_scanner_restarts_its_counter() -> None:
    tracker = FrameCounterTracker()
    for n in range(5000, 5100):
        tracker.observe(n, n)
    assert tracker.observe(0, 0) is FrameArrival.LATE  # one straggler could be a stray
    assert tracker.observe(1, 1) is FrameArrival.RESTART
    assert tracker.observe(2, 2) is FrameArrival.FRESH
    assert tracker.counters.restarts == 1 and tracker.counters.lost == 0

"""ScannerClient fed with hand-made frames over loopback: units, mapping, range, tare, errors."""

import math
import socket
from collections.abc import Iterator

import numpy as np
import pytest

from pressure_scanner.scanner_client import ScannerClient, ScannerClientConfig, wait_frames
from pressure_scanner.scanner_protocol import ChannelMap, ScannerFrame, Units, pack_frame


@pytest.fixture
def sender() -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    try:
        yield sock
    finally:
        sock.close()


def _send(
    sock: socket.socket, port: int, counter: int, values: list[float], units: Units = Units.PA
) -> None:
    frame = ScannerFrame(
        frame_counter=counter,
        stamp_s=1_700_000_000 + counter // 200,
        stamp_subsec_ns=(counter % 200) * 5_000_000,
        units=units,
        pressures=np.array(values, dtype=np.float32),
    )
    sock.sendto(pack_frame(frame), ("127.0.0.1", port))


def _client(cmap: ChannelMap, **kwargs: object) -> ScannerClient:
    return ScannerClient(ScannerClientConfig(cmap, bind_host="127.0.0.1", **kwargs))  # type: ignore[arg-type]


def test_units_mapping_and_out_of_range_give_tap_pressures_in_pascal(
    sender: socket.socket,
) -> None:
    cmap = ChannelMap((2, -1, 0, 3), n_taps=5)  # tap 1 and 4 are not connected
    with _client(cmap, full_scale_pa=1000.0) as client:
        _send(sender, client.port, 0, [0.5, 9.0, -1.5, math.nan], Units.KPA)
        _send(sender, client.port, 1, [-0.25, 0.0, 0.999, 0.125], Units.KPA)
        frames = wait_frames(client, 2, 2.0)
        assert [f.frame_counter for f in frames] == [0, 1]
        first, second = frames
        assert first.stamp_ns == 1_700_000_000_000_000_000
        assert second.stamp_ns - first.stamp_ns == 5_000_000
        # tap 2 ← channel 0 (500 Pa); tap 0 ← channel 2 (-1500 Pa, beyond ±1000 → NaN);
        # tap 3 ← channel 3 (NaN reading → NaN); taps 1, 4 missing → NaN but not out of range.
        assert first.pressures_pa[2] == pytest.approx(500.0)
        assert np.isnan(first.pressures_pa[[0, 1, 3, 4]]).all()
        np.testing.assert_array_equal(first.out_of_range, [True, False, False, True, False])
        np.testing.assert_allclose(second.pressures_pa[[0, 2, 3]], [999.0, -250.0, 125.0])
        assert not second.out_of_range.any()
        stats = client.statistics()
        assert stats.out_of_range_samples == 3  # the unused channel's 9 kPa counts too
        assert stats.missing_taps == (1, 4)
        np.testing.assert_array_equal(client.out_of_range_counts, [1, 0, 0, 1, 0])


def test_tare_removes_the_per_channel_offsets_and_flags_doubtful_channels(
    sender: socket.socket,
) -> None:
    cmap = ChannelMap.identity(4)
    offsets = np.array([12.0, -7.5, 100.0, math.nan])  # ch 2 too large, ch 3 dead
    rng = np.random.default_rng(1)
    with _client(cmap, full_scale_pa=2000.0) as client:
        client.start()
        client.start_tare(40)
        assert client.tare_in_progress
        for k in range(40):
            _send(sender, client.port, k, list(offsets + rng.normal(0.0, 0.5, 4)))
        result = client.wait_for_tare(2.0)
        assert not client.tare_in_progress
        np.testing.assert_allclose(result.offsets_pa[:3], offsets[:3], atol=0.3)
        np.testing.assert_allclose(result.std_pa[:3], 0.5, rtol=0.4)
        assert result.failed_channels == (3,)
        assert result.suspicious_channels == (2,)  # 100 Pa > 2 % of 2000 Pa: wind on?
        client.poll()  # discard the tare frames
        signal = np.array([50.0, -30.0, 5.0, 1.0])
        _send(sender, client.port, 40, list(signal + offsets))
        (frame,) = wait_frames(client, 1, 2.0)
        assert frame.tared
        np.testing.assert_allclose(frame.pressures_pa[:3], signal[:3], atol=0.3)
        assert np.isnan(frame.pressures_pa[3])
        # Saved offsets can be restored or removed.
        client.set_offsets(None)
        _send(sender, client.port, 41, list(signal))
        (raw,) = wait_frames(client, 1, 2.0)
        assert not raw.tared and raw.pressures_pa[3] == pytest.approx(1.0)


def test_bad_datagrams_are_counted_with_a_reason_and_the_stream_goes_on(
    sender: socket.socket,
) -> None:
    cmap = ChannelMap.identity(3)
    with _client(cmap) as client:
        _send(sender, client.port, 0, [1.0, 2.0, 3.0])
        sender.sendto(
            b"not a frame at all, but long enough for a header", ("127.0.0.1", client.port)
        )
        _send(sender, client.port, 1, [1.0, 2.0])  # fewer channels than the map reads
        _send(sender, client.port, 2, [4.0, 5.0, 6.0])
        frames = wait_frames(client, 2, 2.0)
        assert [f.frame_counter for f in frames] == [0, 2]
        stats = client.statistics()
        assert stats.invalid_frames == 2
        assert "has 2 channels but the channel map reads channel 2" in stats.last_invalid_reason
        # Counter 1 was rejected before the bookkeeping: it is reported as lost.
        assert stats.frames.lost == 1 and stats.recent_gaps[0].after_frame == 0


def test_frames_from_another_source_are_ignored(sender: socket.socket) -> None:
    with _client(ChannelMap.identity(2), source_host="127.0.0.2") as client:
        _send(sender, client.port, 0, [1.0, 2.0])
        assert wait_frames(client, 1, 0.3) == []
        assert client.statistics().foreign_datagrams == 1


def test_invalid_settings_are_refused_before_binding() -> None:
    with pytest.raises(ValueError, match="full_scale_pa"):
        ScannerClientConfig(ChannelMap.identity(2), full_scale_pa=0.0)
    with _client(ChannelMap.identity(2)) as client, pytest.raises(ValueError, match="n_frames"):
        client.start_tare(0)

"""ScannerClient against the simulated scanner process on loopback."""

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from scanner_udp_support import run_sim_scanner

from pressure_scanner.scanner_client import ScannerClient, ScannerClientConfig, TapPressures
from pressure_scanner.scanner_protocol import ChannelMap
from rig_testing.processes import wait_for
from wing_sim.plant import WingPlant
from wing_sim.sim_scanner import zero_offsets_pa

RATE_HZ = 200.0


def _shuffled_map(seed: int) -> ChannelMap:
    """49 taps scattered over 64 channels, 15 channels unused."""
    table = [*range(49), *([-1] * 15)]
    np.random.default_rng(seed).shuffle(table)
    return ChannelMap(tuple(int(t) for t in table), n_taps=49)


def _write_map(cmap: ChannelMap, path: Path) -> None:
    path.write_text(
        "pressure_scanner_driver:\n  ros__parameters:\n    n_taps: 49\n"
        f"    channel_to_tap: {list(cmap.channel_to_tap)}\n"
    )


def _plant_taps(seed: int, alphas_rad: list[float]) -> np.ndarray:
    """(len(alphas), 49) tap pressures of the plant run in-process [Pa]."""
    plant = WingPlant(seed=seed)
    return np.array([plant.step(a) for a in alphas_rad], dtype=np.float64)


def test_pressures_stamps_and_stream_faults_arrive_as_sent(tmp_path: Path) -> None:
    seed, n_frames = 5, 240
    cmap = _shuffled_map(seed)
    _write_map(cmap, tmp_path / "map.yaml")
    frames: list[TapPressures] = []
    received_ns: list[int] = []

    def on_frame(frame: TapPressures) -> None:
        frames.append(frame)
        received_ns.append(time.time_ns())

    config = ScannerClientConfig(cmap, bind_host="127.0.0.1", full_scale_pa=1e5)
    with ScannerClient(config) as client:
        client.start(on_frame)
        started_ns = time.time_ns()
        summary = run_sim_scanner(
            [
                *("--port", str(client.port), "--rate", str(RATE_HZ)),
                *("--frames", str(n_frames), "--seed", str(seed)),
                *("--alpha-deg", "8", "--alpha-amp-deg", "4", "--alpha-freq-hz", "2"),
                *("--channels", "64", "--channel-map", str(tmp_path / "map.yaml")),
                *("--units", "INH2O", "--zero-offset-pa", "15"),
                *("--drop", "10,11,12,100", "--duplicate", "20,150", "--swap", "60"),
                *("--bad-magic", "30", "--truncate", "31"),
            ],
            tmp_path / "err.txt",
            timeout_s=20.0,
        )
        # The last frame is the sender's last datagram: every fault before it is counted.
        assert wait_for(lambda: bool(frames) and frames[-1].frame_counter == n_frames - 1, 5.0)
        stats = client.statistics()
    assert summary == {"frames_generated": n_frames, "frames_sent": n_frames - 4}

    # Faults are reported with exact counts; the stream itself stays in order.
    f = stats.frames
    assert (f.lost, f.duplicated, f.late, f.restarts) == (4, 2, 1, 0)
    assert [(g.after_frame, g.missing) for g in stats.recent_gaps] == [(9, 3), (59, 1), (99, 1)]
    assert stats.invalid_frames == 2 and "truncated" in stats.last_invalid_reason
    counters = [fr.frame_counter for fr in frames]
    expected_counters = [k for k in range(n_frames) if k not in {10, 11, 12, 100, 60}]
    assert counters == expected_counters

    # Stamps: the acquisition instants k/rate apart, just before each frame's arrival.
    stamps = np.array([fr.stamp_ns for fr in frames])
    np.testing.assert_array_equal(
        stamps - stamps[0], (np.array(counters) - counters[0]) * 5_000_000
    )
    assert stamps[0] > started_ns
    latency_s = (np.array(received_ns) - stamps) * 1e-9
    assert latency_s.min() > -0.005  # a stamp is never later than the frame's arrival

    # Pressures: the plant run here with the same seed and α(t), plus each tap's channel
    # offset (untared), through float32 inH2O and back.
    alphas = [
        math.radians(8.0 + 4.0 * math.sin(2 * math.pi * 2.0 * j / RATE_HZ)) for j in range(n_frames)
    ]
    expected = _plant_taps(seed, alphas) + cmap.taps_from_channels(zero_offsets_pa(64, 15.0, seed))
    got = np.array([fr.pressures_pa for fr in frames])
    np.testing.assert_allclose(got, expected[counters], rtol=1e-6, atol=1e-3)
    assert not any(fr.tared for fr in frames)
    assert np.ptp(got[:, 0]) > 1.0  # the sine really moved the pressures


def test_tare_at_wind_off_removes_the_zero_offsets(tmp_path: Path) -> None:
    seed, wind_off, n_frames, n_tare = 2, 60, 160, 50
    frames: list[TapPressures] = []
    config = ScannerClientConfig(ChannelMap.identity(49, 64), bind_host="127.0.0.1")
    with ScannerClient(config) as client:
        client.start(frames.append)
        client.start_tare(n_tare)
        run_sim_scanner(
            [
                *("--port", str(client.port), "--rate", str(RATE_HZ)),
                *("--frames", str(n_frames), "--seed", str(seed), "--alpha-deg", "6.6"),
                *("--wind-off-frames", str(wind_off), "--zero-offset-pa", "25"),
                *("--units", "KPA"),
            ],
            tmp_path / "err.txt",
            timeout_s=20.0,
        )
        result = client.wait_for_tare(2.0)
        assert wait_for(lambda: bool(frames) and frames[-1].frame_counter == n_frames - 1, 5.0)
    offsets = zero_offsets_pa(64, 25.0, seed)
    # Mean of 50 wind-off frames with 0.5 Pa noise: within 5 σ of the true offsets.
    np.testing.assert_allclose(result.offsets_pa, offsets, atol=5 * 0.5 / math.sqrt(n_tare))
    assert result.n_frames == n_tare and result.failed_channels == ()

    by_counter = {fr.frame_counter: fr for fr in frames}
    assert len(by_counter) == n_frames
    assert not by_counter[n_tare - 2].tared and by_counter[n_tare].tared
    # Remaining wind-off frames read zero after the tare ...
    rest_off = np.array([by_counter[k].pressures_pa for k in range(n_tare, wind_off)])
    assert np.abs(rest_off).max() < 3.0
    # ... and wind-on frames read the plant's pressures, which the offsets would have spoiled.
    expected = _plant_taps(seed, [math.radians(6.6)] * (n_frames - wind_off))
    got = np.array([by_counter[k].pressures_pa for k in range(wind_off, n_frames)])
    np.testing.assert_allclose(got, expected, atol=0.5)
    untared_error = np.abs(got + offsets[:49] - expected).max()
    assert untared_error > 10.0

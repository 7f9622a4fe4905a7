"""Simulated pressure scanner streaming PWSC frames over UDP (``docs/protocols.md``).

Run as a process::

    python -m wing_sim.sim_scanner --port 5000 --rate 200 --alpha-deg 6.6 \\
        --alpha-amp-deg 2 --alpha-freq-hz 0.5 --frames 2000

It sends to ``--host:--port`` (where the scanner driver listens) from an ephemeral port, which
it prints as the first line on stdout; once its first frame is sent it prints
``{"first_frame_sent": counter}``, and when it ends its summary (JSON, the last line). Frame k
is acquired at t0 + k/rate (real-time pacing;
the stamp is that instant). Its pressures are the
:class:`wing_sim.plant.WingPlant` response to the prescribed angle of attack

    α_j = alpha_deg + alpha_amp_deg · sin(2π · alpha_freq_hz · j / rate),  j = k − wind_off_frames

placed on the scanner channels by the channel → tap table, plus a fixed per-channel zero offset
(so a tare matters). The first ``--wind-off-frames`` frames are wind off: zero offset plus
reading noise only, the plant is not stepped. For tests, chosen frames can be dropped,
duplicated, swapped with their successor, or preceded by a malformed datagram; the plant is
stepped for every frame counter whether or not the frame is sent.
"""

import argparse
import json
import math
import signal
import socket
import sys
import time
from collections.abc import Sequence

import numpy as np

from pressure_scanner.scanner_protocol import (
    MAX_CHANNELS,
    PA_PER_UNIT,
    ChannelMap,
    ScannerFrame,
    Units,
    pack_frame,
)
from rig_runtime.signals import StopSignals


def zero_offsets_pa(n_channels: int, amplitude_pa: float, seed: int) -> np.ndarray:
    """The simulated scanner's fixed per-channel zero offsets, uniform in ±amplitude [Pa]."""
    rng = np.random.default_rng([seed, 0x5A5A])
    return rng.uniform(-amplitude_pa, amplitude_pa, n_channels)


def alpha_rad(j: int, rate_hz: float, alpha_deg: float, amp_deg: float, freq_hz: float) -> float:
    """Prescribed angle of attack of wind-on sample j."""
    return math.radians(alpha_deg + amp_deg * math.sin(2.0 * math.pi * freq_hz * j / rate_hz))


def _frame_list(text: str) -> set[int]:
    if not text:
        return set()
    try:
        return {int(item) for item in text.split(",") if item.strip()}
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give frame counters separated by commas, e.g. 10,11,40"
        ) from None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m wing_sim.sim_scanner",
        description="Simulated pressure scanner (PWSC UDP frames from the WingPlant).",
    )
    p.add_argument("--host", default="127.0.0.1", help="address the driver listens on")
    p.add_argument("--port", type=int, required=True, help="UDP port the driver listens on")
    p.add_argument("--rate", type=float, default=200.0, help="frame rate [Hz]")
    p.add_argument("--frames", type=int, default=0, help="frames to send; 0 = until stopped")
    p.add_argument("--alpha-deg", type=float, default=6.6, help="mean angle of attack [deg]")
    p.add_argument("--alpha-amp-deg", type=float, default=0.0, help="sine amplitude [deg]")
    p.add_argument("--alpha-freq-hz", type=float, default=0.0, help="sine frequency [Hz]")
    p.add_argument("--seed", type=int, default=0, help="WingPlant seed (and offsets, noise)")
    p.add_argument("--channels", type=int, default=64, help="scanner channels per frame")
    p.add_argument("--channel-map", default=None, help="YAML with channel_to_tap (see docs)")
    p.add_argument(
        "--units", default="PA", choices=[u.name for u in Units], help="units of the frames"
    )
    p.add_argument("--zero-offset-pa", type=float, default=20.0, help="±offset amplitude [Pa]")
    p.add_argument("--wind-off-frames", type=int, default=0, help="leading wind-off frames")
    p.add_argument("--wind-off-noise-pa", type=float, default=0.5, help="noise wind off [Pa]")
    p.add_argument("--serial", type=int, default=4242, help="scanner serial number")
    p.add_argument("--start-counter", type=int, default=0, help="first frame counter (u32)")
    p.add_argument("--drop", type=_frame_list, default=set(), help="frames not to send")
    p.add_argument("--duplicate", type=_frame_list, default=set(), help="frames sent twice")
    p.add_argument("--swap", type=_frame_list, default=set(), help="frames sent after the next")
    p.add_argument(
        "--bad-magic", type=_frame_list, default=set(), help="send a bad-magic datagram before"
    )
    p.add_argument(
        "--truncate", type=_frame_list, default=set(), help="send a truncated copy before"
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if not 1 <= args.channels <= MAX_CHANNELS or args.rate <= 0 or args.frames < 0:
        print(
            f"sim_scanner: need 1..{MAX_CHANNELS} channels, rate > 0 and frames >= 0 "
            f"(got {args.channels}, {args.rate}, {args.frames})",
            file=sys.stderr,
        )
        return 2
    try:
        cmap = (
            ChannelMap.from_yaml(args.channel_map)
            if args.channel_map
            else ChannelMap.identity(49, args.channels)
        )
    except (OSError, ValueError) as exc:
        print(f"sim_scanner: channel map: {exc}", file=sys.stderr)
        return 2
    if cmap.required_channels > args.channels:
        print(
            f"sim_scanner: the channel map uses {cmap.required_channels} channels, "
            f"--channels is {args.channels}",
            file=sys.stderr,
        )
        return 2

    from wing_sim.plant import WingPlant

    plant = WingPlant(seed=args.seed)
    units = Units[args.units]
    pa_per_unit = PA_PER_UNIT[units]
    offsets = zero_offsets_pa(args.channels, args.zero_offset_pa, args.seed)
    noise = np.random.default_rng([args.seed, 0x0FF])

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1" if args.host.startswith("127.") else "0.0.0.0", 0))
    print(sock.getsockname()[1], flush=True)
    dest = (args.host, args.port)

    stop = StopSignals(signal.SIGTERM, signal.SIGINT).install()  # for the process's life

    def send(datagram: bytes) -> None:
        try:
            sock.sendto(datagram, dest)
        except OSError:
            pass  # a scanner streams on whether or not anyone listens

    period_ns = 1e9 / args.rate
    t0_ns = 0
    t0_mono = 0.0
    swapped: bytes | None = None
    sent = 0
    k = 0
    try:
        while not stop and (args.frames == 0 or k < args.frames):
            counter = (args.start_counter + k) % (1 << 32)
            # Compute frame k before its send time, so a slow first plant step (imports,
            # caches) delays the start of the stream instead of putting it behind schedule.
            if k < args.wind_off_frames:
                channels_pa = offsets + noise.normal(0.0, args.wind_off_noise_pa, args.channels)
            else:
                j = k - args.wind_off_frames
                alpha = alpha_rad(
                    j, args.rate, args.alpha_deg, args.alpha_amp_deg, args.alpha_freq_hz
                )
                taps_pa = np.asarray(plant.step(alpha), dtype=np.float64)
                channels_pa = cmap.channels_from_taps(taps_pa, args.channels) + offsets
            if k == 0:
                t0_ns, t0_mono = time.time_ns(), time.monotonic()
            delay = t0_mono + k / args.rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            stamp = t0_ns + round(k * period_ns)  # the acquisition instant on the schedule
            datagram = pack_frame(
                ScannerFrame(
                    frame_counter=counter,
                    stamp_s=stamp // 1_000_000_000,
                    stamp_subsec_ns=stamp % 1_000_000_000,
                    units=units,
                    pressures=(channels_pa / pa_per_unit).astype(np.float32),
                    serial=args.serial,
                )
            )
            if counter in args.bad_magic:
                send(b"XXXX" + datagram[4:])
            if counter in args.truncate:
                send(datagram[:-6])
            if counter not in args.drop:
                if counter in args.swap:
                    swapped = datagram
                else:
                    send(datagram)
                    if counter in args.duplicate:
                        send(datagram)
                    sent += 1
                    if swapped is not None:
                        send(swapped)
                        sent += 1
                        swapped = None
            if k == 0:  # the stream has begun (a slow start delays it, see above)
                print(json.dumps({"first_frame_sent": counter}), flush=True)
            k += 1
    finally:
        sock.close()
        print(json.dumps({"frames_generated": k, "frames_sent": sent}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

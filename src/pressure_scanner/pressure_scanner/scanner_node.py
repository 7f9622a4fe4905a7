"""Hardware scanner node: a Scanivalve-style Ethernet pressure scanner (PWSC UDP frames,
docs/protocols.md) to ``/pressure/taps``.

Frames are mapped channel -> tap (``channel_to_tap``, one entry per scanner channel, -1 =
unused), converted to Pa, checked against the scanner's full scale (beyond it: NaN, excluded by
the lift node) and stamped with the scanner's acquisition time. Lost, duplicated and reordered
frames are counted and reported on ``/diagnostics``, never patched. A zero (tare) is taken on
request — wind off! — by publishing ``true`` on ``/pressure/tare`` (std_msgs/Bool): the mean of
the next ``tare_frames`` frames becomes the per-channel offset.
"""

import sys
from collections.abc import Sequence

from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Bool

from rig_runtime import Node, Parameter, new_message, run_node, set_stamp
from rig_runtime.diagnostics import diagnostic_array
from rig_runtime.interface import DIAGNOSTICS, PRESSURE_TAPS, PRESSURE_TARE
from rig_runtime.qos_profiles import DEFAULT_QOS, QOS_BY_NAME

from .scanner_client import ScannerClient, ScannerClientConfig, TapPressures
from .scanner_protocol import ChannelMap
from .tap_cloud import fill_cloud, point_fields
from .taps import load_taps
from .wing_geometry import RigGeometry

PARAMETERS = [
    Parameter("bind_host", "0.0.0.0", "interface the scanner streams to"),
    Parameter("port", 23000, "UDP port the scanner streams to", min=0, max=65535),
    Parameter("source_host", "", "accept frames only from this IPv4 address (empty: any)"),
    Parameter("full_scale_pa", 2490.0, "scanner module full scale [Pa]", min=1.0),
    Parameter(
        "channel_to_tap", list(range(49)), "tap index read by each scanner channel (-1: none)"
    ),
    Parameter("taps_file", "", "tap layout YAML (empty: the package's config/taps.yaml)"),
    Parameter("tare_frames", 400, "frames averaged by a zero (tare)", min=1),
    Parameter("poll_rate_hz", 400.0, "how often received frames are published [Hz]", min=10.0),
    Parameter("diagnostics_period_s", 1.0, "period of /diagnostics status [s]", min=0.05),
    Parameter(
        "taps_qos", "sensor", "QoS of /pressure/taps", choices=("stream", "sensor", "default")
    ),
]


class ScannerNode(Node):
    NODE_NAME = "scanner"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.parameter_values()
        taps = load_taps(p["taps_file"] or None)
        params = RigGeometry()
        self.tap_xyz = taps.xyz_m(params.chord_m, params.span_m)
        channel_map = ChannelMap(tuple(p["channel_to_tap"]), n_taps=taps.n_taps)
        self.client = ScannerClient(
            ScannerClientConfig(
                channel_map=channel_map,
                bind_host=p["bind_host"],
                port=p["port"],
                full_scale_pa=p["full_scale_pa"],
                source_host=p["source_host"] or None,
            )
        )
        self.fields = point_fields(new_message)
        # The taps stream on the serialized path (node.py).
        self.taps_pub = self.create_publisher(
            PRESSURE_TAPS.type, PRESSURE_TAPS.name, QOS_BY_NAME[p["taps_qos"]]
        )
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, DEFAULT_QOS)
        self.create_subscription(Bool, PRESSURE_TARE.name, self.on_tare, DEFAULT_QOS)
        self.create_timer(1.0 / p["poll_rate_hz"], self.on_timer)
        self.create_timer(p["diagnostics_period_s"], self.publish_diagnostics)
        self.published = 0
        self.tare_reported = True
        self.on_shutdown(self.client.close)
        self.get_logger().info(f"listening for scanner frames on UDP port {self.client.port}")

    def on_tare(self, msg: Bool) -> None:
        if msg.data:
            frames = self.get_parameter("tare_frames").value
            self.get_logger().warning(f"zero (tare) over {frames} frames: wind must be off")
            self.client.start_tare(frames)
            self.tare_reported = False

    lost_reported = 0
    last_stamp_ns: int | None = None

    def on_timer(self) -> None:
        frames = self.client.poll()
        for frame in frames:
            self.publish(frame)
        if frames:
            # Frames lost since the last poll: the stretch from the last frame before this batch
            # to the last of it is reported, so the identification excludes the periods it
            # touches (the lost frames themselves are missing samples there).
            lost = self.client.statistics().frames.lost
            if lost > self.lost_reported:
                first = self.last_stamp_ns if self.last_stamp_ns is not None else frames[0].stamp_ns
                self.anomalies.point(
                    "frame_loss",
                    first,
                    frames[-1].stamp_ns,
                    f"{lost - self.lost_reported} scanner frame(s) lost",
                )
                self.lost_reported = lost
            self.last_stamp_ns = frames[-1].stamp_ns
        result = self.client.tare_result
        if not self.tare_reported and result is not None and not self.client.tare_in_progress:
            self.tare_reported = True
            self.get_logger().info(
                f"tare done over {result.n_frames} frames; failed channels "
                f"{list(result.failed_channels)}, suspicious {list(result.suspicious_channels)}"
            )

    def publish(self, frame: TapPressures) -> None:
        cloud = new_message(PRESSURE_TAPS.type)
        set_stamp(cloud.header.stamp, frame.stamp_ns)
        cloud.header.frame_id = "wing"
        fill_cloud(cloud, new_message, self.tap_xyz, frame.pressures_pa, self.fields)
        self.taps_pub.publish(cloud)
        self.published += 1

    def publish_diagnostics(self) -> None:
        stats = self.client.statistics()
        frames = stats.frames
        lost = frames.lost
        values = {
            "published": str(self.published),
            "frames_lost": str(lost),
            "frames_duplicated": str(frames.duplicated),
            "frames_late": str(frames.late),
            "recent_gaps": "; ".join(str(g) for g in stats.recent_gaps[-5:]) or "none",
            "invalid_frames": str(stats.invalid_frames),
            "out_of_range_samples": str(stats.out_of_range_samples),
            "missing_taps": str(list(stats.missing_taps)),
            "tared": str(stats.tared),
        }
        level = 1 if lost or stats.invalid_frames or stats.missing_taps else 0
        msg = diagnostic_array(
            f"{self.name}: pressure scanner",
            level,
            f"{lost} frames lost" if lost else "ok",
            f"pwsc://udp:{self.client.port}",
            values,
        )
        self.diagnostics_pub.publish(msg)


def main(argv: list[str] | None = None) -> int:
    return run_node(ScannerNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())

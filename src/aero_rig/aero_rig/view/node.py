"""Rerun view of a pitching-wing experiment, live (an rclpy node) or from a rosbag.

Shows, on the ``experiment_time`` timeline (the message stamps): commanded and measured pitch
[deg] and C_l over time; the Cp distribution over the chord (−Cp up, upper and lower surface,
decimated); on each ``/identification/model`` update the FRF |G| [dB] with its noise and
nonlinear-distortion variances [dB] per level, the cluster label of every period, the models'
C_l–α predictions against the measured sine records and the validation table; segment events and
identification status as text logs. A blueprint lays these out.

Modes: ``save`` writes ``rrd_path``; ``spawn`` starts a Rerun Viewer; ``serve`` runs a gRPC
server a viewer connects to; ``connect`` streams to a running viewer at ``url``; ``none`` only
counts messages (not ``off``: YAML reads that as false). With ``rrd_path`` set, every mode
also saves to that file.

This module imports rerun (numpy >= 2): run it from the project's virtual environment, where
the PyPI rclpy wheels work with numpy 2 (docs/design.md §3.9). ``RigViewLogger`` has no
middleware and takes plain messages; ``view_bag`` replays a recorded bag through it, without
rclpy.

The ``view`` node subscribes the rig topics and logs them through ``RigViewLogger``.
"""

from collections.abc import Callable, Sequence
from typing import Any, ClassVar

from rig_runtime import Node, Parameter, run_node
from rig_runtime.interface import (
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_MODEL,
    IDENTIFICATION_STATUS,
    PITCH_COMMAND,
    PITCH_STATE,
    PRESSURE_TAPS,
    WING_COEFFICIENTS,
)
from rig_runtime.qos_profiles import QOS_BY_NAME

from .logger import RigViewLogger
from .recording import MODES, TOPICS, close_recording, open_recording, takes_cdr

PARAMETERS = [
    Parameter("mode", "save", "where the view goes", choices=MODES),
    Parameter("rrd_path", "", ".rrd file to write (needed by 'save'; other modes also save)"),
    Parameter("application_id", "aero_rig", "Rerun application id (groups recordings)"),
    Parameter("taps_decimation", 10, "log every n-th Cp distribution / C_l–α trail", min=1),
    Parameter("series_decimation", 1, "log every n-th pitch / C_l sample", min=1),
    Parameter(
        "series_flush_s",
        0.1,
        "send the buffered pitch / C_l samples every … s (a batch of 200 goes at once)",
        min=0.01,
    ),
    Parameter("trail_s", 2.0, "length of the live C_l–α trail [s]", min=0.0),
    Parameter("port", 0, "spawn: viewer port; serve: gRPC port (0 = 9876)", min=0, max=65535),
    Parameter("bind_ip", "127.0.0.1", "serve: address to listen on (0.0.0.0 = all)"),
    Parameter("url", "", "connect: viewer gRPC URL (empty: rerun+http://127.0.0.1:9876/proxy)"),
    Parameter("stats_period_s", 10.0, "log message counts every … s (0 = never)", min=0.0),
]


class ViewNode(Node):
    """The view node: subscribes the rig topics and feeds a :class:`RigViewLogger`.

    Every reader takes the runtime's messages (the serialized path, node.py), the messages a
    recorded bag gives ``view_bag``, so that the live and the replayed view are drawn by the
    same code. High-rate streams are read best effort (a slow viewer drops samples, it never
    holds back the experiment; best effort matches reliable and best-effort publishers);
    segment events reliable and deep; model and status latched, so a late view still gets the
    current model.
    """

    # The histories hold several times what the generator may publish at once (its
    # max_lead_samples, 1000, when credit returns), so that a view busy drawing a model or a Cp
    # frame takes the burst late instead of dropping its oldest samples.
    QOS: ClassVar[dict[str, tuple[str, int | None]]] = {
        PITCH_COMMAND.name: ("sensor", 5000),
        PITCH_STATE.name: ("sensor", 5000),
        PRESSURE_TAPS.name: ("sensor", 1000),
        WING_COEFFICIENTS.name: ("sensor", 5000),
        EXPERIMENT_SEGMENT.name: (EXPERIMENT_SEGMENT.qos, None),
        IDENTIFICATION_MODEL.name: (IDENTIFICATION_MODEL.qos, None),
        IDENTIFICATION_STATUS.name: (IDENTIFICATION_STATUS.qos, 100),
    }

    NODE_NAME = "view"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.parameter_values()
        self.rec, where = open_recording(
            p["application_id"],
            p["mode"],
            p["rrd_path"] or None,
            port=p["port"],
            url=p["url"],
            bind_ip=p["bind_ip"],
        )
        self.rerun_log = RigViewLogger(
            self.rec,
            taps_decimation=p["taps_decimation"],
            series_decimation=p["series_decimation"],
            trail_s=p["trail_s"],
        )
        self.errors = 0
        self.readers: list[Any] = []
        for topic, (type_name, handler) in TOPICS.items():
            qos, depth = self.QOS[topic]
            call = getattr(self.rerun_log, handler)
            raw = takes_cdr(handler)  # a raw subscription: (CDR bytes, receive time)
            if raw:
                call = self._serialized(call)
            self.readers.append(
                self.create_subscription(
                    type_name,
                    topic,
                    self._guard(topic, call),
                    QOS_BY_NAME[qos],
                    depth=depth,
                    raw=raw,
                )
            )
        # The series go to Rerun in batches (RigViewLogger): this bounds how long a sample waits.
        self.create_timer(p["series_flush_s"], self.rerun_log.send_series)
        if p["stats_period_s"] > 0:
            self.create_timer(p["stats_period_s"], self.log_stats)
        self.on_shutdown(self.close_recording)
        self.get_logger().info(f"view: {where}")

    @staticmethod
    def _serialized(handler: Callable[[Any], None]) -> Callable[[Any], None]:
        def call(sample: tuple[bytes, int]) -> None:
            handler(sample[0])

        return call

    def _guard(self, topic: str, handler: Callable[[Any], None]) -> Callable[[Any], None]:
        def call(msg: Any) -> None:
            try:
                handler(msg)
            except (ValueError, KeyError, TypeError) as exc:
                self.errors += 1
                self.rerun_log.warn(topic, str(exc).removeprefix(f"{topic}: "))
                if self.errors <= 20 or self.errors % 1000 == 0:
                    self.get_logger().warning(f"{topic}: {exc} ({self.errors} bad messages)")

        return call

    def log_stats(self) -> None:
        """Counts of what arrived, and how many of the view's readers have matched a writer (a
        best-effort reader drops what a writer sends before the reader has matched it)."""
        counts = " ".join(f"{k}={v}" for k, v in self.rerun_log.counts.items())
        matched = sum(s.publisher_count() > 0 for s in self.readers)
        self.get_logger().info(
            f"received {counts} errors={self.errors} matched={matched}/{len(self.readers)}"
        )

    def close_recording(self) -> None:
        """At shutdown: the counts and the report logged, the buffered series sent, the
        recording closed."""
        try:
            self.log_stats()
            self.get_logger().info(self.rerun_log.report())
        finally:
            self.rerun_log.send_series()
            close_recording(self.rec)


def main(argv: Sequence[str] | None = None) -> int:
    return run_node(ViewNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    raise SystemExit(main())

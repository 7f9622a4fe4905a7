"""Lift node: tap pressures to force coefficients by pressure integration (docs/design.md §6).

Subscribes ``/pressure/taps`` and ``/pitch/state`` (measured pitch = geometric angle of attack)
and publishes ``/wing/coefficients`` (geometry_msgs/Vector3Stamped: x = C_l, y = C_d (pressure),
z = C_m about the quarter chord) with the taps' stamp: exactly one coefficients sample per taps
sample. The pitch is matched by stamp (exact in simulation; linear interpolation between the
neighbouring states on the rig, within ``max_alpha_gap_s``). Taps that are NaN or outside the
scanner range are excluded; a sample whose remaining taps do not cover the surface is invalid
and published as NaN, never as a number. Exclusions are counted on ``/diagnostics``; each run of
NaN samples is one ``invalid_coefficients`` anomaly on ``/experiment/anomaly``.

Every ``PROGRESS_PERIOD_S`` in which it published coefficients, it publishes the stamp of the
latest on ``/wing/coefficients/progress`` (std_msgs/Header): a simulated stream's generator
takes its credit from it (multisine_gen.pacing) instead of reading every coefficients sample.
"""

import math
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Header

from rig_runtime import Node, Parameter, new_message, run_node, stamp_to_ns
from rig_runtime.diagnostics import diagnostic_array
from rig_runtime.interface import (
    DIAGNOSTICS,
    PITCH_JOINT,
    PITCH_STATE,
    PRESSURE_TAPS,
    WING_COEFFICIENTS,
    WING_PROGRESS,
    joint_position,
)
from rig_runtime.qos_profiles import DEFAULT_QOS, QOS_BY_NAME, topic_qos

from .integration import DEFAULT_SCANNER_RANGE_PA, PressureIntegrator
from .pitch_alignment import PitchAlignment
from .tap_cloud import read_cloud
from .taps import load_taps
from .wing_geometry import RigGeometry

PARAMETERS = [
    Parameter(
        "dynamic_pressure_pa",
        RigGeometry().dynamic_pressure_pa,
        "free-stream dynamic pressure q = ½ρU² [Pa] (rig: from the Pitot tube)",
        min=1.0,
    ),
    Parameter("taps_file", "", "tap layout YAML (empty: the package's config/taps.yaml)"),
    Parameter("scanner_min_pa", float(DEFAULT_SCANNER_RANGE_PA[0]), "scanner range, low [Pa]"),
    Parameter("scanner_max_pa", float(DEFAULT_SCANNER_RANGE_PA[1]), "scanner range, high [Pa]"),
    Parameter(
        "max_alpha_gap_s", 0.02, "largest stamp gap to interpolate the pitch over [s]", min=0.0
    ),
    Parameter("max_pending", 5000, "taps samples kept waiting for their pitch", min=1),
    Parameter("diagnostics_period_s", 1.0, "period of /diagnostics status [s]", min=0.05),
    Parameter("qos", "stream", "QoS of inputs and output", choices=("stream", "sensor", "default")),
]

HISTORY = 4000
# Period of /wing/coefficients/progress [s]: at the simulation's full speed (about 5,000 samples
# a second) a credit every 25 samples or so, far inside the generator's lead (1,000 samples).
PROGRESS_PERIOD_S = 0.005
# At shutdown, how long the readers are drained for the waiting taps' pitch [s]: a stopped
# graph's last states are in the reader already or arrive within a heartbeat (100 ms).
DRAIN_TIMEOUT_S = 1.0


def gap_ns(seconds: float) -> int:
    """``max_alpha_gap_s`` as integer nanoseconds for :class:`PitchAlignment`.

    Stamp differences are integers, so ``d <= s * 1e9`` holds exactly when ``d <= int(s * 1e9)``
    (s >= 0); infinity (any gap) becomes a bound no difference of two stamps reaches.
    """
    ns = seconds * 1e9
    return int(ns) if math.isfinite(ns) else 2**64


class LiftNode(Node):
    NODE_NAME = "lift"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.parameter_values()
        self.q = p["dynamic_pressure_pa"]
        self.integrator = PressureIntegrator(
            load_taps(p["taps_file"] or None), (p["scanner_min_pa"], p["scanner_max_pa"])
        )
        self.n_taps = self.integrator.taps.n_taps
        self.alignment = PitchAlignment(gap_ns(p["max_alpha_gap_s"]), p["max_pending"], HISTORY)
        self.counts = {"published": 0, "invalid": 0, "alpha_missing": 0}
        self.excluded_per_tap = np.zeros(self.n_taps, dtype=np.int64)
        self.last_reason = ""
        # The sample streams (coefficients, pitch, taps) on the serialized path (node.py).
        qos = QOS_BY_NAME[p["qos"]]
        self.coefficients_pub = self.create_publisher(
            WING_COEFFICIENTS.type, WING_COEFFICIENTS.name, qos
        )
        self.progress_pub = self.create_publisher(
            Header, WING_PROGRESS.name, topic_qos(WING_PROGRESS)
        )
        self.latest_stamp: Any = None  # of the last coefficients sample published
        self.progress_stamp: Any = None  # the last one /wing/coefficients/progress carried
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, DEFAULT_QOS)
        self.create_subscription(
            PITCH_STATE.type, PITCH_STATE.name, self.on_pitch, qos, required=True
        )
        self.create_subscription(
            PRESSURE_TAPS.type, PRESSURE_TAPS.name, self.on_taps, qos, required=True
        )
        self.create_timer(p["diagnostics_period_s"], self.publish_diagnostics)
        self.create_timer(PROGRESS_PERIOD_S, self.publish_progress)
        self.on_shutdown(self.flush)

    def on_pitch(self, msg: Any) -> None:
        # A state without a finite pitch still takes its stamp: the taps at that stamp are
        # counted as alpha_missing, not aligned to a neighbouring state.
        pitch = joint_position(msg, PITCH_JOINT)
        stamp = stamp_to_ns(msg.header.stamp)
        released = self.alignment.add_pitch(stamp, math.nan if pitch is None else pitch)
        for stamp, taps, alpha in released:
            self._process(stamp, taps, alpha)

    def on_taps(self, msg: Any) -> None:
        for stamp, taps, alpha in self.alignment.add_sample(stamp_to_ns(msg.header.stamp), msg):
            self._process(stamp, taps, alpha)

    def _process(self, stamp: int, msg: Any, alpha: float | None) -> None:
        if alpha is None or not math.isfinite(alpha):
            self.counts["alpha_missing"] += 1
            cl = cd = cm = math.nan
            self.last_reason = "no pitch sample near the taps' stamp"
        else:
            _, pressures = read_cloud(msg)
            if len(pressures) != self.n_taps:
                # A cloud of another layout cannot be integrated with this tap geometry.
                pressures = np.full(self.n_taps, np.nan)
                self.last_reason = f"cloud has {len(msg.data) // 16} points, expected {self.n_taps}"
            c = self.integrator.integrate(pressures, alpha, self.q)
            cl, cd, cm = float(c.cl[0]), float(c.cd[0]), float(c.cm[0])
            self.excluded_per_tap += c.excluded[0]
            if not c.valid[0]:
                self.counts["invalid"] += 1
                self.last_reason = c.describe(0)
        if math.isfinite(cl):
            self.anomalies.clear("invalid_coefficients")
        else:
            self.anomalies.mark("invalid_coefficients", stamp, self.last_reason)
        out = new_message(WING_COEFFICIENTS.type)
        out.header.stamp = msg.header.stamp
        out.header.frame_id = "wing"
        out.vector.x, out.vector.y, out.vector.z = cl, cd, cm
        self.coefficients_pub.publish(out)
        self.counts["published"] += 1
        self.latest_stamp = out.header.stamp

    def publish_progress(self) -> None:
        if self.latest_stamp is None or self.latest_stamp is self.progress_stamp:
            return
        self.progress_stamp = stamp = self.latest_stamp
        progress = Header(frame_id="wing")
        progress.stamp.sec, progress.stamp.nanosec = int(stamp.sec), int(stamp.nanosec)
        self.progress_pub.publish(progress)

    def publish_diagnostics(self) -> None:
        excluded = {
            self.integrator.taps.names[i]: int(n) for i, n in enumerate(self.excluded_per_tap) if n
        }
        problems = self.counts["invalid"] + self.counts["alpha_missing"]
        level = 1 if problems or excluded else 0
        values = {k: str(v) for k, v in self.counts.items()}
        values["excluded_taps"] = ", ".join(f"{k}: {v}" for k, v in excluded.items()) or "none"
        values["pending"] = str(self.alignment.pending_count)
        msg = diagnostic_array(
            f"{self.name}: pressure integration", level, self.last_reason or "ok", "lift", values
        )
        self.diagnostics_pub.publish(msg)

    def flush(self) -> None:
        """At shutdown: the pitch states already received for the taps still waiting taken
        (the readers drained, at most ``DRAIN_TIMEOUT_S``), then the taps released with what is
        known, then the last progress and diagnostics. Without the drain, taps whose state sat
        in the reader when the graph stopped would count as having no pitch."""
        self.drain(lambda: self.alignment.pending_count == 0, DRAIN_TIMEOUT_S)
        for stamp, taps, alpha in self.alignment.flush():
            self._process(stamp, taps, alpha)
        self.publish_progress()
        self.publish_diagnostics()


def main(argv: list[str] | None = None) -> int:
    return run_node(LiftNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())

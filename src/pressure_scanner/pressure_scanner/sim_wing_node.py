"""Simulated wing node: the dynamic-stall plant with 49 pressure taps (DESIGN.md §6).

Reactive: every ``/pitch/state`` sample yields one ``/pressure/taps`` sample with the same
stamp. The angle of attack is the state's ``alpha_true`` joint (simulation ground truth: true
pitch + free-stream gust, from the simulated actuator) or, without it, the ``pitch`` joint.
Deterministic for a seed whatever the speed. A state without a finite pitch gets no taps sample
and is reported on ``/experiment/anomaly`` (``no_pitch``).
"""

import math
import sys
from typing import Any

from rig_runtime import Node, Parameter, run_node, stamp_to_ns

from .plant import WingPlant
from .tap_cloud import fill_cloud, point_fields
from .taps import load_taps
from .wing_params import WingParams

PARAMETERS = [
    Parameter("seed", 0, "seed of stall switching, vortex strength, drift and noise", min=0),
    Parameter("taps_file", "", "tap layout YAML (empty: the package's config/taps.yaml)"),
    Parameter(
        "taps_qos", "stream", "QoS of /pressure/taps", choices=("stream", "sensor", "default")
    ),
]


def joint_position(msg: Any, name: str) -> float | None:
    names = list(msg.name)
    if name in names:
        i = names.index(name)
        if i < len(msg.position):
            return float(msg.position[i])
    return None


class SimWing:
    def __init__(self, node: Node) -> None:
        p = node.params
        self.node = node
        taps = load_taps(p["taps_file"] or None)
        self.plant = WingPlant(WingParams(), taps, seed=p["seed"])
        self.fields = point_fields(node.new_message)
        self.pub = node.create_publisher(
            "sensor_msgs/msg/PointCloud2", "/pressure/taps", p["taps_qos"]
        )
        node.create_subscription(
            "sensor_msgs/msg/JointState", "/pitch/state", self.on_state, "stream", required=True
        )
        self.refused = 0
        node.logger.info(
            "simulated wing: %d taps, q = %.1f Pa", taps.n_taps, self.plant.dynamic_pressure_pa
        )

    def on_state(self, msg: Any) -> None:
        alpha = joint_position(msg, "alpha_true")
        if alpha is None:
            alpha = joint_position(msg, "pitch")
        if alpha is None or not math.isfinite(alpha):
            self.refused += 1
            self.node.anomalies.point(
                "no_pitch",
                stamp_to_ns(msg.header.stamp),
                detail="state without a finite pitch: no taps sample for it",
            )
            return
        pressures = self.plant.step(alpha)
        cloud = self.node.new_message("sensor_msgs/msg/PointCloud2")
        cloud.header.stamp = msg.header.stamp
        cloud.header.frame_id = "wing"
        fill_cloud(cloud, self.node.new_message, self.plant.tap_xyz, pressures, self.fields)
        self.pub.publish(cloud)


def main(argv: list[str] | None = None) -> int:
    return run_node(SimWing, "sim_wing", PARAMETERS, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())

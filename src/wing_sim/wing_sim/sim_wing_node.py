"""Simulated wing node: the dynamic-stall plant with 49 pressure taps (docs/design.md §6).

Reactive: every ``/pitch/state`` sample yields one ``/pressure/taps`` sample with the same
stamp. The angle of attack is the state's ``alpha_true`` joint (simulation ground truth: true
pitch + free-stream gust, from the simulated actuator) or, without it, the ``pitch`` joint.
Deterministic for a seed whatever the speed. A state without a finite pitch gets no taps sample
and is reported on ``/experiment/anomaly`` (``no_pitch``).
"""

import sys
from collections.abc import Mapping, Sequence
from typing import Any

from pressure_scanner.tap_cloud import fill_cloud, point_fields
from pressure_scanner.taps import load_taps
from rig_runtime import Node, Parameter, new_message, run_node, stamp_to_ns
from rig_runtime.interface import (
    ALPHA_TRUE_JOINT,
    PITCH_JOINT,
    PITCH_STATE,
    PRESSURE_TAPS,
    joint_position,
)
from rig_runtime.qos_profiles import QOS_BY_NAME, topic_qos

from .plant import WingPlant
from .wing_params import PRESETS, WingParams, wing_params_preset

PARAMETERS = [
    Parameter("seed", 0, "seed of stall switching, vortex strength, drift and noise", min=0),
    Parameter("taps_file", "", "tap layout YAML (empty: the package's config/taps.yaml)"),
    Parameter(
        "taps_qos", "stream", "QoS of /pressure/taps", choices=("stream", "sensor", "default")
    ),
    Parameter(
        "preset", "stall_regimes", "named wing parameter set", choices=tuple(sorted(PRESETS))
    ),
    Parameter(
        "light_stall_fraction",
        -1.0,
        "fraction of the time in the light-stall regime, 0 <= x < 0.5; < 0: the preset's",
    ),
    Parameter("light_stall_dwell_s", -1.0, "mean light-stall episode [s], > 0; <= 0: the preset's"),
]


def wing_params(p: Mapping[str, Any]) -> WingParams:
    """The WingParams of the node's parameters: the preset, then the set overrides."""
    overrides: dict[str, float] = {}
    if p["light_stall_fraction"] >= 0:
        overrides["light_stall_fraction"] = float(p["light_stall_fraction"])
    if p["light_stall_dwell_s"] > 0:
        overrides["light_stall_dwell_s"] = float(p["light_stall_dwell_s"])
    return wing_params_preset(p["preset"], **overrides)


class SimWingNode(Node):
    NODE_NAME = "sim_wing"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.parameter_values()
        taps = load_taps(p["taps_file"] or None)
        self.plant = WingPlant(wing_params(p), taps, seed=p["seed"])
        self.fields = point_fields(new_message)
        # The state and taps streams on the serialized path (node.py).
        self.taps_pub = self.create_publisher(
            PRESSURE_TAPS.type, PRESSURE_TAPS.name, QOS_BY_NAME[p["taps_qos"]]
        )
        self.create_subscription(
            PITCH_STATE.type, PITCH_STATE.name, self.on_state, topic_qos(PITCH_STATE), required=True
        )
        self.refused = 0
        self.get_logger().info(
            f"simulated wing ({p['preset']}): {taps.n_taps} taps, "
            f"q = {self.plant.dynamic_pressure_pa:.1f} Pa, "
            f"light-stall fraction {self.plant.params.light_stall_fraction:.2f}"
        )

    def on_state(self, msg: Any) -> None:
        # The plant's truth when the actuator gives it, else the measured pitch.
        joint = ALPHA_TRUE_JOINT if ALPHA_TRUE_JOINT in msg.name else PITCH_JOINT
        alpha = joint_position(msg, joint)
        if alpha is None:  # joint_position: None for a missing or non-finite joint
            self.refused += 1
            self.anomalies.point(
                "no_pitch",
                stamp_to_ns(msg.header.stamp),
                detail="state without a finite pitch: no taps sample for it",
            )
            return
        pressures = self.plant.step(alpha)
        cloud = new_message(PRESSURE_TAPS.type)
        cloud.header.stamp = msg.header.stamp
        cloud.header.frame_id = "wing"
        fill_cloud(cloud, new_message, self.plant.tap_xyz, pressures, self.fields)
        self.taps_pub.publish(cloud)


def main(argv: list[str] | None = None) -> int:
    return run_node(SimWingNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())

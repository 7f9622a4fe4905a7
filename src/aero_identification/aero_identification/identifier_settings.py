"""The identifier's parameters, declared once, and the one function that resolves them.

The identifier node declares :data:`PARAMETERS` (identifier_node.py) and reads its settings
with :func:`identifier_settings`; ``aero-rig campaign`` resolves the same declaration from the
graph's parameter files and overrides and reads the same settings when it recovers the final
identification from the bag. No middleware: the CLI uses it where rclpy may not import.
"""

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rig_runtime.params import Parameter

from . import adaptive
from .adaptive import AdaptiveRules
from .hyperparameters import IdentificationConfig, config_from_parameters, config_parameters

PARAMETERS = [
    Parameter("output_dir", "", "run directory for models.json and the report ('' = none)"),
    # The identification hyperparameters, declared with their ranges in hyperparameters.py.
    *config_parameters(),
    # Adaptive runs: the switch and the rules' thresholds, declared in adaptive.py.
    *adaptive.PARAMETERS,
    Parameter("use_worker", True, "refit in a worker process (false: inline, for debugging)"),
    Parameter(
        "exit_after_final",
        True,
        "exit once the final identification is published (live: ros2 param set)",
        read_only=False,
    ),
    Parameter(
        "max_early_samples",
        20000,
        "samples kept while waiting for the plan (live: ros2 param set)",
        min=0,
        read_only=False,
    ),
    Parameter(
        "input_qos",
        "stream",
        "QoS of /pitch/state and /wing/coefficients (sensor on the rig: best effort)",
        choices=("stream", "sensor", "default"),
    ),
]


@dataclass(frozen=True)
class IdentifierSettings:
    """The identifier's read-only parameters, as the identification uses them.

    ``exit_after_final`` and ``max_early_samples`` are not here: they can change while the node
    runs (``ros2 param set``), so the node reads them where it needs them.
    """

    output_dir: str  # run directory for models.json and the report ('' = none)
    config: IdentificationConfig  # the pipeline's hyperparameters
    adaptive: bool  # steer the generator (adaptive.py)
    rules: AdaptiveRules  # the adaptive rules' thresholds
    use_worker: bool  # refit in a worker process (false: inline)
    input_qos: str  # QoS profile of the two sample streams


def identifier_settings(values: Mapping[str, Any]) -> IdentifierSettings:
    """The settings from validated values of :data:`PARAMETERS`: the node's (rcl resolved its
    ``--ros-args``) or ``rig_runtime.params.resolve_parameters``' (a graph's files and
    overrides)."""
    values = dict(values)
    return IdentifierSettings(
        output_dir=values["output_dir"],
        config=config_from_parameters(values),
        adaptive=bool(values["adaptive"]),
        rules=AdaptiveRules.from_parameters(values),
        use_worker=bool(values["use_worker"]),
        input_qos=values["input_qos"],
    )

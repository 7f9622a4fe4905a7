"""The fields of the ``/identification/model`` message (aero_rig_interfaces/IdentificationModel)
from the identifier's payload (identification_result.IdentificationResult.to_json_dict, with the
node's refit count; model_payload.py names its keys).

The summary fields are what a user filters and plots on without parsing the record: the refit,
whether it is the final fit, the model class cross-validation selected, one LevelSummary per
level and Table 1's cells as TableCell rows. The whole payload travels beside them as JSON in
``model_json``, exactly as the node published it on std_msgs/String before. Pure: no ROS; the
node builds the messages from these dictionaries, and :func:`model_from_message` reads the
record back from a message of rclpy or of rosbags' typestore (also the std_msgs/String of a bag
recorded before the typed message).
"""

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

from rig_runtime.interface import IDENTIFICATION_MODEL
from rig_runtime.json_payload import json_object

from . import model_payload as msg

__all__ = [
    "level_summary_fields",
    "model_from_message",
    "model_message_fields",
    "model_stamp_ns",
    "table_cell_fields",
]


def _int(value: Any, absent: int) -> int:
    return absent if value is None else int(value)


def _float(value: Any) -> float:
    return math.nan if value is None else float(value)


def level_summary_fields(level: Mapping[str, Any]) -> dict[str, Any]:
    """A LevelSummary's fields of one ``levels`` entry (identification_result.level_json):
    -1 where a count is absent (no usable periods yet), 0 clusters and dominant -1 when the
    level was not clustered."""
    clusters = level.get(msg.CLUSTERS) or {}
    return {
        "name": str(level.get("name", "")),
        "offset_deg": _float(level.get(msg.OFFSET_DEG)),
        "role": str(level.get("role", "")),
        "periods": _int(level.get("P"), -1),
        "realizations": _int(level.get("M"), -1),
        "periods_used": _int(level.get("periods_used"), -1),
        "excluded_periods": len(level.get("excluded_periods") or ()),
        "clusters": _int(clusters.get(msg.K), 0),
        "dominant_cluster": _int(clusters.get(msg.DOMINANT), -1),
        "cluster_sizes": [int(s) for s in clusters.get(msg.SIZES) or ()],
    }


def table_cell_fields(
    rows: Sequence[Sequence[Any]] | None, spread_rows: Sequence[Sequence[Any]] | None
) -> list[dict[str, Any]]:
    """TableCell fields of Table 1's ``errors`` rows ``[[model, level, freq_hz, error], ...]``,
    each with the spread of the ``*_std`` row of the same model, level and frequency (its
    ``None``, or no such row: NaN)."""
    spreads: dict[tuple[str, str, float], float] = {}
    for model, level, freq_hz, spread in spread_rows or ():
        spreads[(str(model), str(level), float(freq_hz))] = _float(spread)
    cells = []
    for model, level, freq_hz, error in rows or ():
        key = (str(model), str(level), float(freq_hz))
        cells.append(
            {
                "model": key[0],
                "level": key[1],
                "frequency_hz": key[2],
                "error": _float(error),
                "spread": spreads.get(key, math.nan),
            }
        )
    return cells


def model_stamp_ns(payload: Mapping[str, Any], default: int) -> int:
    """The header stamp of a model payload: its experiment time (model_payload.STAMP_NS) when it
    has one, else ``default`` (the identifier's: the last sample the fit had)."""
    stamp = payload.get(msg.STAMP_NS)
    return default if stamp is None else int(stamp)


def model_message_fields(payload: Mapping[str, Any]) -> dict[str, Any]:
    """The IdentificationModel fields (but its header) of a model payload; LevelSummary and
    TableCell entries as dictionaries of their fields."""
    selection = payload.get("selection") or {}
    errors = payload.get("errors") or {}
    levels = payload.get(msg.LEVELS) or {}
    return {
        "refit": int(payload.get(msg.REFIT, 0)),
        "complete": bool(payload.get("complete", False)),
        # pipeline.select_model's class: identification_result.SELECTED_PNLSS or SELECTED_LPV.
        "selected_class": str(selection.get("class", "")),
        "levels": [level_summary_fields(level) for level in levels.values()],
        "table1": table_cell_fields(errors.get("all_levels"), errors.get("all_levels_std")),
        "table1_level1": table_cell_fields(errors.get("level1"), errors.get("level1_std")),
        "warnings": [str(w) for w in payload.get(msg.WARNINGS) or ()],
        "model_json": json.dumps(payload, allow_nan=True),
    }


def model_from_message(msg: Any) -> dict[str, Any]:
    """The record of an ``/identification/model`` message: ``json.loads(msg.model_json)`` of an
    IdentificationModel, ``json.loads(msg.data)`` of an old std_msgs/String. ValueError naming
    the topic when it is neither or holds no JSON object."""
    return json_object(msg, "model_json", IDENTIFICATION_MODEL.name)

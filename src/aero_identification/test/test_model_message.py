"""The /identification/model message's fields (model_message.py) from the payload of a real
identification result (identification_result.IdentificationResult.to_json_dict): the levels'
summaries, Table 1's cells with their spreads, the selected class, and the whole payload as
model_json; and that rclpy and the runtime's typestore take them."""

import json
import math
from typing import Any

import numpy as np
import pytest

from aero_identification import model_payload
from aero_identification.clustering import ClusterResult
from aero_identification.dataset import LevelRecord
from aero_identification.hyperparameters import IdentificationConfig
from aero_identification.identification_result import (
    SELECTED_PNLSS,
    IdentificationResult,
    LevelResult,
)
from aero_identification.model_message import model_message_fields, model_stamp_ns
from aero_identification.periodic_data import PeriodicData
from aero_rig_interfaces.msg import IdentificationModel, LevelSummary, TableCell
from rig_runtime.interface import IDENTIFICATION_MODEL
from rig_runtime.messages import deserialize, new_message, serialize, set_stamp, stamp_to_ns

PNLSS, BLA_SS = "PNLSS", "BLA SS"  # Table 1's rows (report_tables.TABLE1_MODELS)


def _payload() -> dict[str, Any]:
    """A refit's payload: a clustered level with periods, a level without usable periods yet,
    Table 1 cells of which one has no spread (a single period) and one diverged."""
    n, p, m = 8, 4, 2
    t = np.arange(n)[:, None, None] * np.ones((1, p, m))
    data = PeriodicData(np.sin(t), 0.1 * np.sin(t), fs=8.0, excited_lines=np.array([1]))
    low = LevelResult(
        LevelRecord("low", data, key="0", offset_deg=6.6, excluded=("realization 1 period 3: x",)),
        periods_used=6,
    )
    low.clusters = ClusterResult(
        labels=np.array([[0, 0], [0, 1], [0, 0], [1, -1]]),
        keep=np.ones((p, m), dtype=bool),
        k=2,
        silhouette={2: 0.4},
        sizes=np.array([5, 2]),
        dominant=0,
        period_index=np.zeros((p, m), dtype=int),
        realization_index=np.arange(m),
    )
    high = LevelResult(LevelRecord("high", None, key="1", offset_deg=None))
    result = IdentificationResult(config=IdentificationConfig(), fs=8.0, sines_planned=True)
    result.levels = {"low": low, "high": high}
    result.errors_all = {(PNLSS, "low", 1.0): 0.12, (BLA_SS, "high", 1.6): 0.3}
    result.spreads_all = {(PNLSS, "low", 1.0): 0.02, (BLA_SS, "high", 1.6): math.nan}
    result.errors_level1 = {(PNLSS, "low", 1.0): math.inf}
    result.spreads_level1 = {(PNLSS, "low", 1.0): math.nan}
    result.warnings = ["PNLSS (level 1) diverged"]
    result.selection = {"class": SELECTED_PNLSS, "structure": "nx 2", "held_out": "p 3"}
    result.complete = True
    payload = result.to_json_dict()
    payload[model_payload.REFIT] = 3  # as the identifier node adds them
    payload["refit_s"] = 1.5
    return payload


PAYLOAD = _payload()


def test_the_summary_fields_of_a_real_payload() -> None:
    fields = model_message_fields(PAYLOAD)
    assert (fields["refit"], fields["complete"], fields["selected_class"]) == (3, True, "PNLSS")
    low, high = fields["levels"]
    assert low == {
        "name": "low",
        "offset_deg": 6.6,
        "role": "estimation",
        "periods": 4,
        "realizations": 2,
        "periods_used": 6,
        "excluded_periods": 1,
        "clusters": 2,
        "dominant_cluster": 0,
        "cluster_sizes": [5, 2],
    }
    assert math.isnan(high.pop("offset_deg"))
    assert high == {
        "name": "high",
        "role": "estimation",
        "periods": -1,
        "realizations": -1,
        "periods_used": 0,
        "excluded_periods": 0,
        "clusters": 0,
        "dominant_cluster": -1,
        "cluster_sizes": [],
    }
    first, second = fields["table1"]
    assert first == {
        "model": PNLSS,
        "level": "low",
        "frequency_hz": 1.0,
        "error": 0.12,
        "spread": 0.02,
    }
    assert (second["level"], second["error"]) == ("high", 0.3) and math.isnan(second["spread"])
    (cell,) = fields["table1_level1"]
    assert cell["error"] == math.inf and math.isnan(cell["spread"])
    assert fields["warnings"] == ["PNLSS (level 1) diverged"]
    assert fields["model_json"] == json.dumps(PAYLOAD, allow_nan=True)
    assert json.loads(fields["model_json"])["refit"] == 3


def test_a_payload_without_selection_levels_or_errors_has_empty_summaries() -> None:
    fields = model_message_fields({model_payload.REFIT: 1, "selection": None})
    assert (fields["selected_class"], fields["levels"], fields["table1"]) == ("", [], [])
    assert fields["complete"] is False and fields["warnings"] == []


def test_a_cell_without_a_spread_row_has_nan() -> None:
    errors = {"all_levels": [[PNLSS, "low", 1.0, 0.1]], "all_levels_std": []}
    (cell,) = model_message_fields({"errors": errors})["table1"]
    assert math.isnan(cell["spread"])


@pytest.mark.parametrize(("payload", "stamp"), [({}, 7), ({model_payload.STAMP_NS: 42}, 42)])
def test_the_stamp_is_the_payloads_when_it_has_one(payload: dict[str, Any], stamp: int) -> None:
    assert model_stamp_ns(payload, 7) == stamp


def test_rclpy_and_the_typestore_take_the_fields() -> None:
    fields = model_message_fields(PAYLOAD)
    msg = IdentificationModel(
        **fields
        | {
            "levels": [LevelSummary(**lv) for lv in fields["levels"]],
            "table1": [TableCell(**c) for c in fields["table1"]],
            "table1_level1": [TableCell(**c) for c in fields["table1_level1"]],
        }
    )
    assert msg.levels[0].cluster_sizes.tolist() == [5, 2] and msg.table1[0].spread == 0.02
    stored = new_message(
        IDENTIFICATION_MODEL.type,
        **fields
        | {
            "levels": [
                new_message("aero_rig_interfaces/msg/LevelSummary", **lv) for lv in fields["levels"]
            ],
            "table1": [
                new_message("aero_rig_interfaces/msg/TableCell", **c) for c in fields["table1"]
            ],
            "table1_level1": [
                new_message("aero_rig_interfaces/msg/TableCell", **c)
                for c in fields["table1_level1"]
            ],
        },
    )
    set_stamp(stored.header.stamp, 123_456_789_012)
    back = deserialize(serialize(stored), IDENTIFICATION_MODEL.type)
    assert stamp_to_ns(back.header.stamp) == 123_456_789_012
    assert json.loads(back.model_json) == json.loads(fields["model_json"])
    assert [lv.name for lv in back.levels] == ["low", "high"]
    assert back.table1[0].model == PNLSS and math.isinf(back.table1_level1[0].error)

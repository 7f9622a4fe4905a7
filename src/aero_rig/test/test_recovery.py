"""The campaign's recovery from the bag (aero_rig/recovery.py) without a graph: when the
identifier's report asks for it, when the bag cannot give more, and the identifier's parameters
it fits with. The recovery's fit itself runs in the campaign tests (tests/test_campaign.py)."""

import json
from pathlib import Path

import pytest

from aero_identification.hyperparameters import IdentificationConfig
from aero_rig.cli.common import config_path
from aero_rig.recovery import identifier_config, recover_from_whole_bag, samples_missed
from rig_runtime.graph import load_graph
from rig_runtime.launcher import Launcher
from rig_runtime.params import ParameterError


def _report(run_dir: Path, missing: dict[str, int]) -> None:
    samples = {name: {"missing": n, "expected": 100} for name, n in missing.items()}
    (run_dir / "models.json").write_text(json.dumps({"data_quality": {"samples": samples}}))


def test_samples_the_identifier_missed_are_named(tmp_path: Path) -> None:
    assert samples_missed(tmp_path) is None  # no report: nothing to compare
    _report(tmp_path, {"pitch": 0, "C_l": 0})
    assert samples_missed(tmp_path) is None
    _report(tmp_path, {"pitch": 3, "C_l": 0})
    assert samples_missed(tmp_path) == (
        "the identifier's final identification missed plan samples (3 pitch)"
    )


def test_no_recovery_from_a_bag_without_the_plan(tmp_path: Path) -> None:
    said: list[str] = []
    launcher = Launcher(load_graph(config_path("sim.yaml")))
    assert recover_from_whole_bag(tmp_path, launcher, 0, "it died", said.append) is None
    assert said == ["it died; the bag lacks samples too (no plan seen): no recovery"]


def test_the_recovery_fits_with_the_identifiers_own_parameters() -> None:
    graph = load_graph(config_path("sim.yaml"))
    assert identifier_config(Launcher(graph)) == IdentificationConfig()  # identifier.yaml
    campaign = {"identifier": {"max_iter": 7, "scan": False, "adaptive": True}}
    config = identifier_config(Launcher(graph, overrides=campaign))
    assert (config.max_iter, config.scan) == (7, False)
    with pytest.raises(ParameterError, match="from the campaign"):
        identifier_config(Launcher(graph, overrides={"identifier": {"max_iter": -1}}))

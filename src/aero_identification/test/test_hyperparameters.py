"""The identification hyperparameters' one declaration (hyperparameters.py) and what follows
from it: the identifier node's parameters, aero_rig's identifier.yaml, the JSON form and the CLI
flags."""

import argparse
import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from aero_identification.hyperparameters import (
    IdentificationConfig,
    add_config_arguments,
    config_from_args,
    config_from_parameters,
    config_parameters,
    parse_degrees,
)
from rig_runtime.params import ParameterError, default_parameters, resolve_parameters

FIELDS = dataclasses.fields(IdentificationConfig)
NAMES = [f.name for f in FIELDS]
IDENTIFIER_YAML = Path(__file__).resolve().parents[2] / "aero_rig" / "config" / "identifier.yaml"


def _parameter_form(value: Any) -> Any:
    """A field's default as a node parameter: tuples as lists, degree sets as "2,3"."""
    if isinstance(value, tuple):
        if value and isinstance(value[0], tuple):
            return [",".join(map(str, s)) for s in value]
        return list(value)
    return value


def test_every_field_declares_a_description_and_a_range() -> None:
    for f in FIELDS:
        assert f.metadata["description"], f.name
        assert set(f.metadata) == {"description", "min", "max", "choices"}, f.name
    meta = {f.name: f.metadata for f in FIELDS}
    assert (meta["nx"]["min"], meta["nx"]["max"]) == (0, 12)
    assert IdentificationConfig().max_order == 12
    assert IdentificationConfig(nx=0).nx == 0  # 0: the order scan chooses per level


def test_the_node_declares_every_field_with_its_default_and_range() -> None:
    """identifier_node.PARAMETERS and the dataclass cannot drift apart."""
    from aero_identification.identifier_node import PARAMETERS

    declared = {p.name: p for p in PARAMETERS}
    assert len(declared) == len(PARAMETERS)
    node_only = set(declared) - set(NAMES)
    assert node_only == {
        "output_dir",
        "use_worker",
        "exit_after_final",
        "max_early_samples",
        "input_qos",
        # the adaptive run's switch and rules, declared in adaptive.py
        "adaptive",
        "adaptive_noise_db",
        "adaptive_total_db",
        "adaptive_min_cluster_periods",
        "adaptive_distortion_db",
    }
    for f in FIELDS:
        p = declared[f.name]
        assert p.default == _parameter_form(f.default), f.name
        assert p.description == f.metadata["description"], f.name
        assert p.choices == f.metadata["choices"], f.name
        assert p.read_only, f.name
        if isinstance(p.default, list) and p.value_type is str and f.metadata["min"] is not None:
            continue  # degree sets as strings: their numbers are checked by the config
        assert (p.min, p.max) == (f.metadata["min"], f.metadata["max"]), f.name
    assert [p.name for p in config_parameters()] == NAMES


def test_node_defaults_give_the_default_config() -> None:
    from aero_identification.identifier_node import PARAMETERS

    values = default_parameters(PARAMETERS).as_dict()
    assert config_from_parameters(values) == IdentificationConfig()


@pytest.mark.ci_required  # CI runs a source checkout: a skip there fails
def test_identifier_yaml_holds_every_field_at_its_default() -> None:
    if not IDENTIFIER_YAML.is_file():
        pytest.skip("not a source checkout (aero_rig/config/identifier.yaml)")
    document = yaml.safe_load(IDENTIFIER_YAML.read_text())
    section = document["identifier"]["ros__parameters"]
    missing = [name for name in NAMES if name not in section]
    assert not missing, f"identifier.yaml lacks the declared fields {missing}"
    for f in FIELDS:
        assert section[f.name] == _parameter_form(f.default), (
            f"identifier.yaml: {f.name} = {section[f.name]!r}, the declared default "
            f"(aero_identification/hyperparameters.py) is {_parameter_form(f.default)!r}"
        )
    # ... and the file read as the node reads it gives the default config.
    from aero_identification.identifier_node import PARAMETERS

    values = resolve_parameters(PARAMETERS, "/identifier", [IDENTIFIER_YAML]).as_dict()
    assert config_from_parameters(values) == IdentificationConfig()


def test_parameters_convert_generically() -> None:
    values = {
        "nx": 2,
        "degrees": [2, 3],
        "scan_degrees": ["2", "3,4"],
        "scan_nx": [1],
        "scan_equations": ["state"],
        "output_dir": "/tmp/x",  # a node-only parameter: ignored
    }
    config = config_from_parameters(values)
    assert config.nx == 2 and config.degrees == (2, 3)
    assert config.scan_degrees == ((2,), (3, 4))
    assert config.scan_nx == (1,) and config.scan_equations == ("state",)
    assert config.max_iter == IdentificationConfig().max_iter


@pytest.mark.parametrize(
    ("values", "name"),
    [
        ({"nx": 13}, "nx"),
        ({"nx": -1}, "nx"),
        ({"nx": True}, "nx"),
        ({"nx": 1.0}, "nx"),
        ({"degrees": [1, 2]}, "degrees"),
        ({"degrees": []}, "degrees"),
        ({"degrees": "2,3"}, "degrees"),
        ({"structure": "half"}, "structure"),
        ({"scan_degrees": ["2,x"]}, "scan_degrees"),
        ({"scan_degrees": ["2,9"]}, "scan_degrees"),
        ({"scan_equations": ["output"]}, "scan_equations"),
        ({"clustering": "yes"}, "clustering"),
        ({"max_order": 0}, "max_order"),
    ],
)
def test_invalid_values_name_their_parameter(values: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=repr(name)):
        config_from_parameters(values)
    with pytest.raises(ParameterError, match=repr(name)):
        IdentificationConfig.from_dict(values)


def test_dict_round_trip_is_json() -> None:
    config = IdentificationConfig(nx=0, max_order=8, scan_degrees=((2,), (3, 5)), scan=False)
    d = config.to_dict()
    assert list(d) == NAMES
    assert d["scan_degrees"] == [[2], [3, 5]] and d["degrees"] == [2, 3, 4, 5]
    assert IdentificationConfig.from_dict(json.loads(json.dumps(d))) == config
    assert IdentificationConfig.from_dict({}) == IdentificationConfig()
    assert IdentificationConfig.from_dict({"max_iter": 7}).max_iter == 7
    with pytest.raises(ValueError, match=r"unknown identification parameter\(s\) 'nx_max'"):
        IdentificationConfig.from_dict({"nx_max": 3})


def test_config_is_hashable_and_immutable() -> None:
    config = IdentificationConfig.from_dict({"degrees": [2, 3]})
    assert config.degrees == (2, 3)
    assert hash(config) == hash(IdentificationConfig(degrees=(2, 3)))
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.nx = 2  # type: ignore[misc]


def _parser(only: list[str] | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="fit", exit_on_error=False)
    add_config_arguments(parser, only)
    return parser


def test_cli_flags_only_the_given_ones_override() -> None:
    args = _parser().parse_args([])
    assert config_from_args(args) == (IdentificationConfig(), {})
    args = _parser().parse_args(
        [
            "--nx",
            "0",
            "--degrees",
            "2",
            "3",
            "--structure",
            "statesonly",
            "--max-iter",
            "20",
            "--no-clustering",
            "--scan-degrees",
            "2",
            "2,3",
            "2,3,4,5",
            "--scan-equations",
            "state",
        ]
    )
    config, overrides = config_from_args(args)
    assert overrides == {
        "nx": 0,
        "degrees": [2, 3],
        "structure": "statesonly",
        "max_iter": 20,
        "clustering": False,
        "scan_degrees": [[2], [2, 3], [2, 3, 4, 5]],
        "scan_equations": ["state"],
    }
    assert config == IdentificationConfig.from_dict(overrides)
    base = IdentificationConfig(scan=False)
    config, overrides = config_from_args(_parser().parse_args(["--max-iter", "5"]), base)
    assert config == dataclasses.replace(base, max_iter=5) and overrides == {"max_iter": 5}
    config, _ = config_from_args(_parser().parse_args(["--clustering"]))
    assert config.clustering


def test_cli_help_is_the_declaration() -> None:
    text = _parser().format_help()
    for f in FIELDS:
        assert "--" + f.name.replace("_", "-") in text
    assert "--no-clustering" in text
    one = _parser(["max_iter"]).format_help()
    assert "Levenberg-Marquardt iterations per PNLSS fit (default 100)" in " ".join(one.split())
    assert "--nx" not in one
    with pytest.raises(ValueError, match="nxx"):
        _parser(["nxx"])


@pytest.mark.parametrize(
    "argv", [["--nx", "13"], ["--degrees", "1"], ["--structure", "x"], ["--scan-degrees", "2,x"]]
)
def test_cli_rejects_values_out_of_the_declared_range(argv: list[str]) -> None:
    with pytest.raises(argparse.ArgumentError, match=argv[0]):
        _parser().parse_args(argv)


def test_parse_degrees() -> None:
    assert parse_degrees("2, 3") == (2, 3)
    with pytest.raises(ValueError, match=">= 2"):
        parse_degrees("1")


def _loaded(module: str, heavy: tuple[str, ...]) -> subprocess.CompletedProcess[str]:
    """Import ``module`` in a fresh interpreter; exit 1 (printing them) if any of ``heavy``
    came with it."""
    code = (
        f"import sys, {module}\n"
        f"bad = sorted(m for m in sys.modules if m.split('.')[0] in {heavy!r})\n"
        "print(bad); sys.exit(1 if bad else 0)\n"
    )
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)


def test_config_module_stays_light() -> None:
    """The identifier node holds the config without loading the numerical stack."""
    result = _loaded(
        "aero_identification.hyperparameters", ("numpy", "scipy", "rclpy", "numba", "sklearn")
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_the_identifier_node_leaves_the_numerical_stack_to_its_worker() -> None:
    """The node (with the adaptive rules it imports) never loads scipy, scikit-learn or numba
    unless an adaptive run judges a period: the worker fits."""
    result = _loaded("aero_identification.identifier_node", ("scipy", "numba", "sklearn"))
    assert result.returncode == 0, result.stdout + result.stderr

"""Typed node parameters: declarations, ROS-style YAML files, command-line overrides.

A node declares its parameters (type from the default, range, description). Values come from
the defaults, then ROS 2 parameter files (``node_name: ros__parameters: {...}``, also ``/**``
and fully qualified ``/ns/node`` keys), then ``-p name:=value`` overrides, exactly as
``ros2 run pkg exe --ros-args --params-file f.yaml -p name:=value`` would apply them. Anything
invalid raises :class:`ParameterError` before the node creates a publisher.
"""

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml


class ParameterError(ValueError):
    """An invalid parameter value, unknown parameter or unreadable parameter file."""


_TYPE_NAMES = {bool: "bool", int: "int", float: "float", str: "string"}


@dataclass(frozen=True)
class Parameter:
    """A declared parameter. The type is the default's type (lists: their element type).

    ``min``/``max`` bound numbers (and every element of numeric lists); ``choices`` restricts
    strings. ``read_only`` parameters cannot change after start; a live one
    (``read_only=False``) can be set while the node runs (``ros2 param set``) and is
    read by the node at each use (``node.get_parameter(name).value``).
    """

    name: str
    default: Any
    description: str
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] | None = None
    element_type: type | None = None  # for list parameters whose default is empty
    read_only: bool = True

    @property
    def is_list(self) -> bool:
        return isinstance(self.default, list | tuple)

    @property
    def value_type(self) -> type:
        if self.is_list:
            if self.element_type is not None:
                return self.element_type
            if not self.default:
                raise ParameterError(
                    f"parameter {self.name!r}: empty list default needs element_type"
                )
            return type(self.default[0])
        return type(self.default)

    def describe_range(self) -> str:
        parts = [f"type {_TYPE_NAMES.get(self.value_type, self.value_type.__name__)}"]
        if self.is_list:
            parts[0] = f"type list of {_TYPE_NAMES.get(self.value_type, '?')}"
        if self.min is not None or self.max is not None:
            lo = "-inf" if self.min is None else f"{self.min:g}"
            hi = "inf" if self.max is None else f"{self.max:g}"
            parts.append(f"range [{lo}, {hi}]")
        if self.choices:
            parts.append(f"one of {list(self.choices)}")
        return ", ".join(parts)

    def validate(self, value: Any, source: str) -> Any:
        """Return ``value`` converted to this parameter's type or raise ParameterError."""
        if self.is_list:
            if not isinstance(value, list | tuple):
                raise self._error(value, source)
            return [self._validate_scalar(v, value, source) for v in value]
        return self._validate_scalar(value, value, source)

    def _validate_scalar(self, value: Any, whole: Any, source: str) -> Any:
        kind = self.value_type
        if kind is bool:
            if not isinstance(value, bool):
                raise self._error(whole, source)
        elif kind is int:
            if isinstance(value, bool) or not isinstance(value, int):
                raise self._error(whole, source)
        elif kind is float:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise self._error(whole, source)
            value = float(value)
        elif kind is str:
            if not isinstance(value, str):
                raise self._error(whole, source)
        if kind in (int, float):
            if math.isnan(value):  # NaN never passes a range check
                raise self._error(whole, source)
            if (self.min is not None and value < self.min) or (
                self.max is not None and value > self.max
            ):
                raise self._error(whole, source)
        if self.choices and value not in self.choices:
            raise self._error(whole, source)
        return value

    def _error(self, value: Any, source: str) -> ParameterError:
        return ParameterError(
            f"parameter {self.name!r} = {value!r} (from {source}) is invalid: "
            f"expected {self.describe_range()} — {self.description}"
        )


@dataclass
class ParameterSet:
    """Validated values by name, with where each came from."""

    declared: dict[str, Parameter]
    values: dict[str, Any] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)

    def __getitem__(self, name: str) -> Any:
        return self.values[name]

    def __contains__(self, name: str) -> bool:
        return name in self.values

    def as_dict(self) -> dict[str, Any]:
        return dict(self.values)


class _ParameterFileLoader(yaml.SafeLoader):
    """YAML as rcl reads parameter files: safe, plus ``!!python/tuple`` as a list. launch_ros
    writes the ``parameters=[{...}]`` of a launch file to a temporary file with ``yaml.dump``,
    after turning every list into a tuple; rclpy nodes read those, and so must the runtime's
    own reading of parameter files (resolve_parameters: the campaign's identifier
    configuration, the config-file tests)."""


_ParameterFileLoader.add_constructor(
    "tag:yaml.org,2002:python/tuple",
    lambda loader, node: list(loader.construct_sequence(node)),  # type: ignore[arg-type]
)
# rcl reads ``1e-6`` as a double (YAML 1.2's float); PyYAML's YAML 1.1 resolver wants a dot and
# would make it a string. After the int resolver, so that ``5`` stays an int.
_ParameterFileLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


def _parse_override(text: str) -> Any:
    """ROS 2 parses ``-p name:=value`` values as YAML scalars or flow sequences."""
    try:
        return yaml.load(text, Loader=_ParameterFileLoader)
    except yaml.YAMLError as exc:
        raise ParameterError(f"cannot parse parameter value {text!r}: {exc}") from exc


def _node_sections(document: Any, fq_name: str, path: Path) -> list[dict[str, Any]]:
    """The ``ros__parameters`` blocks of a parameter file that apply to ``fq_name``."""
    if document is None:
        return []
    if not isinstance(document, dict):
        raise ParameterError(f"{path}: a parameter file maps node names to 'ros__parameters'")
    node_name = fq_name.rsplit("/", 1)[-1]
    sections = []
    for key, block in document.items():
        key_str = str(key)
        if key_str not in ("/**", node_name, fq_name, fq_name.lstrip("/")):
            continue
        if not isinstance(block, dict) or "ros__parameters" not in block:
            raise ParameterError(
                f"{path}: section {key_str!r} has no 'ros__parameters' mapping "
                "(expected `node_name: {ros__parameters: {name: value}}`)"
            )
        params = block["ros__parameters"] or {}
        if not isinstance(params, dict):
            raise ParameterError(f"{path}: {key_str}.ros__parameters must be a mapping")
        sections.append(_flatten(params))
    return sections


def _file_sections(path: Path, fq_name: str) -> list[dict[str, Any]]:
    """The parameter file's sections that apply to ``fq_name``, each flattened."""
    try:
        document = yaml.load(path.read_text(), Loader=_ParameterFileLoader)
    except OSError as exc:
        raise ParameterError(f"cannot read parameter file {path}: {exc}") from exc
    except yaml.YAMLError as exc:
        raise ParameterError(f"parameter file {path} is not valid YAML: {exc}") from exc
    return _node_sections(document, fq_name, path)


def _flatten(params: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    # Nested mappings become dotted names, as in rclpy ("limits.max_deg").
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def resolve_parameters(
    declared: Iterable[Parameter],
    fq_node_name: str,
    param_files: Sequence[str | Path] = (),
    overrides: Sequence[tuple[str, str]] = (),
    *,
    as_ros_args: bool = False,
) -> ParameterSet:
    """Defaults, then files in order, then ``-p`` overrides; every value validated.

    ``as_ros_args``: the values as rcl hands them to the node (files and overrides merged, the
    later winning), each checked under the name the node gives its source (``--ros-args
    (NAME:=VALUE)``, node_parameters.declare_parameters), so that an error reads as the node's
    own line."""
    if as_ros_args:
        merged = resolve_parameters(declared, fq_node_name)  # only the declarations
        given: dict[str, Any] = {}
        for file in param_files:
            for section in _file_sections(Path(file), fq_node_name):
                given.update(section)
        given.update((name, _parse_override(text)) for name, text in overrides)
        for name, value in given.items():
            assign(merged, name, value, f"--ros-args ({name}:={value!r})")
            if name in merged.sources:
                merged.sources[name] = "--ros-args"
        return merged
    result = default_parameters(declared)
    for file in param_files:
        path = Path(file)
        for section in _file_sections(path, fq_node_name):
            for name, value in section.items():
                assign(result, name, value, f"{path}")
    for name, text in overrides:
        assign(result, name, _parse_override(text), f"-p {name}:={text}")
    return result


def default_parameters(declared: Iterable[Parameter]) -> ParameterSet:
    """Every declared parameter at its (validated) default."""
    result = ParameterSet(declared={p.name: p for p in declared})
    for p in result.declared.values():
        result.values[p.name] = p.validate(p.default, "default")
        result.sources[p.name] = "default"
    return result


# Accepted by every ROS 2 node (rclpy declares them itself); we keep stamps explicit.
ROS_NODE_PARAMETERS = ("use_sim_time", "start_type_description_service")


def assign(result: ParameterSet, name: str, value: Any, source: str) -> None:
    """Set one parameter from ``source``: an unknown name or invalid value raises
    ParameterError naming both (the one rule for files, ``-p`` and rcl's overrides)."""
    if name in ROS_NODE_PARAMETERS:
        return
    if name not in result.declared:
        known = ", ".join(sorted(result.declared)) or "none"
        raise ParameterError(
            f"unknown parameter {name!r} (from {source}); this node declares: {known}"
        )
    result.values[name] = result.declared[name].validate(value, source)
    result.sources[name] = source


def ros_descriptor(p: "Parameter") -> Any:
    """An rcl_interfaces ParameterDescriptor from a declaration (type, description, range);
    rcl_interfaces is imported only here (this module is light)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    descriptor = ParameterDescriptor(
        name=p.name,
        type=ros_parameter_type(p),
        description=p.description,
        additional_constraints=p.describe_range(),
        read_only=p.read_only,
    )
    if p.min is not None or p.max is not None:
        if p.value_type is float:
            lo = -float("inf") if p.min is None else float(p.min)
            hi = float("inf") if p.max is None else float(p.max)
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=lo, to_value=hi, step=0.0)
            ]
        elif p.value_type is int:
            lo_i = -(2**63) if p.min is None else int(p.min)
            hi_i = 2**63 - 1 if p.max is None else int(p.max)
            descriptor.integer_range = [IntegerRange(from_value=lo_i, to_value=hi_i, step=0)]
    return descriptor


def ros_parameter_type(p: "Parameter") -> int:
    """The rcl_interfaces ParameterType of a declaration."""
    from rcl_interfaces.msg import ParameterType

    scalar = {
        bool: ParameterType.PARAMETER_BOOL,
        int: ParameterType.PARAMETER_INTEGER,
        float: ParameterType.PARAMETER_DOUBLE,
        str: ParameterType.PARAMETER_STRING,
    }
    arrays = {
        bool: ParameterType.PARAMETER_BOOL_ARRAY,
        int: ParameterType.PARAMETER_INTEGER_ARRAY,
        float: ParameterType.PARAMETER_DOUBLE_ARRAY,
        str: ParameterType.PARAMETER_STRING_ARRAY,
    }
    return int((arrays if p.is_list else scalar)[p.value_type])

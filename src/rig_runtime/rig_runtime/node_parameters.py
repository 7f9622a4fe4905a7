"""A node's parameters as rclpy parameters: each declared once, with its descriptor, from the
module's declarations (params.py), the values rcl parsed (``--params-file``, ``-p``) checked by
the same rules first, and ``ros2 param set`` checked again."""

import array
import logging
from collections.abc import Mapping, Sequence
from typing import Any

from .params import (
    Parameter,
    ParameterError,
    ParameterSet,
    assign,
    default_parameters,
    ros_descriptor,
)

__all__ = ["declare_parameters"]


def declare_parameters(
    node: Any, declared: Sequence[Parameter], overrides: Mapping[str, Any]
) -> ParameterSet:
    """Declare every parameter on the rclpy ``node`` with its descriptor. ``overrides``: rcl's
    parsed values (rclpy keeps them in ``Node._parameter_overrides``, with no public getter),
    checked by :meth:`Parameter.validate` (types, ranges, choices, list elements) first, so a
    bad one stops the node before any of its own publishers exists (rclpy's
    /parameter_events and /rosout writers already do). Raises ParameterError."""
    from rclpy.exceptions import InvalidParameterValueException

    result = default_parameters(declared)
    for name, override in overrides.items():
        given = override.value
        if isinstance(given, array.array):  # rclpy's numeric arrays
            given = list(given)
        assign(result, name, given, f"--ros-args ({name}:={given!r})")
    for p in declared:
        if result.sources[p.name] != "default":
            result.sources[p.name] = "--ros-args"
        try:
            _declare_one(node, p, result.values[p.name])
        except InvalidParameterValueException as exc:
            raise ParameterError(f"parameter {p.name!r}: {exc}") from None
    node.add_on_set_parameters_callback(lambda params: _set_parameters(node, result, params))
    return result


def _declare_one(node: Any, p: Parameter, value: Any) -> None:
    from rclpy.parameter import Parameter as RclpyParameter

    descriptor = ros_descriptor(p)
    if not (p.is_list and not value):
        node.declare_parameter(
            p.name, list(value) if p.is_list else value, descriptor, ignore_override=True
        )
        return
    # An empty list does not say its element type: declare the type, then set [] (rclpy
    # refuses a set on a read-only parameter, so read-only is restored afterwards).
    kind = RclpyParameter.Type(descriptor.type)
    read_only, descriptor.read_only = descriptor.read_only, False
    node.declare_parameter(p.name, kind, descriptor, ignore_override=True)
    node.set_parameters([RclpyParameter(p.name, kind, [])])
    node.describe_parameter(p.name).read_only = read_only


def _set_parameters(node: Any, params: ParameterSet, parameters: list[Any]) -> Any:
    """``ros2 param set``: rclpy has already refused read-only parameters, wrong types and
    values outside the descriptor's range; choices and element ranges are checked here."""
    from rcl_interfaces.msg import SetParametersResult

    checked: list[tuple[str, Any]] = []
    for param in parameters:
        declared = params.declared.get(param.name)
        if declared is None:
            continue  # rclpy's own (use_sim_time)
        try:
            given = list(param.value) if isinstance(param.value, array.array) else param.value
            checked.append((param.name, declared.validate(given, "ros2 param set")))
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
    for name, value in checked:
        params.values[name] = value
        params.sources[name] = "ros2 param set"
        logger: logging.Logger | None = getattr(node, "logger", None)
        if logger is not None:
            logger.info("parameter %s set to %r", name, value)
    return SetParametersResult(successful=True)

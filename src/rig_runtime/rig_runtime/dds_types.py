"""Cyclone DDS IDL types generated from the rosbags Jazzy typestore.

ROS 2 (rmw_cyclonedds_cpp) names a message type ``pkg::msg::dds_::Type_``, makes every struct
``@final`` and writes XCDR1 little endian. The classes built here follow those conventions
field by field, so a ROS 2 peer matches our readers and writers by type name and agrees on
the bytes. No ``from __future__ import annotations`` here: cyclonedds resolves the
annotations of IdlStructs at runtime.
"""

import functools
from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.idl import types as idl
from cyclonedds.idl.annotations import final
from rosbags.typesys.store import Nodetype

from .messages import dds_type_name, normalize_type_name, typestore

_BASE_TYPES: dict[str, Any] = {
    "bool": bool,
    "byte": idl.byte,
    "char": idl.uint8,  # ROS 2 maps msg 'char' to IDL uint8
    "int8": idl.int8,
    "uint8": idl.uint8,
    "int16": idl.int16,
    "uint16": idl.uint16,
    "int32": idl.int32,
    "uint32": idl.uint32,
    "int64": idl.int64,
    "uint64": idl.uint64,
    "float32": idl.float32,
    "float64": idl.float64,
    "string": str,
}


# cyclonedds builds IDL types by subscripting plain classes (``__class_getitem__``), which mypy
# reads as a generic alias of a non-generic class: the subscriptions below carry an ignore.
def _idl_type(node: tuple[Any, Any]) -> Any:
    nodetype, rest = node
    if nodetype == Nodetype.BASE:
        base, bound = rest
        if base == "string" and bound:
            return idl.bounded_str[bound]  # type: ignore[misc]  # IDL type, see above
        return _BASE_TYPES[base]
    if nodetype == Nodetype.NAME:
        return idl_struct(rest)
    sub, length = rest
    if nodetype == Nodetype.ARRAY:
        return idl.array[_idl_type(sub), length]  # type: ignore[misc]  # IDL type, see above
    if length:
        return idl.sequence[_idl_type(sub), length]  # type: ignore[misc]  # IDL type, see above
    return idl.sequence[_idl_type(sub)]  # type: ignore[misc]  # IDL type, see above


@functools.cache
def idl_struct(type_name: str) -> type[IdlStruct]:
    """The ``@final`` IdlStruct class for a ROS message type, named as ROS 2 names it on DDS."""
    name = normalize_type_name(type_name)
    _, fielddefs = typestore().fielddefs[name]
    fields = {field_name: _idl_type(node) for field_name, node in fielddefs}
    class_name = name.split("/")[-1] + "_"
    cls = make_idl_struct(class_name, dds_type_name(name), fields)
    return final(cls)


def to_idl(msg: Any) -> IdlStruct:
    """Convert a typestore message to the matching IdlStruct instance (for wire-format checks)."""
    name = msg.__msgtype__
    _, fielddefs = typestore().fielddefs[name]
    values = {}
    for field_name, node in fielddefs:
        values[field_name] = _value_to_idl(node, getattr(msg, field_name))
    return idl_struct(name)(**values)


def _value_to_idl(node: tuple[Any, Any], value: Any) -> Any:
    nodetype, rest = node
    if nodetype == Nodetype.BASE:
        return value
    if nodetype == Nodetype.NAME:
        return to_idl(value)
    sub = rest[0]
    if sub[0] == Nodetype.BASE:
        return [v.item() if hasattr(v, "item") else v for v in value]
    return [_value_to_idl(sub, v) for v in value]

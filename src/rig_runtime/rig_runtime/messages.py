"""ROS 2 messages by type name, backed by the rosbags Jazzy typestore.

One typestore (``rosbags.typesys.get_typestore(Stores.ROS2_JAZZY)`` with the rig's own types
from aero_rig_interfaces' ``.msg`` files registered) is the single source of message
definitions for the nodes' serialized endpoints, the recorder and offline fits: messages are
the typestore's dataclasses (numpy arrays for primitive sequences, nested dataclasses for
headers), CDR bytes come from its ``serialize_cdr``.
"""

import dataclasses
import functools
import os
import struct
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Nodetype, Typestore

_NUMPY_DTYPES = {
    "bool": np.bool_,
    "byte": np.uint8,
    "char": np.uint8,
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}


class MessageTypeError(ValueError):
    """A message type name that the Jazzy typestore does not know."""


INTERFACES_PACKAGE = "aero_rig_interfaces"


def interface_msg_dir() -> Path:
    """The folder of aero_rig_interfaces' ``.msg`` files: the installed package's (an ament
    prefix's ``share/``, the venv's), else the source checkout's (offline tools without a
    build)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    candidates = [Path(p) / "share" / INTERFACES_PACKAGE / "msg" for p in (*prefixes, sys.prefix)]
    candidates.append(Path(__file__).resolve().parents[2] / INTERFACES_PACKAGE / "msg")
    for folder in candidates:
        if folder.is_dir() and any(folder.glob("*.msg")):
            return folder
    raise MessageTypeError(
        f"no {INTERFACES_PACKAGE} message definitions in {[str(c) for c in candidates]}"
    )


@functools.cache
def typestore() -> Typestore:
    """The process-wide ROS 2 Jazzy typestore (common_interfaces and friends) with the rig's
    own messages (aero_rig_interfaces) registered from their ``.msg`` files."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict[str, Any] = {}
    for path in sorted(interface_msg_dir().glob("*.msg")):
        name = f"{INTERFACES_PACKAGE}/msg/{path.stem}"
        types.update(get_types_from_msg(path.read_text(encoding="utf-8"), name))
    store.register(types)
    return store


@functools.lru_cache(maxsize=1024)  # called per message: keep it a dictionary lookup
def normalize_type_name(type_name: str) -> str:
    """``'sensor_msgs/JointState'`` or ``'sensor_msgs/msg/JointState'`` -> the latter."""
    parts = type_name.strip().strip("/").split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    name = "/".join(parts)
    if name not in typestore().fielddefs:
        raise MessageTypeError(
            f"unknown message type {type_name!r}: the runtime knows the ROS 2 Jazzy "
            "common_interfaces types (e.g. 'sensor_msgs/msg/JointState') and aero_rig_interfaces'"
        )
    return name


def _default_maker(node: tuple[Any, Any]) -> Callable[[], Any]:
    """A function that returns a fresh ROS default value of one field (built once per type)."""
    nodetype, rest = node
    if nodetype == Nodetype.BASE:
        base = rest[0]
        value: Any = "" if base == "string" else False if base == "bool" else 0
        if base.startswith("float"):
            value = 0.0
        return lambda: value  # immutable
    if nodetype == Nodetype.NAME:
        return _factory(rest)
    sub, length = rest
    if sub[0] == Nodetype.BASE and sub[1][0] in _NUMPY_DTYPES:
        count = length if nodetype == Nodetype.ARRAY else 0
        dtype = _NUMPY_DTYPES[sub[1][0]]
        return lambda: np.zeros(count, dtype=dtype)
    if nodetype == Nodetype.ARRAY:
        item = _default_maker(sub)
        return lambda: [item() for _ in range(length)]
    return list


@functools.cache
def _makers(name: str) -> tuple[Any, list[tuple[str, Any, Callable[[], Any]]]]:
    """``name``'s class and, per field, its type node and default maker: the type tree is
    walked once, since stream nodes build one message per sample."""
    _, fielddefs = typestore().fielddefs[name]
    makers = [(field_name, node, _default_maker(node)) for field_name, node in fielddefs]
    return typestore().types[name], makers


@functools.cache
def _factory(name: str) -> Callable[[], Any]:
    """``name``'s message with every field at its ROS default."""
    cls, makers = _makers(name)
    return lambda: cls(**{field_name: make() for field_name, _, make in makers})


def new_message(type_name: str, **fields: Any) -> Any:
    """A message of ``type_name`` with ROS defaults, fields overridden by keyword.

    Primitive sequences are numpy arrays (assign any array-like; it is converted to the field's
    dtype), nested messages are constructed with defaults (``msg.header.stamp.sec = 1``).
    """
    name = normalize_type_name(type_name)
    if not fields:
        return _factory(name)()
    cls, makers = _makers(name)
    values = {
        field_name: _coerce(node, fields.pop(field_name)) if field_name in fields else make()
        for field_name, node, make in makers
    }
    if fields:
        raise TypeError(
            f"{name} has no field(s) {sorted(fields)}; fields are {[f for f, _, _ in makers]}"
        )
    return cls(**values)


def _coerce(node: tuple[Any, Any], value: Any) -> Any:
    nodetype, rest = node
    if nodetype in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        sub = rest[0]
        if sub[0] == Nodetype.BASE and sub[1][0] in _NUMPY_DTYPES:
            return np.asarray(value, dtype=_NUMPY_DTYPES[sub[1][0]])
        return list(value)
    return value


Step = Callable[[Any], None]


def _nested_step(field_name: str, prepare: Step) -> Step:
    return lambda msg: prepare(getattr(msg, field_name))


def _array_step(field_name: str, dtype: np.dtype) -> Step:
    def step(msg: Any) -> None:
        value = getattr(msg, field_name)
        if not (isinstance(value, np.ndarray) and value.dtype == dtype):
            setattr(msg, field_name, np.ascontiguousarray(value, dtype=dtype))

    return step


def _items_step(field_name: str, prepare: Step) -> Step:
    def step(msg: Any) -> None:
        for item in getattr(msg, field_name):
            prepare(item)

    return step


@functools.cache
def _preparer(name: str) -> Step | None:
    """What :func:`_prepare` does to a ``name`` message, worked out once per type: None when no
    field of the type (or of its nested types) can need a conversion."""
    _, fielddefs = typestore().fielddefs[name]
    steps: list[Step] = []
    for field_name, (nodetype, rest) in fielddefs:
        if nodetype == Nodetype.NAME:
            nested = _preparer(rest)
            if nested is not None:
                steps.append(_nested_step(field_name, nested))
        elif nodetype in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            sub = rest[0]
            if sub[0] == Nodetype.BASE and sub[1][0] in _NUMPY_DTYPES:
                steps.append(_array_step(field_name, np.dtype(_NUMPY_DTYPES[sub[1][0]])))
            elif sub[0] == Nodetype.NAME:
                nested = _preparer(sub[1])
                if nested is not None:
                    steps.append(_items_step(field_name, nested))
    if not steps:
        return None

    def prepare(msg: Any) -> None:
        for step in steps:
            step(msg)

    return prepare


def _prepare(msg: Any) -> None:
    """Make user-assigned fields serialisable: lists/scalars in primitive sequences -> numpy."""
    prepare = _preparer(msg.__msgtype__)
    if prepare is not None:
        prepare(msg)


def serialize(msg: Any) -> bytes:
    """CDR (XCDR1, little endian, with the 4-byte encapsulation header) bytes of ``msg``."""
    _prepare(msg)
    return bytes(typestore().serialize_cdr(msg, msg.__msgtype__))


# Trailing bytes a CDR writer may leave after the last field: Fast DDS aligns an empty float64
# sequence at a message's end to 8 (a JointState with no efforts ends 4 bytes later than rosbags
# counts), where rosbags accepts at most 3 (XCDR1 end padding to 4).
MAX_TRAILING_PADDING = 7


def deserialize(data: bytes | memoryview, type_name: str) -> Any:
    """Inverse of :func:`serialize`; also reads the bytes of other CDR writers (rclpy's own
    messages, ``ros2 topic pub``), which may end in up to 7 padding bytes."""
    store = typestore()
    name = normalize_type_name(type_name)
    try:
        return store.deserialize_cdr(data, name)
    except SerdeError as exc:
        if "size mismatch" not in str(exc) or bytes(data[:2]) != b"\x00\x01":
            raise
    msgdef = store.get_msgdef(name)
    message, pos = msgdef.deserialize_cdr_le(data[4:], 0, msgdef.cls, store)
    if pos + 4 + MAX_TRAILING_PADDING < len(data):
        raise SerdeError(
            f"CDR message size mismatch for {name!r}: {len(data) - pos - 4} bytes left"
        )
    return message


def to_dict(msg: Any) -> Any:
    """A message as plain Python (dicts, lists, floats), e.g. for logging or JSON."""
    if dataclasses.is_dataclass(msg):
        return {f.name: to_dict(getattr(msg, f.name)) for f in dataclasses.fields(msg)}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, list):
        return [to_dict(v) for v in msg]
    return msg


def stamp_to_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def set_stamp(stamp: Any, t_ns: int) -> None:
    """Write integer nanoseconds into a ``builtin_interfaces/Time`` in place."""
    stamp.sec, stamp.nanosec = divmod(int(t_ns), 1_000_000_000)


@functools.cache
def starts_with_header(type_name: str) -> bool:
    """Whether a message type's first field is a std_msgs/Header (its CDR begins with the
    stamp: :func:`cdr_stamp_ns`)."""
    fields = typestore().fielddefs[normalize_type_name(type_name)][1]
    return bool(fields) and fields[0][1] == (Nodetype.NAME, "std_msgs/msg/Header")


def cdr_stamp_ns(cdr: bytes | memoryview) -> int:
    """The header stamp [ns] of a serialized stamped message, without deserializing it: after
    the 4-byte encapsulation header (its second byte 1: little-endian) a std_msgs/Header begins
    with its stamp, int32 sec and uint32 nanosec (OMG DDS-XTypes 1.3, §7.4.3 CDR)."""
    order = "<" if cdr[1] & 1 else ">"
    sec, nanosec = struct.unpack_from(order + "iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec

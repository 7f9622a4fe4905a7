"""ROS 2 messages by type name, backed by the rosbags Jazzy typestore.

One typestore (``rosbags.typesys.get_typestore(Stores.ROS2_JAZZY)``) is the single source of
message definitions for the Cyclone DDS backend, the recorder and offline fits: messages are the
typestore's dataclasses (numpy arrays for primitive sequences, nested dataclasses for headers),
CDR bytes come from its ``serialize_cdr`` and type hashes from its ``hash_rihs01``.
"""

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import numpy as np
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


# rmw_dds_common's graph messages, Jazzy layout (16-byte GIDs; 24 before Iron): what the Cyclone
# DDS backend publishes on ``ros_discovery_info`` so that ROS 2 tools see its nodes
# (docs/design.md §3.1). The .msg text of ros2/rmw_dds_common (jazzy). rosbags' Jazzy store
# ships the same definitions; they are registered only into a store that lacks them.
RMW_DDS_COMMON_MSGS = {
    "rmw_dds_common/msg/Gid": "char[16] data\n",
    "rmw_dds_common/msg/NodeEntitiesInfo": (
        "string<=256 node_namespace\n"
        "string<=256 node_name\n"
        "Gid[] reader_gid_seq\n"
        "Gid[] writer_gid_seq\n"
    ),
    "rmw_dds_common/msg/ParticipantEntitiesInfo": (
        "Gid gid\nNodeEntitiesInfo[] node_entities_info_seq\n"
    ),
}


def register_missing(store: Typestore, definitions: dict[str, str]) -> None:
    """Register ``{type name: .msg text}`` into ``store``, skipping types it already has."""
    types: dict[str, Any] = {}
    for name, text in definitions.items():
        if name not in store.fielddefs:
            types.update(get_types_from_msg(text, name))
    if types:
        store.register(types)


@functools.cache
def typestore() -> Typestore:
    """The process-wide ROS 2 Jazzy typestore (common_interfaces and friends, rmw_dds_common)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    register_missing(store, RMW_DDS_COMMON_MSGS)
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
            "common_interfaces types (e.g. 'sensor_msgs/msg/JointState')"
        )
    return name


def dds_type_name(type_name: str) -> str:
    """DDS type name ROS 2 uses on the wire: ``sensor_msgs::msg::dds_::JointState_``."""
    pkg, kind, name = normalize_type_name(type_name).split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


@functools.cache
def type_hash(type_name: str) -> str:
    """RIHS01 type hash of a message type (REP 2011), as ROS 2 Jazzy advertises it."""
    return typestore().hash_rihs01(normalize_type_name(type_name))


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


def deserialize(data: bytes | memoryview, type_name: str) -> Any:
    """Inverse of :func:`serialize`."""
    return typestore().deserialize_cdr(data, normalize_type_name(type_name))


def message_type_name(msg: Any) -> str:
    """The ROS type name of a message object (``'sensor_msgs/msg/JointState'``)."""
    return str(msg.__msgtype__)


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

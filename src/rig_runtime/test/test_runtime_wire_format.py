"""The runtime's CDR bytes equal rosbags' serialize_cdr and are what rclpy's own message classes
read and write (the serialized publish path, node.py)."""

import numpy as np
import pytest

from rig_runtime.messages import deserialize, new_message, serialize, typestore


def _messages() -> list:
    js = new_message("sensor_msgs/msg/JointState", name=["pitch"], position=[0.1], velocity=[-2.5])
    js.header.stamp.sec, js.header.stamp.nanosec = 17, 5_000_000
    js.header.frame_id = "wing"
    fields = [
        new_message("sensor_msgs/msg/PointField", name=n, offset=4 * i, datatype=7, count=1)
        for i, n in enumerate("xyzp")
    ]
    cloud = new_message(
        "sensor_msgs/msg/PointCloud2",
        height=1,
        width=49,
        fields=fields,
        point_step=16,
        row_step=16 * 49,
        data=np.random.default_rng(0).integers(0, 255, 49 * 16),
        is_dense=True,
    )
    vec = new_message("geometry_msgs/msg/Vector3Stamped")
    vec.vector.x, vec.vector.y, vec.vector.z = 1.25, 0.02, -0.1
    text = new_message("std_msgs/msg/String", data='{"plan": "ünïcode"}')
    status = new_message(
        "diagnostic_msgs/msg/DiagnosticStatus",
        level=1,
        name="actuator",
        message="clamped",
        values=[new_message("diagnostic_msgs/msg/KeyValue", key="count", value="3")],
    )
    diag = new_message("diagnostic_msgs/msg/DiagnosticArray", status=[status, status])
    return [js, cloud, vec, text, diag]


def _same(a: object, b: object) -> bool:
    """Field-by-field equality of two runtime messages (numpy sequences compared by value)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(
            _same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__
        )
    return a == b


@pytest.mark.parametrize("msg", _messages(), ids=lambda m: m.__msgtype__)
def test_runtime_bytes_equal_rosbags_and_rclpy(msg) -> None:
    from rclpy.serialization import deserialize_message, serialize_message

    from rig_runtime.node import message_class

    ours = serialize(msg)
    reference = bytes(typestore().serialize_cdr(msg, msg.__msgtype__))
    assert ours == reference
    assert ours[:4] == b"\x00\x01\x00\x00"  # CDR_LE encapsulation
    # rclpy's generated class reads these bytes, and its own bytes read back as the same
    # message: what a subscriber of rclpy messages gets from our serialized publish, and the
    # other way round (alignment padding may differ: CDR leaves it unspecified).
    native = deserialize_message(ours, message_class(msg.__msgtype__))
    assert _same(deserialize(serialize_message(native), msg.__msgtype__), msg)
    back = deserialize(ours, msg.__msgtype__)
    assert serialize(back) == ours


def test_new_message_defaults_and_errors() -> None:
    js = new_message("sensor_msgs/msg/JointState")
    assert js.position.dtype == np.float64 and js.position.size == 0
    assert js.header.stamp.sec == 0
    with pytest.raises(ValueError, match="unknown message type"):
        new_message("sensor_msgs/msg/NoSuchType")
    with pytest.raises(TypeError, match="no field"):
        new_message("std_msgs/msg/String", text="x")


def test_messages_from_the_cached_factory_share_no_mutable_state() -> None:
    # The factory is built once per type: each message must still get its own nested
    # messages, arrays and lists, or a stream node would overwrite the one it just published.
    a = new_message("sensor_msgs/msg/JointState")
    b = new_message("sensor_msgs/msg/JointState")
    assert a.header is not b.header and a.header.stamp is not b.header.stamp
    assert a.position is not b.position and a.name is not b.name
    a.header.stamp.sec = 5
    a.name.append("pitch")
    assert b.header.stamp.sec == 0 and b.name == []
    imu = new_message("sensor_msgs/msg/Imu")  # fixed-size float64[9] arrays
    assert imu.orientation_covariance.shape == (9,)
    assert (
        imu.orientation_covariance is not new_message("sensor_msgs/msg/Imu").orientation_covariance
    )


def test_lists_assigned_anywhere_in_a_message_are_serialised_as_its_arrays() -> None:
    # Serialisation's preparation is worked out once per type, nested types included.
    array = new_message("diagnostic_msgs/msg/DiagnosticArray")
    array.status = [new_message("diagnostic_msgs/msg/DiagnosticStatus", name="a")]
    js = new_message("sensor_msgs/msg/JointState")
    js.position = [0.5, 1.5]  # a list, not an array
    js.effort = (2.0,)
    back = deserialize(serialize(js), "sensor_msgs/msg/JointState")
    np.testing.assert_array_equal(back.position, [0.5, 1.5])
    np.testing.assert_array_equal(back.effort, [2.0])
    assert (
        deserialize(serialize(array), "diagnostic_msgs/msg/DiagnosticArray").status[0].name == "a"
    )
    cloud = new_message("sensor_msgs/msg/PointCloud2")
    cloud.fields = [new_message("sensor_msgs/msg/PointField", name="x", datatype=7, count=1)]
    cloud.data = [1, 2, 3]
    assert deserialize(serialize(cloud), "sensor_msgs/msg/PointCloud2").data.tolist() == [1, 2, 3]

"""CDR bytes on the DDS backend equal rosbags' serialize_cdr; names follow ROS 2 conventions."""

import numpy as np
import pytest

from rig_runtime.dds_types import idl_struct, to_idl
from rig_runtime.interface import PITCH_COMMAND
from rig_runtime.messages import (
    dds_type_name,
    deserialize,
    new_message,
    serialize,
    type_hash,
    typestore,
)
from rig_runtime.names import resolve_name


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


@pytest.mark.parametrize("msg", _messages(), ids=lambda m: m.__msgtype__)
def test_backend_bytes_equal_rosbags_and_generated_idl(msg) -> None:
    ours = serialize(msg)
    reference = bytes(typestore().serialize_cdr(msg, msg.__msgtype__))
    assert ours == reference
    # The generated @final IdlStruct, serialised by cyclonedds itself as XCDR1, gives the
    # same bytes: the DDS types we register are the wire types ROS 2 uses.
    assert to_idl(msg).serialize(use_version_2=False) == reference
    assert ours[:4] == b"\x00\x01\x00\x00"  # CDR_LE encapsulation
    back = deserialize(ours, msg.__msgtype__)
    assert serialize(back) == ours


def test_dds_names_follow_ros2_conventions() -> None:
    assert dds_type_name("sensor_msgs/msg/JointState") == "sensor_msgs::msg::dds_::JointState_"
    assert dds_type_name("std_msgs/String") == "std_msgs::msg::dds_::String_"
    cls = idl_struct("geometry_msgs/msg/Vector3Stamped")
    assert cls.__idl_typename__ == "geometry_msgs::msg::dds_::Vector3Stamped_"
    assert cls.__idl_annotations__["extensibility"] == "final"
    assert type_hash("std_msgs/msg/String").startswith("RIHS01_")
    assert resolve_name("pitch/command", "/rig", "gen", {}) == "/rig/pitch/command"
    assert resolve_name(PITCH_COMMAND.name, "/rig", "gen", {}) == PITCH_COMMAND.name
    assert resolve_name("~/status", "/", "gen", {}) == "/gen/status"
    assert resolve_name("/a", "/", "n", {"/a": "/b"}) == "/b"


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

"""The DDS backend tells ROS 2 tools which nodes it runs (``ros_discovery_info``).

ROS 2's rmw layer (rmw_dds_common's graph cache) learns nodes only from
``rmw_dds_common/msg/ParticipantEntitiesInfo`` samples on the DDS topic ``ros_discovery_info``:
without them ``ros2 node list`` is empty. Here an independent reader - IDL types written by hand
below, not the project's generated ones, with rmw_cyclonedds' reader QoS - checks what the
backend publishes, and the bytes are checked against rosbags' serializer.

No ``from __future__ import annotations``: cyclonedds reads the IdlStruct annotations at run
time.
"""

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cyclonedds._clayer import ddspy_take
from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import InstanceState, SampleState, ViewState
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from cyclonedds.idl.annotations import final
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.typesys import Stores, get_typestore

from rig_runtime import Node
from rig_runtime.dds_backend import cyclone_config
from rig_runtime.graph import load_graph, package_share
from rig_runtime.interface import EXPERIMENT_ANOMALY, GRAPH_READY, PITCH_COMMAND
from rig_runtime.launcher import Launcher
from rig_runtime.messages import RMW_DDS_COMMON_MSGS, register_missing, typestore
from rig_runtime.testing import Processes, graph_env, join_graph, wait_for

# -- the three types, by hand, as rmw_dds_common (Jazzy) defines them ------------------------------


@final
@dataclass
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: t.array[t.uint8, 16]  # type: ignore[type-arg, valid-type]


@final
@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: t.bounded_str[256]  # type: ignore[type-arg, valid-type]
    node_name: t.bounded_str[256]  # type: ignore[type-arg, valid-type]
    reader_gid_seq: t.sequence[Gid]  # type: ignore[type-arg]
    writer_gid_seq: t.sequence[Gid]  # type: ignore[type-arg]


@final
@dataclass
class ParticipantEntitiesInfo(
    IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
):
    gid: Gid
    node_entities_info_seq: t.sequence[NodeEntitiesInfo]  # type: ignore[type-arg]


# rmw_cyclonedds' reader of ros_discovery_info: reliable, transient local, keep all (its writer
# keeps last 1; the topic has no key, so a keep-last-1 reader would let one participant's sample
# replace another's).
READER_QOS = Qos(
    Policy.Reliability.Reliable(max_blocking_time=0),
    Policy.Durability.TransientLocal,
    Policy.History.KeepAll,
    Policy.DataRepresentation(use_cdrv0_representation=True),
)
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any
PAE = "rmw_dds_common/msg/ParticipantEntitiesInfo"


def _delete(entity: Any) -> None:
    """Delete a cyclonedds entity now (cyclonedds keeps entities alive in a class table)."""
    table = type(entity)._entities
    if entity._ref in table:
        del table[entity._ref]
        entity._delete(entity._ref)


class DiscoveryWatcher:
    """A participant of its own that reads ros_discovery_info and the DDS endpoint discovery."""

    def __init__(self, domain_id: int, create_domain: bool) -> None:
        config = cyclone_config()
        self.domain = Domain(domain_id, config) if create_domain and config else None
        self.dp = DomainParticipant(domain_id)
        topic = Topic(self.dp, "ros_discovery_info", ParticipantEntitiesInfo)
        self.reader = DataReader(self.dp, topic, READER_QOS)
        self.publications = BuiltinDataReader(self.dp, BuiltinTopicDcpsPublication)
        self.subscriptions = BuiltinDataReader(self.dp, BuiltinTopicDcpsSubscription)
        self.latest: dict[bytes, Any] = {}  # ParticipantEntitiesInfo by participant GID
        self.raw: list[bytes] = []
        self.endpoints: dict[bytes, tuple[bytes, str]] = {}  # GID -> (participant GID, topic)

    def poll(self) -> None:
        batch = ddspy_take(self.reader._ref, _ANY, 64)
        assert not isinstance(batch, int), batch
        for data, info in batch:
            if info.valid_data:
                self.raw.append(bytes(data))
                sample: Any = ParticipantEntitiesInfo.deserialize(bytes(data))
                self.latest[bytes(sample.gid.data)] = sample
        for builtin in (self.publications, self.subscriptions):
            for ep in builtin.take(N=256):
                if getattr(ep, "topic_name", None):
                    self.endpoints[ep.key.bytes] = (ep.participant_key.bytes, ep.topic_name)

    def nodes(self) -> dict[str, tuple[bytes, Any]]:
        """Every node now announced: fully qualified name -> (participant GID, entry)."""
        found = {}
        for gid, sample in self.latest.items():
            for node in sample.node_entities_info_seq:
                prefix = "" if node.node_namespace == "/" else node.node_namespace
                found[f"{prefix}/{node.node_name}"] = (gid, node)
        return found

    def topics(self, participant: bytes, gids: Any) -> list[str] | None:
        """The DDS topics of these endpoint GIDs, each checked to belong to ``participant``
        (None while an endpoint is not discovered yet)."""
        names = []
        for gid in gids:
            entry = self.endpoints.get(bytes(gid.data))
            if entry is None or entry[0] != participant:
                return None
            names.append(entry[1])
        return sorted(names)

    def close(self) -> None:
        _delete(self.dp)
        if self.domain is not None:
            _delete(self.domain)


@pytest.fixture
def dds_graph(monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, str]]:
    env = graph_env(RIG_RUNTIME_BACKEND="dds")  # what the DDS backend announces
    join_graph(env, monkeypatch.setenv)
    yield env


def _wait(watcher: DiscoveryWatcher, predicate: Any, timeout_s: float) -> bool:
    def check() -> bool:
        watcher.poll()
        return bool(predicate())

    return wait_for(check, timeout_s)


INTERNAL_WRITERS = ["rt" + EXPERIMENT_ANOMALY.name, "rt" + GRAPH_READY.name]


def test_rmw_dds_common_definitions_equal_jazzy_store() -> None:
    """The .msg texts registered when a store lacks them are the Jazzy store's definitions."""
    empty = get_typestore(Stores.EMPTY)
    register_missing(empty, RMW_DDS_COMMON_MSGS)
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    for name in RMW_DDS_COMMON_MSGS:
        assert empty.fielddefs[name] == jazzy.fielddefs[name] == typestore().fielddefs[name]
        assert empty.hash_rihs01(name) == jazzy.hash_rihs01(name)
    data_field = jazzy.fielddefs["rmw_dds_common/msg/Gid"][1][0]
    assert data_field[1][1][1] == 16  # Jazzy GIDs are 16 bytes (24 up to Humble)


def test_bytes_equal_rosbags_and_node_leaves_at_close(dds_graph: dict[str, str]) -> None:
    """In one process: the sample the backend writes is, byte for byte, rosbags' CDR of the
    message built here from the entities' GUIDs; closing the node publishes it gone."""
    node = Node("probe", namespace="/wire", backend="dds")
    watcher: DiscoveryWatcher | None = None
    try:
        pub_a = node.create_publisher("std_msgs/msg/String", "/probe/a", "latched")
        pub_b = node.create_publisher("sensor_msgs/msg/JointState", "/probe/b", "sensor")
        sub = node.create_subscription("std_msgs/msg/String", "/probe/c", lambda m: None)
        watcher = DiscoveryWatcher(int(dds_graph["ROS_DOMAIN_ID"]), create_domain=False)
        participant_gid = node._backend.participant.guid.bytes  # type: ignore[attr-defined]

        store = typestore()
        gid_cls = store.types["rmw_dds_common/msg/Gid"]
        node_cls = store.types["rmw_dds_common/msg/NodeEntitiesInfo"]
        pae_cls = store.types[PAE]

        def gid(raw: bytes) -> Any:
            return gid_cls(data=np.frombuffer(raw, dtype=np.uint8).copy())

        expected: Any = pae_cls(
            gid=gid(participant_gid),
            node_entities_info_seq=[
                node_cls(
                    node_namespace="/wire",
                    node_name="probe",
                    reader_gid_seq=[gid(sub.reader.guid.bytes)],  # type: ignore[attr-defined]
                    writer_gid_seq=[
                        gid(p.writer.guid.bytes)  # type: ignore[attr-defined]
                        for p in (pub_a, pub_b)
                    ],
                )
            ],
        )
        reference = bytes(store.serialize_cdr(expected, PAE))
        assert _wait(watcher, lambda: reference in watcher.raw, 10), watcher.raw
        assert reference[:4] == b"\x00\x01\x00\x00"  # XCDR1 little endian, as rmw_cyclonedds
        sample = watcher.latest[participant_gid]
        assert [n.node_name for n in sample.node_entities_info_seq] == ["probe"]
        # The GIDs are the DDS GUIDs: participant prefix (12 bytes) + entity id.
        for g in sample.node_entities_info_seq[0].writer_gid_seq:
            assert bytes(g.data)[:12] == participant_gid[:12]

        node.close()
        gone = bytes(store.serialize_cdr(pae_cls(gid=expected.gid, node_entities_info_seq=[]), PAE))
        assert _wait(watcher, lambda: watcher.raw and watcher.raw[-1] == gone, 10), watcher.raw
    finally:
        node.close()
        if watcher is not None:
            watcher.close()


@pytest.mark.slow  # node processes talking DDS: `make test-fast` skips them
def test_independent_reader_sees_each_node_of_a_graph(tmp_path: Path) -> None:
    """Three node processes (one namespaced): each announces its node with the GIDs of exactly
    its readers and writers, the project's own /graph/ready and /experiment/anomaly included."""
    env = graph_env(RIG_RUNTIME_BACKEND="dds")  # what the DDS backend announces
    watcher = DiscoveryWatcher(int(env["ROS_DOMAIN_ID"]), create_domain=True)
    try:
        with Processes(env, log_dir=tmp_path) as procs:
            talker = ["count:=1000000", "rate_hz:=5.0", "wait_for_subscribers:=0"]
            procs.start_entry(
                "rig_runtime", "talker", "--ros-args", *_params(talker), name="talker"
            )
            procs.start_entry("rig_runtime", "listener", "--ros-args", name="listener")
            procs.start_entry(
                "rig_runtime",
                "listener",
                "--ros-args",
                "-r",
                "__node:=listener_b",
                "-r",
                "__ns:=/rig",
                name="listener_b",
            )
            expected = {
                "/talker": ([], sorted(["rt/chatter", *INTERNAL_WRITERS])),
                "/listener": (["rt/chatter"], sorted(INTERNAL_WRITERS)),
                "/rig/listener_b": (["rt/chatter"], sorted(INTERNAL_WRITERS)),
            }

            def seen() -> dict[str, tuple[list[str] | None, list[str] | None]]:
                return {
                    name: (
                        watcher.topics(gid, info.reader_gid_seq),
                        watcher.topics(gid, info.writer_gid_seq),
                    )
                    for name, (gid, info) in watcher.nodes().items()
                }

            ok = _wait(watcher, lambda: seen() == expected, 30)
            logs = {name: procs.log(name)[-1000:] for name in ("talker", "listener")}
            assert ok, (seen(), logs)
            # One participant per process, each announcing its own node.
            participants = {gid for gid, _ in watcher.nodes().values()}
            assert len(participants) == 3
            for gid, info in watcher.nodes().values():
                assert len(watcher.latest[gid].node_entities_info_seq) == 1
                assert (
                    len(info.reader_gid_seq) + len(info.writer_gid_seq)
                    == len([p for p, _ in watcher.endpoints.values() if p == gid]) - 1
                )  # every endpoint of the participant but its ros_discovery_info writer
    finally:
        watcher.close()


@pytest.mark.slow  # the simulated campaign's six node processes
def test_sim_graph_nodes_are_announced(tmp_path: Path) -> None:
    """The graph of `aero-rig run sim`, as rig-launch starts it: every node is announced,
    /pitch/command with the generator writing and the simulated actuator reading, which is
    what `ros2 node list` and `ros2 topic info -v /pitch/command` show on a ROS 2 machine."""
    pytest.importorskip("aero_rig")
    graph = load_graph(package_share("aero_rig") / "config" / "sim.yaml")
    env = graph_env(RIG_RUNTIME_BACKEND="dds")  # what the DDS backend announces
    overrides: dict[str, dict[str, Any]] = {
        "generator": {"plan": "short", "start_timeout_s": 120.0},
        "identifier": {"output_dir": str(tmp_path / "run")},
        "recorder": {"output": str(tmp_path / "run" / "bag")},
    }
    watcher = DiscoveryWatcher(int(env["ROS_DOMAIN_ID"]), create_domain=True)
    launcher = Launcher(graph, env=env, overrides=overrides, log_dir=tmp_path / "logs")
    command = "rt" + PITCH_COMMAND.name
    try:
        launcher.start()

        def announced() -> bool:
            nodes = watcher.nodes()
            if set(nodes) != {f"/{n.name}" for n in graph.nodes}:
                return False
            for gid, info in nodes.values():
                readers = watcher.topics(gid, info.reader_gid_seq)
                writers = watcher.topics(gid, info.writer_gid_seq)
                if readers is None or writers is None or "rt" + GRAPH_READY.name not in writers:
                    return False
            return True

        ok = _wait(watcher, announced, 90)
        assert ok, (sorted(watcher.nodes()), launcher.poll(), launcher.running())
        nodes = watcher.nodes()
        gen_gid, gen = nodes["/generator"]
        act_gid, act = nodes["/sim_actuator"]
        assert command in (watcher.topics(gen_gid, gen.writer_gid_seq) or [])
        assert command in (watcher.topics(act_gid, act.reader_gid_seq) or [])
        assert len({gid for gid, _ in nodes.values()}) == len(graph.nodes)
    finally:
        launcher.stop()
        watcher.close()


def _params(values: list[str]) -> list[str]:
    args: list[str] = []
    for value in values:
        args += ["-p", value]
    return args

"""Cyclone DDS backend: ROS 2 wire conventions without ROS (docs/design.md §3).

- Topics are ``rt/<fully qualified name>``; types ``pkg::msg::dds_::Type_``, ``@final``,
  generated from the rosbags Jazzy typestore (dds_types.py).
- Samples are written as XCDR1 little-endian bytes from rosbags' ``serialize_cdr`` (the same
  bytes the generated IdlStruct produces; tests check both) and read back with
  ``deserialize_cdr``, so messages are the typestore's dataclasses with numpy sequences.
- Every reader and writer carries ``typehash=RIHS01_<hex>;`` in USER_DATA, as rmw_cyclonedds
  does in Jazzy.
- The process's nodes and the GIDs of their readers and writers are published on
  ``ros_discovery_info`` (``rmw_dds_common/msg/ParticipantEntitiesInfo``), as rmw_cyclonedds
  does, so ``ros2 node list`` on a ROS 2 machine sees them; the participant carries
  ``enclave=/;`` in USER_DATA like an rmw participant.
- Domain from ``ROS_DOMAIN_ID``; network from ``ROS_AUTOMATIC_DISCOVERY_RANGE`` and
  ``ROS_STATIC_PEERS`` as rmw_cyclonedds maps them (cyclone_config; ros_environment.py);
  ``CYCLONEDDS_URI`` (if set) wins. ``RIG_DDS_MAX_PARTICIPANTS`` (default 32) bounds the
  unicast participant indices on LOCALHOST, i.e. how many processes one domain holds.
"""

import ctypes
import ctypes as ct
import logging
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import (
    DDSException,
    GuardCondition,
    InstanceState,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.internal import DDS, dds_c_t
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from .barrier import Endpoint
from .dds_types import idl_struct
from .messages import deserialize, new_message, normalize_type_name, serialize, type_hash
from .qos import PROFILES, QosProfile
from .ros_environment import discovery_range, domain_id, static_peers

# How long a reliable keep-all writer may block while a reader does not acknowledge (a paused
# or starved process). Longer than Cyclone's participant lease (10 s): a reader that is gone
# for good is unmatched by then and the writer goes on; one that is only paused catches up.
WRITE_BLOCKING_S = 60
_REDELIVERY_WINDOW = 4096  # samples per writer remembered to recognise a redelivery
_log = logging.getLogger("rig.dds")
_ANY_STATE = SampleState.Any | ViewState.Any | InstanceState.Any
_TAKE_BATCH = 256

# Write batching (Cyclone's per-domain ``whc_batch``): a write queues its RTPS submessage in the
# writer's packet instead of sending a UDP datagram per sample; the executor flushes every
# writer that wrote at the end of each turn (DdsBackend.spin_once), so a burst of samples
# handled in one turn leaves as a few full datagrams, and a lone sample leaves at once.
_dds_write_set_batch = DDS._dll_handle.dds_write_set_batch
_dds_write_set_batch.argtypes = [ctypes.c_bool]
_dds_write_set_batch.restype = None
_dds_write_flush = DDS._dll_handle.dds_write_flush
_dds_write_flush.argtypes = [ctypes.c_int32]
_dds_write_flush.restype = ctypes.c_int32


def cyclone_config() -> str | None:
    """The Cyclone DDS XML configuration this process uses, from the ROS 2 discovery
    variables as rmw_cyclonedds_cpp (Jazzy) maps them (None: Cyclone's own default or
    ``CYCLONEDDS_URI`` applies).

    - LOCALHOST: the loopback interface only, no multicast, unicast discovery of the
      participant indices on 127.0.0.1;
    - SUBNET: Cyclone's default interface with multicast discovery;
    - OFF: loopback, no multicast and no peers: no other process is discovered;
    - SYSTEM_DEFAULT: Cyclone's own configuration untouched.
    ``ROS_STATIC_PEERS`` are added as peers (except with OFF).
    """
    if os.environ.get("CYCLONEDDS_URI"):
        return None
    scope = discovery_range()
    peers = static_peers()
    if scope == "SYSTEM_DEFAULT" or (scope == "SUBNET" and not peers):
        return None
    max_index = int(os.environ.get("RIG_DDS_MAX_PARTICIPANTS", "32"))
    general = ""
    discovery = ""
    if scope in ("LOCALHOST", "OFF"):
        general = (
            '<General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
            "<AllowMulticast>false</AllowMulticast></General>"
        )
    if scope == "LOCALHOST":
        peers = ["127.0.0.1", *peers]
    if scope == "OFF":
        peers = []
    if scope in ("LOCALHOST", "OFF"):
        discovery += (
            "<ParticipantIndex>auto</ParticipantIndex>"
            f"<MaxAutoParticipantIndex>{max_index}</MaxAutoParticipantIndex>"
        )
    if peers:
        discovery += "<Peers>" + "".join(f'<Peer address="{p}"/>' for p in peers) + "</Peers>"
    return (
        '<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any">'
        f"{general}<Discovery>{discovery}</Discovery>"
        '<Internal><SocketReceiveBufferSize min="4MB"/><Watermarks><WhcHigh>4MB</WhcHigh>'
        "<WhcHighInit>4MB</WhcHighInit><WhcAdaptive>false</WhcAdaptive></Watermarks></Internal>"
        "<Tracing><Verbosity>severe</Verbosity><OutputFile>stderr</OutputFile></Tracing>"
        "</Domain></CycloneDDS>"
    )


def dds_qos(profile: QosProfile, type_name: str | None = None, writer: bool = False) -> Qos:
    policies: list[Any] = [
        Policy.Reliability.Reliable(max_blocking_time=duration(seconds=WRITE_BLOCKING_S))
        if profile.reliability == "reliable"
        else Policy.Reliability.BestEffort,
        Policy.Durability.TransientLocal
        if profile.durability == "transient_local"
        else Policy.Durability.Volatile,
        Policy.History.KeepAll if profile.keep_all else Policy.History.KeepLast(profile.depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if profile.keep_all and writer:
        # Keep-all writers hold at most this many unacknowledged samples, then block (up to
        # max_blocking_time): back-pressure instead of loss. Readers stay unlimited: a full
        # keep-all reader cache makes Cyclone reject samples and the reliable protocol can stall
        # until the writer times out. In simulation the generator's credit bounds what is in
        # flight; on the rig consumers keep up with real time.
        policies.append(Policy.ResourceLimits(max_samples=4096))
    if type_name is not None:
        policies.append(Policy.Userdata(data=f"typehash={type_hash(type_name)};".encode()))
    return Qos(*policies)


def profile_from_dds_qos(qos: Qos) -> QosProfile:
    """Best-effort reconstruction of an offered profile from a discovered endpoint's QoS."""
    reliability = "reliable"
    durability = "volatile"
    depth = 10
    for policy in qos:
        text = repr(policy)
        if "BestEffort" in text:
            reliability = "best_effort"
        elif "TransientLocal" in text or "Transient" in text or "Persistent" in text:
            durability = "transient_local"
        elif "KeepAll" in text:
            depth = 0
        elif "KeepLast" in text:
            depth = int(getattr(policy, "depth", depth))
    return QosProfile(reliability, durability, depth)  # type: ignore[arg-type]


_participants: dict[int, tuple[Domain | None, DomainParticipant]] = {}


def participant() -> DomainParticipant:
    """One participant per process and domain (each takes a unicast participant index)."""
    did = domain_id()
    if did not in _participants:
        config = cyclone_config()
        domain = Domain(did, config) if config else None
        # USER_DATA as rmw_cyclonedds sets it (the default enclave "/").
        qos = Qos(Policy.Userdata(data=b"enclave=/;"))
        _participants[did] = (domain, DomainParticipant(did, qos=qos))
        _dds_write_set_batch(True)  # applies to the domain just created, before any writer
    return _participants[did][1]


# ROS 2 graph information (rmw_dds_common): which nodes a participant holds and which readers and
# writers belong to each. Topic name without the "rt/" prefix; QoS as rmw_cyclonedds creates its
# writer: reliable, transient local, keep last 1 (a late joiner gets the current state), no
# autodispose.
DISCOVERY_INFO_TOPIC = "ros_discovery_info"
DISCOVERY_INFO_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
DISCOVERY_INFO_QOS = PROFILES["latched"]


def ros_gid(entity: Any) -> bytes:
    """An entity's ROS GID: its 16-byte DDS GUID (prefix + entity id), byte for byte as
    rmw_cyclonedds_cpp's convert_guid_to_gid copies ``dds_guid_t.v`` (Jazzy: 16-byte GIDs)."""
    return bytes(entity.guid.bytes)


class _GraphInfo:
    """This process's ``ParticipantEntitiesInfo`` on ``ros_discovery_info``, one per participant.

    Rebuilt whenever a node, reader or writer is added or removed, and written only when it
    differs from the last sample (the writer keeps that one for late joiners). Nodes are listed
    in creation order, their readers and writers in creation order, as rmw_dds_common's graph
    cache lists them; the discovery writer itself belongs to no node, as in rmw.
    """

    def __init__(self, participant: DomainParticipant) -> None:
        self.participant = participant
        self.nodes: list[DdsBackend] = []
        self._lock = threading.Lock()
        self._pub: DdsPublisher | None = None
        self._last: bytes | None = None

    def message(self) -> Any:
        def gid(entity: Any) -> Any:
            return new_message("rmw_dds_common/msg/Gid", data=list(ros_gid(entity)))

        nodes = [
            new_message(
                "rmw_dds_common/msg/NodeEntitiesInfo",
                node_namespace=node.namespace,
                node_name=node.node_name,
                reader_gid_seq=[gid(s.reader) for s in node._subscriptions],
                writer_gid_seq=[gid(p.writer) for p in node._publishers],
            )
            for node in self.nodes
        ]
        return new_message(
            DISCOVERY_INFO_TYPE, gid=gid(self.participant), node_entities_info_seq=nodes
        )

    def add(self, node: "DdsBackend") -> None:
        with self._lock:
            self.nodes.append(node)
        self.update()

    def remove(self, node: "DdsBackend") -> None:
        with self._lock:
            if node in self.nodes:
                self.nodes.remove(node)
        self.update()

    def update(self) -> None:
        """Publish the current state if it changed (cheap enough to call on every change)."""
        with self._lock:
            msg = self.message()
            data = serialize(msg)
            if data == self._last:
                return
            if self._pub is None:
                topic = Topic(
                    self.participant, DISCOVERY_INFO_TOPIC, idl_struct(DISCOVERY_INFO_TYPE)
                )
                qos = dds_qos(DISCOVERY_INFO_QOS, DISCOVERY_INFO_TYPE, writer=True)
                qos += Qos(Policy.WriterDataLifecycle(autodispose=False))
                writer = DataWriter(self.participant, topic, qos)
                # Its own flush queue: written outside any executor turn, so sent at once.
                self._pub = DdsPublisher(
                    DISCOVERY_INFO_TOPIC,
                    DISCOVERY_INFO_TYPE,
                    writer,
                    _FlushQueue(),
                    DISCOVERY_INFO_QOS,
                )
            self._pub.publish(msg)
            self._last = data


_graph_infos: dict[int, _GraphInfo] = {}


def graph_info() -> _GraphInfo:
    """The ``ros_discovery_info`` state of this process's participant in the current domain."""
    did = domain_id()
    if did not in _graph_infos:
        _graph_infos[did] = _GraphInfo(participant())
    return _graph_infos[did]


class _FlushQueue:
    """Publishers that wrote during the current executor turn, flushed when the turn ends.

    Outside a turn (node construction, shutdown, another thread) a write is flushed at once.
    """

    def __init__(self) -> None:
        self.turn_thread: int | None = None
        self.dirty: set[DdsPublisher] = set()

    def wrote(self, pub: "DdsPublisher") -> None:
        if self.turn_thread == threading.get_ident():
            self.dirty.add(pub)
        else:
            pub.flush()

    def flush(self) -> None:
        dirty, self.dirty = self.dirty, set()
        for pub in dirty:
            pub.flush()


def _matched_handles(entity: Any, getter: Callable[..., int]) -> list[int]:
    """Instance handles of the endpoints matched to a reader or writer.

    cyclonedds' own get_matched_* sizes its buffer by a first call and fails (IndexError) when
    a match arrives between the two calls; here the buffer grows until the answer fits.
    """
    capacity = 16
    while True:
        buffer = (dds_c_t.instance_handle * capacity)()
        ret = getter(entity._ref, ct.cast(buffer, ct.POINTER(dds_c_t.instance_handle)), capacity)
        if ret < 0:
            raise DDSException(ret, "getting matched endpoints")
        if ret <= capacity:
            return [buffer[i] for i in range(ret)]
        capacity = ret + 16


class _MatchedGids:
    """GIDs of an endpoint's matched remote endpoints, cached by instance handle."""

    def __init__(self) -> None:
        self.by_handle: dict[int, str] = {}

    def gid(self, handle: int, lookup: Callable[[int], Any]) -> str | None:
        """The GID behind a handle (None if it was unmatched in between)."""
        gid = self.by_handle.get(handle)
        if gid is None:
            try:
                data = lookup(handle)
            except DDSException:
                data = None
            if data is None:
                return None
            gid = self.by_handle[handle] = str(data.key)
        return gid

    def gids(self, handles: list[int], lookup: Callable[[int], Any]) -> tuple[str, ...]:
        return tuple(sorted(g for h in handles if (g := self.gid(h, lookup)) is not None))


def _endpoint(
    topic: str, kind: str, entity: Any, profile: QosProfile, matched: tuple[str, ...]
) -> Endpoint:
    return Endpoint(
        topic=topic,
        kind=kind,
        gid=str(entity.guid),
        reliable=profile.reliability == "reliable",
        transient_local=profile.durability == "transient_local",
        matched=matched,
        matched_count=len(matched),
    )


@dataclass(eq=False)  # hashable by identity: a member of the flush queue's set
class DdsPublisher:
    topic: str
    type_name: str
    writer: DataWriter
    flush_queue: _FlushQueue
    profile: QosProfile = PROFILES["default"]
    _matched: _MatchedGids = field(default_factory=_MatchedGids)

    def publish(self, msg: Any) -> None:
        data = serialize(msg)
        pad = (-len(data)) % 4
        if pad:
            data += b"\0" * pad
        self.publish_raw(data)

    def publish_raw(self, data: bytes) -> None:
        ret = ddspy_write(self.writer._ref, data)
        if ret < 0:
            raise DDSException(ret, f"writing {self.type_name} on {self.topic}")
        self.flush_queue.wrote(self)

    def flush(self) -> None:
        """Send what this writer has queued (write batching)."""
        ret = _dds_write_flush(self.writer._ref)
        if ret < 0:
            raise DDSException(ret, f"flushing the writer of {self.topic}")

    def matched(self) -> list[int]:
        return _matched_handles(self.writer, self.writer._get_matched_subscriptions)

    def subscription_count(self) -> int:
        return len(self.matched())

    def endpoint(self) -> Endpoint:
        gids = self._matched.gids(self.matched(), self.writer.get_matched_subscription_data)
        return _endpoint(self.topic, "writer", self.writer, self.profile, gids)


@dataclass
class DdsSubscription:
    topic: str
    type_name: str
    reader: DataReader
    condition: ReadCondition
    callback: Callable[[Any], None]
    raw: bool
    profile: QosProfile = PROFILES["default"]
    _matched: _MatchedGids = field(default_factory=_MatchedGids)
    _recent: dict[str | int, list[Any]] = field(default_factory=dict)  # [latest, recent times]
    redeliveries: int = 0

    def matched(self) -> list[int]:
        return _matched_handles(self.reader, self.reader._get_matched_publications)

    def _redelivered(self, info: Any) -> bool:
        """Whether this sample was delivered before: same writer, same source timestamp.

        Seen under SIGSTOP of nodes (2 of 15 paused-node campaigns before this filter, keyed
        then by the writer's instance handle, which changes if DDS rediscovers the writer):
        one reader got a run of a writer's samples twice, the other readers once. Keyed by the
        writer's GUID since; no duplicate in 10 runs after that, so whether this filter is what
        stopped it is not established. A node that publishes the same stamp twice writes twice
        (two source timestamps) and is not affected: the identification still sees and
        reports such duplicates.
        """
        # The writer's GUID: stable if DDS rediscovers it under a new handle (the handle itself
        # once it is no longer matched).
        handle = info.publication_handle
        writer = self._matched.gid(handle, self.reader.get_matched_publication_data) or handle
        recent = self._recent.get(writer)
        if recent is None:
            recent = self._recent[writer] = [-1, deque(maxlen=_REDELIVERY_WINDOW)]
        ts = info.source_timestamp
        if ts > recent[0]:  # the usual case: later than anything from this writer
            recent[0] = ts
            recent[1].append(ts)
            return False
        if ts in recent[1]:
            self.redeliveries += 1
            _log.warning(
                "%s: dropped a sample delivered twice by DDS (same writer and source time; "
                "%d so far)",
                self.topic,
                self.redeliveries,
            )
            return True
        recent[1].append(ts)  # an earlier time, never seen: the writer's clock stepped back
        return False

    def publisher_count(self) -> int:
        return len(self.matched())

    def endpoint(self) -> Endpoint:
        gids = self._matched.gids(self.matched(), self.reader.get_matched_publication_data)
        return _endpoint(self.topic, "reader", self.reader, self.profile, gids)

    def drain(self) -> int:
        """Take one batch of available samples and deliver them; returns how many.

        One batch per subscription per spin keeps subscriptions fair: a busy topic cannot
        starve another one whose samples a callback needs (e.g. the pitch a tap sample needs).
        """
        batch = ddspy_take(self.reader._ref, _ANY_STATE, _TAKE_BATCH)
        if isinstance(batch, int):
            raise DDSException(batch, f"taking from {self.topic}")
        delivered = 0
        for data, info in batch:
            if not info.valid_data:  # dispose/unregister notifications carry no sample
                continue
            if self.profile.reliability == "reliable" and self._redelivered(info):
                continue
            if self.raw:
                self.callback((data, time.time_ns()))
            else:
                self.callback(deserialize(data, self.type_name))
            delivered += 1
        return delivered


@dataclass
class DdsTimer:
    period_ns: int
    callback: Callable[[], None]
    next_ns: int
    cancelled: bool = False

    def cancel(self) -> None:
        self.cancelled = True


class DdsBackend:
    """Single-threaded executor: one WaitSet over all readers, timers by deadline."""

    name = "dds"

    def __init__(self, node_name: str, namespace: str) -> None:
        self.node_name = node_name
        self.namespace = namespace
        self.participant = participant()
        self._topics: dict[tuple[str, str], Topic] = {}
        self._subscriptions: list[DdsSubscription] = []
        self._publishers: list[DdsPublisher] = []
        self._timers: list[DdsTimer] = []
        self._flush_queue = _FlushQueue()
        self._waitset = WaitSet(self.participant)
        self._guard = GuardCondition(self.participant)
        self._waitset.attach(self._guard)
        self._discovery: BuiltinDataReader | None = None
        self._discovered: dict[str, tuple[str, QosProfile | None]] = {}
        self._graph = graph_info()
        self._graph.add(self)  # ROS 2 tools see the node (ros_discovery_info)

    def _topic(self, topic: str, type_name: str) -> Topic:
        key = (topic, type_name)
        if key not in self._topics:
            self._topics[key] = Topic(self.participant, "rt" + topic, idl_struct(type_name))
        return self._topics[key]

    def create_publisher(self, topic: str, type_name: str, qos: QosProfile) -> DdsPublisher:
        type_name = normalize_type_name(type_name)
        writer = DataWriter(
            self.participant, self._topic(topic, type_name), dds_qos(qos, type_name)
        )
        pub = DdsPublisher(topic, type_name, writer, self._flush_queue, qos)
        self._publishers.append(pub)
        self._graph.update()
        return pub

    def create_subscription(
        self,
        topic: str,
        type_name: str,
        callback: Callable[[Any], None],
        qos: QosProfile,
        raw: bool = False,
    ) -> DdsSubscription:
        type_name = normalize_type_name(type_name)
        reader = DataReader(
            self.participant, self._topic(topic, type_name), dds_qos(qos, type_name)
        )
        condition = ReadCondition(reader, _ANY_STATE)
        self._waitset.attach(condition)
        sub = DdsSubscription(topic, type_name, reader, condition, callback, raw, qos)
        self._subscriptions.append(sub)
        self._graph.update()
        return sub

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> DdsTimer:
        period_ns = int(period_s * 1e9)
        timer = DdsTimer(period_ns, callback, time.monotonic_ns() + period_ns)
        self._timers.append(timer)
        return timer

    def new_message(self, type_name: str, **fields: Any) -> Any:
        return new_message(type_name, **fields)

    def wake(self) -> None:
        """Wake a blocked spin_once from another thread (drivers with receive threads)."""
        self._guard.set(True)

    def spin_once(self, timeout_s: float) -> int:
        """One executor turn; returns how many samples it delivered."""
        self._flush_queue.turn_thread = threading.get_ident()
        try:
            return self._turn(timeout_s)
        finally:
            self._flush_queue.turn_thread = None
            self._flush_queue.flush()

    def _turn(self, timeout_s: float) -> int:
        now = time.monotonic_ns()
        timeout_ns = int(timeout_s * 1e9)
        self._timers = [t for t in self._timers if not t.cancelled]
        for timer in self._timers:
            timeout_ns = min(timeout_ns, timer.next_ns - now)
        if timeout_ns > 0:
            self._waitset.wait(timeout_ns)
        self._guard.set(False)
        busy = True
        delivered = 0
        while busy:  # round robin, one batch each, until every reader is empty
            busy = False
            for sub in self._subscriptions:
                n = sub.drain()
                delivered += n
                if n >= _TAKE_BATCH:
                    busy = True
            self._flush_queue.flush()  # what this round produced goes downstream now
            if time.monotonic_ns() - now > 20_000_000:
                break  # let due timers run
        now = time.monotonic_ns()
        for timer in list(self._timers):
            if not timer.cancelled and timer.next_ns <= now:
                timer.next_ns += timer.period_ns
                if timer.next_ns <= now:  # skip missed periods instead of bursting
                    timer.next_ns = now + timer.period_ns
                timer.callback()
        return delivered

    def now_ns(self) -> int:
        return time.time_ns()

    def match_signature(self) -> tuple[object, ...]:
        """The matched endpoints' instance handles, per reader and writer: equal as long as
        nothing was matched or unmatched (the readiness report is rebuilt only otherwise)."""
        return tuple(tuple(p.matched()) for p in self._publishers) + tuple(
            tuple(s.matched()) for s in self._subscriptions
        )

    def endpoints(self) -> list[Endpoint]:
        """This node's readers and writers with the GIDs they have matched (start barrier)."""
        return [p.endpoint() for p in self._publishers] + [
            s.endpoint() for s in self._subscriptions
        ]

    def topic_types(self) -> dict[str, tuple[str, QosProfile | None]]:
        """Topics with at least one writer in the domain, from DCPSPublication discovery."""
        if self._discovery is None:
            self._discovery = BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)
        for sample in self._discovery.take(N=256):
            topic_name = getattr(sample, "topic_name", None)
            dds_type = getattr(sample, "type_name", None)
            if not topic_name or not dds_type or not topic_name.startswith("rt/"):
                continue
            parts = dds_type.split("::")
            if len(parts) != 4 or parts[2] != "dds_":
                continue
            ros_type = f"{parts[0]}/{parts[1]}/{parts[3].rstrip('_')}"
            try:
                profile = profile_from_dds_qos(sample.qos)
            except Exception:
                profile = None
            self._discovered[topic_name[2:]] = (ros_type, profile)
        return dict(self._discovered)

    def close(self) -> None:
        """Delete this node's readers and writers now, so that peers see them leave at once
        (an orderly unmatch) instead of at the participant's lease expiry. A writer with data
        not yet acknowledged lingers (Cyclone's writer linger, 1 s) until its readers have it:
        a recorder stopped with the graph still gets the last samples."""
        for sub in self._subscriptions:
            try:
                self._waitset.detach(sub.condition)
            except DDSException:
                pass
        for pub in self._publishers:
            _delete_entity(pub.writer)
        for sub in self._subscriptions:
            _delete_entity(sub.condition)
            _delete_entity(sub.reader)
        self._subscriptions.clear()
        self._publishers.clear()
        self._timers.clear()
        self._graph.remove(self)  # the node and its endpoints leave the ROS graph


def _delete_entity(entity: Any) -> None:
    """dds_delete an entity now (cyclonedds keeps every entity alive in a class-level table,
    so dropping the Python reference never deletes it)."""
    table = type(entity)._entities
    ref = getattr(entity, "_ref", None)
    if ref is None or ref not in table:
        return
    del table[ref]
    entity._delete(ref)

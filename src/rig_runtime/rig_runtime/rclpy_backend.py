"""rclpy backend: the node API on the ROS 2 client library (docs/design.md §3).

rclpy comes from the PyPI wheels (``pip install "ros-jazzy-rclpy[fastrtps]"
ros-jazzy-common-interfaces``) or from a sourced ROS 2 Jazzy install. What rclpy gives a node
here is what every rclpy node has:

- ``--ros-args`` (``-r``, ``__node``, ``__ns``, ``-p``, ``--params-file``, ``--log-level``) are
  parsed by rcl, per node (``cli_args``), so several nodes can share a process;
- every declared parameter is an rclpy parameter with a descriptor (description, range,
  read-only), so ``ros2 param list|get|describe|dump|set`` work; a live parameter
  (``Parameter.read_only=False``) takes a new value at once, a read-only one is refused by
  rclpy with its reason;
- logs go through the node's rcl logger: to the console and to ``/rosout``.

Messages stay the runtime's own (messages.py: rosbags dataclasses with numpy sequences), the
same objects as on the Cyclone DDS backend: publishers send the runtime's CDR bytes
(``publish(bytes)`` is rclpy's serialized publish) and subscriptions are ``raw=True``,
decoded by the same codec. So node code, recorded bytes and results do not depend on the
backend, and the message conversion that made rclpy's executors slow is skipped. The
executor is ``rclpy.experimental.EventsExecutor`` (``RIG_RCLPY_EXECUTOR=single`` selects
rclpy's SingleThreadedExecutor; bench/transport.py compares them).
"""

import array
import importlib
import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .barrier import Endpoint
from .messages import deserialize, new_message, normalize_type_name, serialize
from .names import ArgumentError
from .params import Parameter, ParameterError, ParameterSet, assign, default_parameters
from .qos import QosProfile
from .ros_environment import INSTALL_RCLPY, domain_id

EXECUTOR_ENV = "RIG_RCLPY_EXECUTOR"
# When a node closes, its reliable writers wait this long for their readers to acknowledge what
# they hold, as Cyclone DDS's writer linger (1 s) does on the DDS backend (dds_backend.close).
# Fast DDS deletes a writer at once: a reader that lost the end of a burst (a full receive
# queue, a paused process) gets its repair from the writer only, so it lost that end for good.
WRITER_LINGER_S = 1.0
# Fast DDS reads its default QoS profiles from this file when the first participant is made.
PROFILES_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
PROFILES_FILE = Path(__file__).with_name("fastdds_profiles.xml")
PROFILE_BLOCKING_S = 60  # the writers' max_blocking_time in that file
# rmw_fastrtps publishes synchronously (RMW_FASTRTPS_PUBLICATION_MODE unset): the publishing
# callback sends each sample to every reader. ASYNCHRONOUS (Fast DDS's sending thread) streamed
# the default campaign at 15.4× real time against 11.6×, but in a mixed graph (generator and
# plant on rclpy, lift, identifier and recorder on Cyclone DDS) it lost tens of samples right
# after the start barrier in 3 runs of 3, none in synchronous mode (README, "Known limits"):
# Cyclone starts a reliable session with another implementation's writer at its first
# heartbeat (docs/design.md §3.5). So this backend leaves the variable as it finds it:
# `aero-rig campaign` sets it for an all-rclpy graph (ros_environment.asynchronous_publication).


def message_class(type_name: str) -> Any:
    """The generated rclpy message class of a ROS type name (``sensor_msgs/msg/JointState``),
    imported from its package as ``from sensor_msgs.msg import JointState`` would."""
    pkg, kind, name = normalize_type_name(type_name).split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError) as exc:
        raise ImportError(
            f"the rclpy backend needs the Python package of {type_name} ({pkg}): "
            f"{INSTALL_RCLPY} ({exc})"
        ) from exc


def _rclpy_qos(profile: QosProfile) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if profile.keep_all else HistoryPolicy.KEEP_LAST,
        depth=max(profile.depth, 1),
        reliability=ReliabilityPolicy.RELIABLE
        if profile.reliability == "reliable"
        else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if profile.durability == "transient_local"
        else DurabilityPolicy.VOLATILE,
    )


@dataclass(eq=False)
class RclpyPublisher:
    publisher: Any
    topic: str
    type_name: str
    profile: QosProfile

    def publish(self, msg: Any) -> None:
        self.publish_raw(serialize(msg))

    def publish_raw(self, data: bytes) -> None:
        try:
            self.publisher.publish(bytes(data))
        except Exception as exc:  # rclpy's RCLError: say which writer and why it gave up
            raise RuntimeError(
                f"publishing on {self.topic} failed: a reader has not acknowledged for "
                f"{PROFILE_BLOCKING_S} s (Fast DDS's max_blocking_time), or it is gone: {exc}"
            ) from exc

    def subscription_count(self) -> int:
        return int(self.publisher.get_subscription_count())


@dataclass(eq=False)
class RclpySubscription:
    subscription: Any
    topic: str
    type_name: str
    profile: QosProfile

    def publisher_count(self) -> int:
        return int(self.subscription.get_publisher_count())


def _endpoint(
    entity: RclpyPublisher | RclpySubscription, kind: str, gid: str, matched_count: int
) -> Endpoint:
    return Endpoint(
        topic=entity.topic,
        kind=kind,
        gid=gid,
        reliable=entity.profile.reliability == "reliable",
        transient_local=entity.profile.durability == "transient_local",
        matched=None,
        matched_count=matched_count,
    )


def _descriptor(p: Parameter) -> Any:
    """An rcl_interfaces ParameterDescriptor from a declaration (type, description, range)."""
    from rcl_interfaces.msg import (
        FloatingPointRange,
        IntegerRange,
        ParameterDescriptor,
    )

    descriptor = ParameterDescriptor(
        name=p.name,
        type=_parameter_type(p),
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


def _parameter_type(p: Parameter) -> int:
    from rcl_interfaces.msg import ParameterType

    scalar = {
        bool: ParameterType.PARAMETER_BOOL,
        int: ParameterType.PARAMETER_INTEGER,
        float: ParameterType.PARAMETER_DOUBLE,
        str: ParameterType.PARAMETER_STRING,
    }
    array = {
        bool: ParameterType.PARAMETER_BOOL_ARRAY,
        int: ParameterType.PARAMETER_INTEGER_ARRAY,
        float: ParameterType.PARAMETER_DOUBLE_ARRAY,
        str: ParameterType.PARAMETER_STRING_ARRAY,
    }
    return int((array if p.is_list else scalar)[p.value_type])


class _RosoutHandler(logging.Handler):
    """Python log records -> the node's rcl logger (console and /rosout)."""

    def __init__(self, rcl_logger: Any) -> None:
        super().__init__()
        self.rcl_logger = rcl_logger

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record)
            level = record.levelno
            if level >= logging.CRITICAL:
                self.rcl_logger.fatal(text)
            elif level >= logging.ERROR:
                self.rcl_logger.error(text)
            elif level >= logging.WARNING:
                self.rcl_logger.warning(text)
            elif level >= logging.INFO:
                self.rcl_logger.info(text)
            else:
                self.rcl_logger.debug(text)
        except Exception:
            self.handleError(record)


def _import_rclpy() -> Any:
    try:
        import rclpy
    except ImportError as exc:
        raise ArgumentError(
            f"RIG_RUNTIME_BACKEND=rclpy but rclpy does not import ({exc}); install it with "
            f"`{INSTALL_RCLPY}` (CPython 3.10-3.13 on x86_64 Linux) or source a ROS 2 Jazzy "
            "install, or use RIG_RUNTIME_BACKEND=dds"
        ) from None
    return rclpy


def _events_executor(context: Any) -> Any:
    """rclpy.experimental.EventsExecutor without its ``faulthandler.enable()``, which fails
    where stderr has no file descriptor (pytest's capture) and is the process's business."""
    from rclpy.impl.implementation_singleton import rclpy_implementation

    executor = rclpy_implementation.EventsExecutor(context)
    context.on_shutdown(executor.wake)  # as the wrapper does: a shutdown ends a blocked spin
    return executor


class RclpyBackend:
    name = "rclpy"

    def __init__(self, node_name: str, namespace: str, argv: Sequence[str] = ()) -> None:
        rclpy = _import_rclpy()
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        cli_args = list(argv)
        choice = os.environ.get(EXECUTOR_ENV, "events").strip().lower()
        if choice not in ("events", "single"):  # checked before anything is created
            raise ArgumentError(f"{EXECUTOR_ENV}={choice!r}: expected 'events' or 'single'")
        # Writers block up to 60 s for a slow reader, as on the DDS backend (the XML says why).
        os.environ.setdefault(PROFILES_ENV, str(PROFILES_FILE))
        # A context per node: its own participant in the domain of this moment (tests move
        # between domains), shut down with the node. run_node handles SIGINT/SIGTERM itself
        # (an orderly stop that lets the recorder drain), so rclpy installs no handler.
        self._context = rclpy.Context()
        rclpy.init(
            context=self._context,
            domain_id=domain_id(),
            signal_handler_options=SignalHandlerOptions.NO,
        )
        try:
            self.node = rclpy.create_node(
                node_name,
                namespace=namespace,
                context=self._context,
                cli_args=cli_args or None,
                use_global_arguments=False,
                start_parameter_services=True,
            )
        except Exception as exc:  # rcl's argument parser: RCLError / ValueError
            self._context.try_shutdown()
            raise ArgumentError(
                f"invalid ROS arguments {cli_args}: {type(exc).__name__}: {exc}"
            ) from None
        self._executor = (
            _events_executor(self._context)
            if choice == "events"
            else SingleThreadedExecutor(context=self._context)
        )
        self._executor.add_node(self.node)
        self._publishers: list[RclpyPublisher] = []
        self._subscriptions: list[RclpySubscription] = []
        self._delivered = 0
        self._params: ParameterSet | None = None
        self._on_change: Callable[[str, Any], None] | None = None

    # -- names and parameters, done by rcl ----------------------------------------------------
    @property
    def node_name(self) -> str:
        return str(self.node.get_name())

    @property
    def namespace(self) -> str:
        return str(self.node.get_namespace())

    @property
    def log_level(self) -> int:
        """The rcl logger's effective level (rcutils severities equal Python's levels)."""
        return int(self.node.get_logger().get_effective_level())

    def resolve_topic(self, topic: str) -> str:
        """Expanded and remapped as rcl does it (``~``, relative names, ``-r from:=to``)."""
        return str(self.node.resolve_topic_name(topic))

    def declare_parameters(self, declared: Sequence[Parameter]) -> ParameterSet:
        """Declare every parameter with its descriptor; values from rcl's overrides
        (``--params-file``, ``-p``) are checked by the same rules as on the DDS backend."""
        from rclpy.exceptions import InvalidParameterValueException

        result = default_parameters(declared)
        for name, override in self.node._parameter_overrides.items():  # parsed by rcl
            given = override.value
            if isinstance(given, array.array):  # rclpy's numeric arrays
                given = list(given)
            assign(result, name, given, f"--ros-args ({name}:={given!r})")
        for p in declared:
            if result.sources[p.name] != "default":
                result.sources[p.name] = "--ros-args"
            try:
                self._declare(p, result.values[p.name])
            except InvalidParameterValueException as exc:
                raise ParameterError(f"parameter {p.name!r}: {exc}") from None
        self._params = result
        self.node.add_on_set_parameters_callback(self._set_parameters)
        return result

    def _declare(self, p: Parameter, value: Any) -> None:
        from rclpy.parameter import Parameter as RclpyParameter

        descriptor = _descriptor(p)
        if not (p.is_list and not value):
            self.node.declare_parameter(
                p.name, list(value) if p.is_list else value, descriptor, ignore_override=True
            )
            return
        # An empty list does not say its element type: declare the type, then set [] (rclpy
        # refuses a set on a read-only parameter, so read-only is restored afterwards).
        kind = RclpyParameter.Type(descriptor.type)
        read_only, descriptor.read_only = descriptor.read_only, False
        self.node.declare_parameter(p.name, kind, descriptor, ignore_override=True)
        self.node.set_parameters([RclpyParameter(p.name, kind, [])])
        self.node.describe_parameter(p.name).read_only = read_only

    def on_parameter_change(self, callback: Callable[[str, Any], None]) -> None:
        self._on_change = callback

    def _set_parameters(self, parameters: list[Any]) -> Any:
        """``ros2 param set``: rclpy has already refused read-only parameters, wrong types and
        values outside the descriptor's range; choices and element ranges are checked here."""
        from rcl_interfaces.msg import SetParametersResult

        assert self._params is not None
        checked: list[tuple[str, Any]] = []
        for param in parameters:
            declared = self._params.declared.get(param.name)
            if declared is None:
                continue  # rclpy's own (use_sim_time)
            try:
                given = list(param.value) if isinstance(param.value, array.array) else param.value
                checked.append((param.name, declared.validate(given, "ros2 param set")))
            except ParameterError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        for name, value in checked:
            self._params.values[name] = value
            self._params.sources[name] = "ros2 param set"
            if self._on_change is not None:
                self._on_change(name, value)
        return SetParametersResult(successful=True)

    def log_handler(self) -> logging.Handler:
        handler = _RosoutHandler(self.node.get_logger())
        handler.setFormatter(logging.Formatter("%(message)s"))
        return handler

    # -- publishers, subscriptions, timers ---------------------------------------------------
    def create_publisher(self, topic: str, type_name: str, qos: QosProfile) -> RclpyPublisher:
        type_name = normalize_type_name(type_name)
        pub = self.node.create_publisher(message_class(type_name), topic, _rclpy_qos(qos))
        publisher = RclpyPublisher(pub, topic, type_name, qos)
        self._publishers.append(publisher)
        return publisher

    def create_subscription(
        self,
        topic: str,
        type_name: str,
        callback: Callable[[Any], None],
        qos: QosProfile,
        raw: bool = False,
    ) -> RclpySubscription:
        type_name = normalize_type_name(type_name)

        def deliver(data: bytes) -> None:
            self._delivered += 1
            if raw:
                callback((data, time.time_ns()))
            else:
                callback(deserialize(data, type_name))

        sub = self.node.create_subscription(
            message_class(type_name), topic, deliver, _rclpy_qos(qos), raw=True
        )
        subscription = RclpySubscription(sub, topic, type_name, qos)
        self._subscriptions.append(subscription)
        return subscription

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> Any:
        return self.node.create_timer(period_s, callback)

    def new_message(self, type_name: str, **fields: Any) -> Any:
        return new_message(type_name, **fields)

    def spin_once(self, timeout_s: float) -> int:
        """Wait up to ``timeout_s`` for work and handle one ready item (a sample, a timer, a
        service request); returns how many samples were delivered (0 or 1)."""
        before = self._delivered
        self._executor.spin_once(timeout_sec=max(timeout_s, 0.0))
        return self._delivered - before

    def wake(self) -> None:
        self._executor.wake()

    def now_ns(self) -> int:
        return time.time_ns()

    # -- the start barrier and graph queries ------------------------------------------------
    def match_signature(self) -> tuple[object, ...]:
        """Matched counts per reader and writer (rclpy names no matched endpoints)."""
        return tuple(e.matched_count for e in self.endpoints())

    def endpoints(self) -> list[Endpoint]:
        """Readers and writers with matched counts: rclpy does not name the matched endpoints
        (their GIDs), so the start barrier compares counts (barrier.py)."""
        fq = self.node.get_fully_qualified_name()
        writers = [
            _endpoint(p, "writer", f"{fq}#writer{i}", p.subscription_count())
            for i, p in enumerate(self._publishers)
        ]
        readers = [
            _endpoint(s, "reader", f"{fq}#reader{i}", s.publisher_count())
            for i, s in enumerate(self._subscriptions)
        ]
        return writers + readers

    def topic_types(self) -> dict[str, tuple[str, QosProfile | None]]:
        """Topics with at least one publisher, with their type and the QoS offered by the
        first (as the DDS backend's): a topic known only from its readers has no offered QoS
        yet, and a recorder that guessed one could ask for reliable from a best-effort
        writer and never be matched."""
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

        result: dict[str, tuple[str, QosProfile | None]] = {}
        for name, types in self.node.get_topic_names_and_types():
            profile = None
            for info in self.node.get_publishers_info_by_topic(name):
                q = info.qos_profile
                profile = QosProfile(
                    "best_effort" if q.reliability == ReliabilityPolicy.BEST_EFFORT else "reliable",
                    "transient_local"
                    if q.durability == DurabilityPolicy.TRANSIENT_LOCAL
                    else "volatile",
                    0 if q.history == HistoryPolicy.KEEP_ALL else int(q.depth),
                )
                break
            if profile is not None:
                result[name] = (types[0], profile)
        return result

    def _linger(self) -> list[str]:
        """Wait (WRITER_LINGER_S in all) until every reliable writer's samples are
        acknowledged; the topics of those whose samples were not."""
        from rclpy.duration import Duration

        deadline = time.monotonic() + WRITER_LINGER_S
        late = []
        for pub in self._publishers:
            if pub.profile.reliability != "reliable":
                continue
            remaining = max(deadline - time.monotonic(), 0.0)
            try:
                acked = pub.publisher.wait_for_all_acked(Duration(nanoseconds=int(remaining * 1e9)))
            except Exception:  # rclpy's RCLError: the writer cannot say
                acked = False
            if not acked:
                late.append(pub.topic)
        return late

    def close(self) -> None:
        late = self._linger()
        if late:
            self.node.get_logger().warning(
                f"closing with samples not acknowledged after {WRITER_LINGER_S:g} s on "
                f"{', '.join(sorted(set(late)))}: a reader is paused, starved or gone"
            )
        self._executor.remove_node(self.node)
        self._executor.shutdown()
        self.node.destroy_node()
        self._context.try_shutdown()

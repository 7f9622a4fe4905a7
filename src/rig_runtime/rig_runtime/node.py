"""The base class of every node of this project: an rclpy node with the rig's contract
(docs/design.md §3).

:class:`Node` *is* an ``rclpy.node.Node``. What it adds is what ROS does not provide and
every node of the rig needs: parameters declared once from a list of
:class:`~rig_runtime.params.Parameter` (each an rclpy parameter with its
``ParameterDescriptor``), the start barrier's readiness report, the anomaly log, the pause
watch, and typed endpoints for the interface contract's topics. A node module reads::

    PARAMETERS = [Parameter("fs", 200.0, "sample rate [Hz]", min=1.0)]

    class Generator:
        def __init__(self, node: Node) -> None:
            self.pub = node.create_publisher(PITCH_COMMAND.type, PITCH_COMMAND.name, "stream")
            node.create_timer(1.0 / node.params["fs"], self.tick)

    def main(argv=None) -> int:
        return run_node(Generator, "generator", PARAMETERS, argv, description=__doc__)

``create_publisher`` and ``create_subscription`` are rclpy's; given a ROS type *name* (the
interface contract's ``Topic.type``) instead of a message class, they send and take the
serialized CDR of the runtime's messages (rosbags dataclasses with numpy sequences,
messages.py) through rclpy's serialized publish and ``raw=True`` subscriptions. rclpy's
message conversion is skipped where it costs the most (bench/transport.py measures it).

rclpy comes from the PyPI wheels (``pip install "ros-jazzy-rclpy[fastrtps]"
ros-jazzy-common-interfaces``, CPython 3.10-3.13 on x86_64 Linux) or a sourced ROS 2 Jazzy.
"""

import array
import logging
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, overload

from . import ros_environment
from .anomaly import Anomaly, AnomalyLog
from .barrier import Endpoint, ReadinessReport
from .diagnostics import OK, diagnostic_array
from .flow import FLOW_PERIOD_S, FLOW_STATUS_SUFFIX, flow_values
from .interface import DIAGNOSTICS, EXPERIMENT_ANOMALY, GRAPH_READY
from .messages import (
    cdr_stamp_ns,
    deserialize,
    new_message,
    normalize_type_name,
    serialize,
    starts_with_header,
)
from .params import Parameter, ParameterError, ParameterSet, assign, default_parameters
from .participant_profile import participant_environment
from .qos import QosProfile, resolve_qos, to_rclpy_qos
from .ros_environment import LAUNCHER_PID_ENV, ArgumentError
from .signals import StopSignals

try:
    import rclpy
    import rclpy.node
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from rclpy.task import Future
except ImportError as _exc:  # the one line every graph command prints (ros_environment)
    raise ImportError(ros_environment.NO_RCLPY) from _exc

# spin()'s turn check: how soon a flag set by a signal handler (or a gone launcher) is read.
SPIN_TURN_S = 0.05
PAUSE_WATCH_S = 1.0  # the period of every node's pause watch (start_pause_watch)
EXECUTOR_ENV = "RIG_RCLPY_EXECUTOR"
# When a node closes, its reliable writers wait this long for their readers to acknowledge what
# they hold: Fast DDS deletes a writer at once, and a reader that lost the end of a burst (a
# full receive queue, a paused process) gets its repair from that writer only.
WRITER_LINGER_S = 1.0
PROFILE_BLOCKING_S = 60  # the writers' max_blocking_time in fastdds_profiles.xml

# Exit codes: 0 ok, 2 configuration error (bad parameters/arguments), 1 runtime failure.
EXIT_CONFIG_ERROR = 2


def message_class(type_name: str) -> Any:
    """The generated rclpy message class of a ROS type name (``sensor_msgs/msg/JointState``),
    imported from its package as ``from sensor_msgs.msg import JointState`` would."""
    import importlib

    pkg, kind, name = normalize_type_name(type_name).split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError) as exc:
        raise ImportError(
            f"no Python package for {type_name} ({pkg}): {ros_environment.INSTALL_RCLPY} ({exc})"
        ) from exc


@dataclass(eq=False)
class CdrEndpoint:
    """What a reader or writer of the runtime's messages is: its rclpy entity (``handle``),
    resolved topic, ROS type name and QoS profile."""

    handle: Any  # rclpy.publisher.Publisher | rclpy.subscription.Subscription
    topic: str
    type_name: str
    profile: QosProfile
    # Its flow (flow.py): messages passed, and the last one's CDR bytes (its stamp is read only
    # when the flow is reported, not per message).
    count: int = 0
    last: bytes | None = None

    def __post_init__(self) -> None:
        # A reliable keep-all endpoint of stamped messages: its flow is reported.
        self.streams = (
            self.profile.keep_all
            and self.profile.reliability == "reliable"
            and starts_with_header(self.type_name)
        )

    def passed(self, data: bytes) -> None:
        """Count a message (its CDR bytes) through this endpoint."""
        self.count += 1
        self.last = data

    @property
    def stamp_ns(self) -> int:
        """The header stamp of the last stream message passed (0: none, or not a stream)."""
        return cdr_stamp_ns(self.last) if self.streams and self.last is not None else 0


class CdrPublisher(CdrEndpoint):
    """An rclpy publisher of the runtime's messages: ``publish(msg)`` sends their CDR bytes."""

    def publish(self, msg: Any) -> None:
        self.publish_raw(serialize(msg))

    def publish_raw(self, data: bytes) -> None:
        try:
            self.handle.publish(bytes(data))
        except Exception as exc:  # rclpy's RCLError: say which writer and why it gave up
            raise RuntimeError(
                f"publishing on {self.topic} failed: a reader has not acknowledged for "
                f"{PROFILE_BLOCKING_S} s (Fast DDS's max_blocking_time), or it is gone: {exc}"
            ) from exc
        self.passed(data)

    def subscription_count(self) -> int:
        return int(self.handle.get_subscription_count())

    def matched_count(self) -> int:
        return self.subscription_count()


class CdrSubscription(CdrEndpoint):
    """An rclpy ``raw=True`` subscription delivering runtime messages (or the bytes)."""

    polled_at: int = -1  # its count at the last flow report (Node._take_undelivered)
    undelivered: int = 0  # samples the flow report found held undelivered and took

    def publisher_count(self) -> int:
        return int(self.handle.get_publisher_count())

    def matched_count(self) -> int:
        return self.publisher_count()


def _descriptor(p: Parameter) -> Any:
    """An rcl_interfaces ParameterDescriptor from a declaration (type, description, range)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

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
    arrays = {
        bool: ParameterType.PARAMETER_BOOL_ARRAY,
        int: ParameterType.PARAMETER_INTEGER_ARRAY,
        float: ParameterType.PARAMETER_DOUBLE_ARRAY,
        str: ParameterType.PARAMETER_STRING_ARRAY,
    }
    return int((arrays if p.is_list else scalar)[p.value_type])


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


def _events_executor(context: Any) -> Any:
    """rclpy.experimental.EventsExecutor without its ``faulthandler.enable()``, which fails
    where stderr has no file descriptor (pytest's capture) and is the process's business."""
    from rclpy.impl.implementation_singleton import rclpy_implementation

    executor = rclpy_implementation.EventsExecutor(context)
    context.on_shutdown(executor.wake)  # as the wrapper does: a shutdown ends a blocked spin
    return executor


def _new_context(domain: int) -> Any:
    """A context per node: its own participant in ``domain``, the domain of this moment (tests
    move between domains), shut down with the node. run_node handles SIGINT/SIGTERM itself (an
    orderly stop that lets the recorder drain), so rclpy installs no handler."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    return context


class Node(rclpy.node.Node):
    """An rclpy node with validated parameters, the start barrier, anomalies and a pause watch.

    Each instance owns its ``rclpy.Context`` and executor (rclpy's ``EventsExecutor``;
    ``RIG_RCLPY_EXECUTOR=single`` for its ``SingleThreadedExecutor``).
    """

    def __init__(
        self,
        name: str,
        parameters: Sequence[Parameter] = (),
        argv: Sequence[str] | None = None,
        namespace: str | None = None,
    ) -> None:
        args = list(sys.argv[1:] if argv is None else argv)
        choice = os.environ.get(EXECUTOR_ENV, "events").strip().lower()
        if choice not in ("events", "single"):  # checked before anything is created
            raise ArgumentError(f"{EXECUTOR_ENV}={choice!r}: expected 'events' or 'single'")
        domain = ros_environment.check()  # a bad ROS environment too
        # rmw_fastrtps makes the participant with the first node of a context: both under the
        # profile of participant_profile.py (discovery over UDP alone; writers that block up to
        # 60 s for a slow reader, fastdds_profiles.xml).
        with participant_environment():
            context = _new_context(domain)
            try:
                # rcl parses --ros-args (names, remaps, -p, --params-file, --log-level), per node.
                super().__init__(
                    name,
                    context=context,
                    namespace=namespace,
                    cli_args=args or None,
                    use_global_arguments=False,
                    start_parameter_services=True,
                )
            except Exception as exc:  # rcl's argument parser: RCLError / ValueError
                context.try_shutdown()
                raise ArgumentError(
                    f"invalid ROS arguments {args}: {type(exc).__name__}: {exc}"
                ) from None
        self._rig_context = context
        try:
            self.name = str(self.get_name())
            self.namespace = str(self.get_namespace())
            self.fq_name = str(self.get_fully_qualified_name())
            self.params = self._declare_parameters(parameters)
        except Exception:
            self.destroy_node()
            context.try_shutdown()
            raise
        self.logger = _make_logger(self.fq_name, int(self.get_logger().get_effective_level()))
        self.logger.addHandler(self._log_handler())
        self._rig_executor = (
            _events_executor(context)
            if choice == "events"
            else SingleThreadedExecutor(context=context)
        )
        self._rig_executor.add_node(self)
        self._cdr_publishers: list[CdrPublisher] = []
        self._cdr_subscriptions: list[CdrSubscription] = []
        self._delivered = 0
        self.exit_code = 0
        self._closed = False
        self._shutdown_requested = False
        self._spin_turn: Future | None = None  # the turn of spin() under way
        self._on_shutdown: list[Callable[[], None]] = []
        # Only a direct child of that launcher watches it (not a process that inherited the
        # variable further down).
        launcher = os.environ.get(LAUNCHER_PID_ENV, "")
        watched = launcher.isdigit() and int(launcher) == os.getppid()
        self._launcher_pid = int(launcher) if watched else None
        # Start barrier (barrier.py): what this node reports on /graph/ready.
        self._ready = True
        self._ready_reason = ""
        self._required_inputs: list[str] = []
        self._records: tuple[tuple[str, ...], tuple[str, ...]] = ((), ())
        self._ready_pub: CdrPublisher | None = None
        self._last_report = ""
        self._last_signature: object = None
        self._anomalies: AnomalyLog | None = None
        self._flow_pub: CdrPublisher | None = None
        self._flow_tick = 0.0  # monotonic time of the last flow report
        self._flow_period_s = FLOW_PERIOD_S
        # Pauses past the participant lease (start_pause_watch): how long this process did not run.
        self.paused_s: list[float] = []
        self._on_paused: list[Callable[[float], None]] = []
        self._last_watch = 0.0

    @property
    def middleware_description(self) -> str:
        """``rclpy (rmw_fastrtps_cpp)``, with rmw_fastrtps's publication mode when it was
        chosen (``rclpy (rmw_fastrtps_cpp, ASYNCHRONOUS publication)``), for the log."""
        from rclpy.utilities import get_rmw_implementation_identifier

        rmw = get_rmw_implementation_identifier()
        mode = os.environ.get(ros_environment.PUBLICATION_MODE_ENV)
        if mode and rmw.startswith("rmw_fastrtps"):
            return f"rclpy ({rmw}, {mode} publication)"
        return f"rclpy ({rmw})"

    # -- parameters: rclpy's, each declared once with its descriptor --------------------------
    def _declare_parameters(self, declared: Sequence[Parameter]) -> ParameterSet:
        """Declare every parameter with its descriptor; values from rcl's overrides
        (``--params-file``, ``-p``) are checked by :meth:`Parameter.validate` (types, ranges,
        choices, list elements) first, so a bad one stops the node before any of its own
        publishers exists (rclpy's /parameter_events and /rosout writers already do)."""
        from rclpy.exceptions import InvalidParameterValueException

        result = default_parameters(declared)
        for name, override in self._parameter_overrides.items():  # parsed by rcl
            given = override.value
            if isinstance(given, array.array):  # rclpy's numeric arrays
                given = list(given)
            assign(result, name, given, f"--ros-args ({name}:={given!r})")
        for p in declared:
            if result.sources[p.name] != "default":
                result.sources[p.name] = "--ros-args"
            try:
                self._declare_one(p, result.values[p.name])
            except InvalidParameterValueException as exc:
                raise ParameterError(f"parameter {p.name!r}: {exc}") from None
        self._rig_params = result
        self.add_on_set_parameters_callback(self._set_parameters)
        return result

    def _declare_one(self, p: Parameter, value: Any) -> None:
        from rclpy.parameter import Parameter as RclpyParameter

        descriptor = _descriptor(p)
        if not (p.is_list and not value):
            self.declare_parameter(
                p.name, list(value) if p.is_list else value, descriptor, ignore_override=True
            )
            return
        # An empty list does not say its element type: declare the type, then set [] (rclpy
        # refuses a set on a read-only parameter, so read-only is restored afterwards).
        kind = RclpyParameter.Type(descriptor.type)
        read_only, descriptor.read_only = descriptor.read_only, False
        self.declare_parameter(p.name, kind, descriptor, ignore_override=True)
        self.set_parameters([RclpyParameter(p.name, kind, [])])
        self.describe_parameter(p.name).read_only = read_only

    def _set_parameters(self, parameters: list[Any]) -> Any:
        """``ros2 param set``: rclpy has already refused read-only parameters, wrong types and
        values outside the descriptor's range; choices and element ranges are checked here."""
        from rcl_interfaces.msg import SetParametersResult

        checked: list[tuple[str, Any]] = []
        for param in parameters:
            declared = self._rig_params.declared.get(param.name)
            if declared is None:
                continue  # rclpy's own (use_sim_time)
            try:
                given = list(param.value) if isinstance(param.value, array.array) else param.value
                checked.append((param.name, declared.validate(given, "ros2 param set")))
            except ParameterError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        for name, value in checked:
            self._rig_params.values[name] = value
            self._rig_params.sources[name] = "ros2 param set"
            if hasattr(self, "logger"):
                self.logger.info("parameter %s set to %r", name, value)
        return SetParametersResult(successful=True)

    def _log_handler(self) -> logging.Handler:
        handler = _RosoutHandler(self.get_logger())
        handler.setFormatter(logging.Formatter("%(message)s"))
        return handler

    # -- publishers, subscriptions, timers: rclpy's ------------------------------------------
    @overload
    def create_publisher(
        self, msg_type: str, topic: str, qos_profile: str | QosProfile = ..., *,
        depth: int | None = ..., **kwargs: Any,
    ) -> CdrPublisher: ...  # fmt: skip

    @overload
    def create_publisher(
        self, msg_type: type, topic: str, qos_profile: Any = ..., *,
        depth: int | None = ..., **kwargs: Any,
    ) -> Any: ...  # fmt: skip

    def create_publisher(
        self,
        msg_type: Any,
        topic: str,
        qos_profile: Any = "default",
        *,
        depth: int | None = None,
        **kwargs: Any,
    ) -> Any:
        """rclpy's ``create_publisher``; with a ROS type name (``"std_msgs/msg/String"``) and a
        named profile (qos.py) it returns a :class:`CdrPublisher` of the runtime's messages,
        which the start barrier reports and which lingers at ``close``. Given a message
        class, rclpy's own publisher (not reported to the barrier)."""
        if not isinstance(msg_type, str):
            if depth is not None:
                raise TypeError("depth= is for a named QoS profile; give rclpy a QoSProfile")
            return super().create_publisher(msg_type, topic, qos_profile, **kwargs)
        type_name = normalize_type_name(msg_type)
        profile = resolve_qos(qos_profile, depth)
        pub = super().create_publisher(
            message_class(type_name), topic, to_rclpy_qos(profile), **kwargs
        )
        publisher = CdrPublisher(pub, str(self.resolve_topic_name(topic)), type_name, profile)
        self._cdr_publishers.append(publisher)
        return publisher

    @overload
    def create_subscription(
        self, msg_type: str, topic: str, callback: Callable[[Any], None],
        qos_profile: str | QosProfile = ..., *, depth: int | None = ..., raw: bool = ...,
        required: bool = ..., **kwargs: Any,
    ) -> CdrSubscription: ...  # fmt: skip

    @overload
    def create_subscription(
        self, msg_type: type, topic: str, callback: Callable[[Any], None],
        qos_profile: Any = ..., *, depth: int | None = ..., raw: bool = ...,
        required: bool = ..., **kwargs: Any,
    ) -> Any: ...  # fmt: skip

    def create_subscription(
        self,
        msg_type: Any,
        topic: str,
        callback: Callable[[Any], None],
        qos_profile: Any = "default",
        *,
        depth: int | None = None,
        raw: bool = False,
        required: bool = False,
        **kwargs: Any,
    ) -> Any:
        """rclpy's ``create_subscription``; with a ROS type name it delivers the runtime's
        messages decoded from the CDR bytes, or with ``raw=True`` ``(cdr_bytes,
        receive_time_ns)`` (the recorder). ``required=True``: an input without which the
        node cannot work; the start barrier waits until it has a publisher."""
        if not isinstance(msg_type, str):
            if depth is not None or required:
                raise TypeError("depth= and required= are for endpoints by ROS type name")
            return super().create_subscription(
                msg_type, topic, callback, qos_profile, raw=raw, **kwargs
            )
        type_name = normalize_type_name(msg_type)
        profile = resolve_qos(qos_profile, depth)
        resolved = str(self.resolve_topic_name(topic))
        if required:
            self._required_inputs.append(resolved)

        def deliver(data: bytes) -> None:
            self._delivered += 1
            subscription.passed(data)
            if raw:
                callback((data, time.time_ns()))
            else:
                callback(deserialize(data, type_name))

        sub = super().create_subscription(
            message_class(type_name), topic, deliver, to_rclpy_qos(profile), raw=True, **kwargs
        )
        subscription = CdrSubscription(sub, resolved, type_name, profile)
        self._cdr_subscriptions.append(subscription)
        return subscription

    def create_timer(self, timer_period_sec: float, callback: Any, *args: Any, **kw: Any) -> Any:
        if not timer_period_sec > 0:
            raise ValueError(f"timer period must be > 0 s, got {timer_period_sec}")
        return super().create_timer(timer_period_sec, callback, *args, **kw)

    def new_message(self, type_name: str, **fields: Any) -> Any:
        """A runtime message by ROS type name (messages.py)."""
        return new_message(type_name, **fields)

    def now_ns(self) -> int:
        return time.time_ns()

    def topic_types(self) -> dict[str, tuple[str, QosProfile | None]]:
        """Topics with at least one publisher: name -> (type name, QoS offered by the first).
        A topic known only from its readers has no offered QoS yet, and a recorder that
        guessed one could ask for reliable from a best-effort writer and never be matched."""
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

        result: dict[str, tuple[str, QosProfile | None]] = {}
        for name, types in self.get_topic_names_and_types():
            for info in self.get_publishers_info_by_topic(name):
                q = info.qos_profile
                profile = QosProfile(
                    "best_effort" if q.reliability == ReliabilityPolicy.BEST_EFFORT else "reliable",
                    "transient_local"
                    if q.durability == DurabilityPolicy.TRANSIENT_LOCAL
                    else "volatile",
                    0 if q.history == HistoryPolicy.KEEP_ALL else int(q.depth),
                )
                result[name] = (types[0], profile)
                break
        return result

    # -- start barrier (barrier.py) --------------------------------------------------------
    def set_ready(self, ready: bool, reason: str = "") -> None:
        """The node's own readiness (default: ready once constructed); ``reason`` says why not.

        Reported on /graph/ready at the next announcement; a driver waiting for its device
        sets False until the link is up.
        """
        self._ready = bool(ready)
        self._ready_reason = "" if ready else (reason or "not ready")

    def set_records(self, topics: Sequence[str], excluded: Sequence[str] = ()) -> None:
        """This node records ``topics`` (``["*"]``: every topic but ``excluded``): the start
        barrier waits until it has a reader on each of them that a member publishes."""
        self._records = (tuple(topics), tuple(excluded))

    def endpoints(self) -> list[Endpoint]:
        """The runtime's readers and writers with their matched counts (rclpy does not name
        the matched endpoints, so the start barrier compares counts)."""
        fq = self.fq_name
        out = [
            _endpoint(p, "writer", f"{fq}#writer{i}", p.matched_count())
            for i, p in enumerate(self._cdr_publishers)
        ]
        out += [
            _endpoint(s, "reader", f"{fq}#reader{i}", s.matched_count())
            for i, s in enumerate(self._cdr_subscriptions)
        ]
        return out

    def readiness_report(self) -> ReadinessReport:
        return ReadinessReport(
            node=self.fq_name,
            ready=self._ready,
            reason=self._ready_reason,
            endpoints=tuple(self.endpoints()),
            required_inputs=tuple(self._required_inputs),
            records=self._records[0],
            excluded=self._records[1],
        )

    def start_readiness(self, period_s: float = 0.05) -> None:
        """Publish the readiness report now and whenever it changes (run_node calls this
        once the node is constructed). Every ``period_s`` only the matched counts are
        compared (cheap); the report is rebuilt when they or the node's own readiness changed."""
        if self._ready_pub is not None:
            return
        # The anomaly writer exists before the node reports ready, so the barrier sees it matched
        # to the identifier and the recorder: a first anomaly record is never sent into the void.
        _ = self.anomalies
        self._ready_pub = self.create_publisher(GRAPH_READY.type, GRAPH_READY.name, GRAPH_READY.qos)
        self._announce()
        self.create_timer(period_s, self._announce)

    def _announce(self) -> None:
        assert self._ready_pub is not None
        counts = tuple(e.matched_count for e in self.endpoints())
        signature = (self._ready, self._ready_reason, counts)
        if signature == self._last_signature:
            return
        self._last_signature = signature
        text = self.readiness_report().to_json()
        if text != self._last_report:
            self._last_report = text
            self._ready_pub.publish(self.new_message(GRAPH_READY.type, data=text))

    # -- the flow of the streams (flow.py) -------------------------------------------------
    def start_flow_report(self, period_s: float = FLOW_PERIOD_S) -> None:
        """Report on /diagnostics, every ``period_s``, what each stream reader has received and
        each stream writer has sent (flow.py); run_node starts it for every graph node. It is
        also the node's heartbeat: a host whose nodes all fall silent is cut off."""
        if self._flow_pub is not None:
            return
        self._flow_pub = self.create_publisher(DIAGNOSTICS.type, DIAGNOSTICS.name, DIAGNOSTICS.qos)
        self._flow_period_s = period_s
        self.create_timer(period_s, self._report_flow)

    def _report_flow(self) -> None:
        assert self._flow_pub is not None
        self._take_undelivered()
        endpoints = [("writer", p) for p in self._cdr_publishers] + [
            ("reader", s) for s in self._cdr_subscriptions
        ]
        values = flow_values(
            (kind, e.topic, e.count, e.stamp_ns, e.matched_count())
            for kind, e in endpoints
            if e.streams
        )
        name = self.fq_name + FLOW_STATUS_SUFFIX
        self._flow_pub.publish(diagnostic_array(self, name, OK, "", self.fq_name, values))

    def _take_undelivered(self) -> None:
        """Take what a stream reader holds but its executor was not woken for: a reader that
        delivered nothing since the last report is asked directly (rmw take, as the executor
        would). What it holds is delivered in order; the samples held for a period or longer
        are counted (``undelivered``) and logged."""
        now = time.monotonic()
        # A tick late by more than a period: this process did not run (paused, starved), and
        # what arrived meanwhile is still queued for its executor. Judge at the next tick.
        ran = now - self._flow_tick <= 2 * self._flow_period_s
        self._flow_tick = now
        held_since = time.time_ns() - int(self._flow_period_s * 1e9)
        for sub in self._cdr_subscriptions:
            if not sub.streams or sub.count != sub.polled_at or not ran:
                sub.polled_at = sub.count
                continue
            held = 0  # taken samples received a whole period ago or earlier
            handle = sub.handle
            while True:
                try:
                    with handle.handle:
                        info = handle.handle.take_message(handle.msg_type, handle.raw)
                except Exception:  # destroyed while closing: nothing to take
                    break
                if info is None:
                    break
                received = info[1].get("received_timestamp", 0) if len(info) > 1 else 0
                held += 0 < received <= held_since
                handle.callback(info[0])
            sub.polled_at = sub.count
            if held:
                sub.undelivered += held
                self.logger.warning(
                    "reader of %s: %d sample(s) were held undelivered for %g s or more (its "
                    "executor was not woken); taken now, the last stamped %d ns",
                    sub.topic,
                    held,
                    self._flow_period_s,
                    sub.stamp_ns,
                )

    # -- pauses past the participant lease (docs/design.md §3.10) --------------------------
    def start_pause_watch(self) -> None:
        """Notice, on the first timer tick after it runs again, that this process did not run
        for longer than the DDS participant lease (SIGSTOP, a debugger, a suspended laptop, a
        swap storm): its peers have then dropped it, and reliable writers with it what they had
        not delivered. Logged at once, kept in ``paused_s``, passed to ``on_paused`` callbacks;
        the holes it leaves show as each node's own gap or time-discontinuity checks when the
        next sample arrives. run_node starts it for every graph node."""
        if self._last_watch:
            return
        self._last_watch = time.monotonic()
        self.create_timer(PAUSE_WATCH_S, self._watch_pause)

    def on_paused(self, callback: Callable[[float], None]) -> None:
        """``callback(seconds)`` after this process did not run for longer than the lease."""
        self._on_paused.append(callback)

    def _watch_pause(self) -> None:
        now = time.monotonic()
        stopped = now - self._last_watch - PAUSE_WATCH_S
        self._last_watch = now
        lease_s = ros_environment.PARTICIPANT_LEASE_S
        if stopped <= lease_s:
            return
        self.paused_s.append(stopped)
        self.logger.warning(
            "this process did not run for %.1f s, past the DDS participant lease (%g s): its "
            "peers dropped it, and the samples they published meanwhile are lost for it unless "
            "the recorder's bag holds them",
            stopped,
            lease_s,
        )
        for callback in self._on_paused:
            callback(stopped)

    # -- anomalies (anomaly.py) ------------------------------------------------------------
    @property
    def anomalies(self) -> AnomalyLog:
        """This node's anomaly log: records go to /experiment/anomaly and to the log."""
        if self._anomalies is None:
            pub = self.create_publisher(
                EXPERIMENT_ANOMALY.type, EXPERIMENT_ANOMALY.name, EXPERIMENT_ANOMALY.qos
            )

            def send(anomaly: Anomaly) -> None:
                self.logger.warning("anomaly: %s", anomaly.describe())
                pub.publish(self.new_message(EXPERIMENT_ANOMALY.type, data=anomaly.to_json()))

            self._anomalies = AnomalyLog(self.fq_name, send)
        return self._anomalies

    # -- spinning and stopping -------------------------------------------------------------
    def on_shutdown(self, callback: Callable[[], None]) -> None:
        self._on_shutdown.append(callback)

    def request_shutdown(self, exit_code: int | None = None) -> None:
        """Stop spinning: ``spin``'s turn ends after the event whose callback asks (a
        subscription's event delivers every sample it announced). Not from a signal handler:
        see ``_signal_shutdown``."""
        self._signal_shutdown(exit_code)
        self._end_turn()

    def _signal_shutdown(self, exit_code: int | None = None) -> None:
        """``request_shutdown`` for a signal handler: only the flag, which ``spin``'s turn
        check reads within SPIN_TURN_S. Completing the turn's future there could deadlock:
        the handler may interrupt this thread inside that future's own lock."""
        if exit_code is not None:
            self.exit_code = exit_code
        self._shutdown_requested = True

    def _end_turn(self) -> None:
        turn = self._spin_turn
        if turn is not None and not turn.done():
            turn.set_result(None)  # the executor's loop returns once this callback does

    def spin_once(self, timeout_s: float = 0.05) -> int:
        """Wait up to ``timeout_s`` for work and handle one ready item (a sample, a timer, a
        service request); returns how many samples were delivered (0 or 1)."""
        before = self._delivered
        self._rig_executor.spin_once(timeout_sec=max(timeout_s, 0.0))
        return self._delivered - before

    def wake(self) -> None:
        self._rig_executor.wake()

    def spin(self) -> None:
        """Handle callbacks until a shutdown is requested (or the launcher is gone)."""
        next_check = time.monotonic() + 0.5

        def check_turn() -> None:
            # A timer: while samples keep coming, the executor's loop may not return at its
            # timeout, so the flag a signal handler set and the launcher are checked here.
            nonlocal next_check
            if self._launcher_pid is not None and time.monotonic() >= next_check:
                next_check = time.monotonic() + 0.5
                if os.getppid() != self._launcher_pid:
                    self.logger.error(
                        "the launcher (pid %d) is gone: shutting down", self._launcher_pid
                    )
                    self._signal_shutdown(1)
            if self._shutdown_requested:
                self._end_turn()

        # The executor's own loop, in turns: a turn handles every event that comes without
        # returning to Python between them (a Python loop around spin_once costs the stream
        # nodes about a tenth of their CPU). rclpy 7.1's EventsExecutor.spin takes no
        # timeout; spin_until_future_complete does, and the turn ends when its future is
        # completed (request_shutdown, check_turn). A new future per turn: each call adds a
        # done callback to it.
        timer = self.create_timer(SPIN_TURN_S, check_turn)
        try:
            while not self._shutdown_requested and self.context.ok():
                self._spin_turn = Future()
                self._rig_executor.spin_until_future_complete(
                    self._spin_turn, timeout_sec=SPIN_TURN_S
                )
                check_turn()
        finally:
            self._spin_turn = None
            self.destroy_timer(timer)

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Spin until ``predicate()`` is true (returns True) or the timeout passes (False)."""
        deadline = time.monotonic() + timeout_s
        while not predicate():
            remaining = deadline - time.monotonic()
            if remaining <= 0 or self._shutdown_requested:
                return predicate()
            self.spin_once(min(0.05, remaining))
        return True

    def drain(self, until: Callable[[], bool], timeout_s: float) -> bool:
        """Keep delivering messages after a shutdown request until ``until()`` holds and a turn
        delivers nothing more, or the timeout passes (a recorder taking what is still in its
        readers once the writers are gone). True if ``until()`` held."""
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            done = until()
            if remaining <= 0:
                return done
            delivered = self.spin_once(0.0 if done else min(0.05, remaining))
            if done and not delivered:
                return True

    def _linger(self) -> list[str]:
        """Wait (WRITER_LINGER_S in all) until every reliable writer's samples are
        acknowledged; the topics of those whose samples were not."""
        from rclpy.duration import Duration

        deadline = time.monotonic() + WRITER_LINGER_S
        late = []
        for pub in self._cdr_publishers:
            # the flow report is a heartbeat: a cut-off peer need not get the last one
            if pub.profile.reliability != "reliable" or pub is self._flow_pub:
                continue
            remaining = max(deadline - time.monotonic(), 0.0)
            try:
                acked = pub.handle.wait_for_all_acked(Duration(nanoseconds=int(remaining * 1e9)))
            except Exception:  # rclpy's RCLError: the writer cannot say
                acked = False
            if not acked:
                late.append(pub.topic)
        return late

    def close(self) -> None:
        """Run the shutdown callbacks, let the reliable writers linger, then destroy the node
        and shut its context down (once; the context is shut down whatever failed before)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._close_endpoints()
        finally:
            self._rig_context.try_shutdown()

    def _close_endpoints(self) -> None:
        for callback in reversed(self._on_shutdown):
            try:
                callback()
            except Exception:
                self.logger.exception("shutdown callback failed")
        self._on_shutdown.clear()
        if self._anomalies is not None:
            self._anomalies.close_all()  # an episode still open ends at its last stamp
        late = self._linger()
        if late:
            self.logger.warning(
                "closing with samples not acknowledged after %g s on %s: a reader is paused, "
                "starved or gone",
                WRITER_LINGER_S,
                ", ".join(sorted(set(late))),
            )
        try:
            self._rig_executor.remove_node(self)
            self._rig_executor.shutdown()
        finally:
            self.destroy_node()


def _endpoint(entity: CdrEndpoint, kind: str, gid: str, count: int) -> Endpoint:
    return Endpoint(
        topic=entity.topic,
        kind=kind,
        gid=gid,
        reliable=entity.profile.reliability == "reliable",
        transient_local=entity.profile.durability == "transient_local",
        matched_count=count,
    )


def _make_logger(fq_name: str, level: int | str) -> logging.Logger:
    """The node's Python logger (printf-style, as the node modules write); its records go to
    the node's rcl logger: the console in rcutils' format and /rosout."""
    logger = logging.getLogger(f"rig{fq_name.replace('/', '.')}")
    for old in list(logger.handlers):  # a node of the same name made before in this process
        logger.removeHandler(old)
    logger.propagate = False
    logger.setLevel(level)
    return logger


def format_parameter_help(name: str, parameters: Sequence[Parameter], description: str) -> str:
    lines = [
        f"usage: {name} [--ros-args [-r __node:=NAME] [-r __ns:=NS] [-r FROM:=TO]",
        "                 [--params-file FILE.yaml] [-p NAME:=VALUE] [--log-level LEVEL]]",
        "",
        (description or "").strip(),
        "",
        "parameters (set in a ROS 2 parameter file or with -p NAME:=VALUE):",
    ]
    for p in parameters:
        lines.append(f"  {p.name} = {p.default!r}  ({p.describe_range()})")
        lines.append(f"      {p.description}")
    return "\n".join(lines)


def run_node(
    factory: Callable[[Node], Any],
    name: str,
    parameters: Sequence[Parameter],
    argv: Sequence[str] | None = None,
    description: str = "",
) -> int:
    """Parse arguments, validate parameters, build the node, spin until SIGINT/SIGTERM.

    Returns the process exit code: 0 on a clean stop, 2 on a configuration error (message on
    stderr naming the parameter), the node's ``exit_code`` otherwise.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if any(a in ("-h", "--help") for a in args):
        print(format_parameter_help(name, parameters, description))
        return 0
    try:
        node = Node(name, parameters, args)
    except (ParameterError, ArgumentError) as exc:
        print(f"[FATAL] [{name}]: {exc}", file=sys.stderr)
        return EXIT_CONFIG_ERROR

    def _stop(name: str) -> None:
        if len(signalled.received) > 1:  # a terminal's Ctrl-C and ros2 launch's SIGINT: one
            return
        node.logger.info("received %s, shutting down", name)
        node._signal_shutdown()

    # Stopped by a signal, the process is on its way out: a second SIGINT (Ctrl-C in the
    # terminal's process group, then ros2 launch's own) must not kill it after the stop.
    signalled = StopSignals(signal.SIGINT, signal.SIGTERM, on_signal=_stop, ignore_after=True)
    signalled.install()
    try:
        try:
            instance = factory(node)
        except (ParameterError, ValueError) as exc:
            print(f"[FATAL] [{node.fq_name}]: {exc}", file=sys.stderr)
            return EXIT_CONFIG_ERROR
        close = getattr(instance, "close", None)
        if callable(close):
            node.on_shutdown(close)
        node.start_flow_report()
        node.start_readiness()
        node.start_pause_watch()
        node.logger.info("running on %s", node.middleware_description)
        profile_dir = os.environ.get("RIG_PROFILE_DIR")
        if profile_dir:  # cProfile of the spin loop, for `python -m pstats DIR/<node>.prof`
            import cProfile

            with cProfile.Profile(time.process_time) as profiler:  # CPU, not waiting
                node.spin()
            Path(profile_dir).mkdir(parents=True, exist_ok=True)
            profiler.dump_stats(Path(profile_dir) / f"{node.name}.prof")
        else:
            node.spin()
    except Exception:
        node.logger.exception("node failed")
        node.exit_code = node.exit_code or 1
    finally:
        node.close()
        signalled.restore()
    return node.exit_code

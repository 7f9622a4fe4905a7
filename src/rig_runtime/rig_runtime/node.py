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

import logging
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any, overload

from . import ros_environment
from .anomaly import Anomaly, AnomalyLog
from .barrier import Endpoint, ReadinessReport
from .endpoints import CdrPublisher, CdrSubscription, message_class, offered_topics
from .flow import FLOW_PERIOD_S
from .flow_report import FlowReport
from .interface import EXPERIMENT_ANOMALY
from .messages import deserialize, new_message, normalize_type_name
from .node_logging import RosoutHandler, make_logger
from .node_parameters import declare_parameters
from .params import Parameter
from .participant_profile import participant_environment
from .pause_watch import PAUSE_WATCH_S, PauseWatch
from .qos import QosProfile, resolve_qos, to_rclpy_qos
from .readiness import Readiness
from .ros_environment import LAUNCHER_PID_ENV, ArgumentError
from .spinning import Spinner

try:
    import rclpy
    import rclpy.node
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
except ImportError as _exc:  # the one line every graph command prints (ros_environment)
    raise ImportError(ros_environment.NO_RCLPY) from _exc

__all__ = ["EXECUTOR_ENV", "PAUSE_WATCH_S", "CdrPublisher", "CdrSubscription", "Node"]

EXECUTOR_ENV = "RIG_RCLPY_EXECUTOR"


def _events_executor(context: Any) -> Any:
    """rclpy.experimental.EventsExecutor without its ``faulthandler.enable()``, which fails
    where stderr has no file descriptor (pytest's capture) and is the process's business. The
    public wrapper has no option to skip it, so the executor comes from rclpy's implementation
    module, which that wrapper itself constructs it from."""
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
            self.params = declare_parameters(self, parameters, self._parameter_overrides)
        except Exception:
            self.destroy_node()
            context.try_shutdown()
            raise
        self.logger = make_logger(self.fq_name, int(self.get_logger().get_effective_level()))
        self.logger.addHandler(self._log_handler())
        executor = (
            _events_executor(context)
            if choice == "events"
            else SingleThreadedExecutor(context=context)
        )
        executor.add_node(self)
        self.cdr_publishers: list[CdrPublisher] = []
        self.cdr_subscriptions: list[CdrSubscription] = []
        self.exit_code = 0
        # Only a direct child of that launcher watches it (not a process that inherited the
        # variable further down).
        launcher = os.environ.get(LAUNCHER_PID_ENV, "")
        watched = launcher.isdigit() and int(launcher) == os.getppid()
        # Each job in its own module: spinning.py, readiness.py (the start barrier),
        # flow_report.py, pause_watch.py; anomaly.py's log on first use.
        self.spinner = Spinner(self, executor, context, int(launcher) if watched else None)
        self.readiness = Readiness(self)
        self.flow_report = FlowReport(self)
        self.pause_watch = PauseWatch(self)
        self._anomalies: AnomalyLog | None = None

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

    def _log_handler(self) -> logging.Handler:
        handler = RosoutHandler(self.get_logger())
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
        self.cdr_publishers.append(publisher)
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
            self.readiness.required_inputs.append(resolved)

        def deliver(data: bytes) -> None:
            self.spinner.delivered += 1
            subscription.passed(data)
            if raw:
                callback((data, time.time_ns()))
            else:
                callback(deserialize(data, type_name))

        sub = super().create_subscription(
            message_class(type_name), topic, deliver, to_rclpy_qos(profile), raw=True, **kwargs
        )
        subscription = CdrSubscription(sub, resolved, type_name, profile)
        self.cdr_subscriptions.append(subscription)
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
        """endpoints.offered_topics of this node's graph."""
        return offered_topics(self)

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

    def close_anomalies(self) -> None:
        if self._anomalies is not None:
            self._anomalies.close_all()

    # -- the start barrier (readiness.py) ---------------------------------------------------
    def set_ready(self, ready: bool, reason: str = "") -> None:
        """The node's own readiness (default: ready once constructed); ``reason`` says why not,
        on /graph/ready at the next announcement (a driver sets False until its link is up)."""
        self.readiness.set_ready(ready, reason)

    def set_records(self, topics: Sequence[str], excluded: Sequence[str] = ()) -> None:
        """This node records ``topics`` (``["*"]``: every topic but ``excluded``): the start
        barrier waits until it has a reader on each of them that a member publishes."""
        self.readiness.set_records(topics, excluded)

    def endpoints(self) -> list[Endpoint]:
        return self.readiness.endpoints()

    def readiness_report(self) -> ReadinessReport:
        return self.readiness.report()

    def start_readiness(self, period_s: float = 0.05) -> None:
        self.readiness.start(period_s)

    # -- the flow report (flow_report.py), the pause watch (pause_watch.py) -----------------
    def start_flow_report(self, period_s: float = FLOW_PERIOD_S) -> None:
        self.flow_report.start(period_s)

    def start_pause_watch(self) -> None:
        self.pause_watch.start()

    def on_paused(self, callback: Callable[[float], None]) -> None:
        """``callback(seconds)`` after this process did not run for longer than the lease."""
        self.pause_watch.callbacks.append(callback)

    @property
    def paused_s(self) -> list[float]:
        return self.pause_watch.paused_s

    # -- spinning and stopping (spinning.py) ------------------------------------------------
    def on_shutdown(self, callback: Callable[[], None]) -> None:
        self.spinner.callbacks.append(callback)

    def request_shutdown(self, exit_code: int | None = None) -> None:
        self.spinner.request_shutdown(exit_code)

    def spin_once(self, timeout_s: float = 0.05) -> int:
        """Wait up to ``timeout_s`` for work and handle one ready item (a sample, a timer, a
        service request); returns how many samples were delivered (0 or 1)."""
        return self.spinner.spin_once(timeout_s)

    def wake(self) -> None:
        self.spinner.executor.wake()

    def spin(self) -> None:
        """Handle callbacks until a shutdown is requested (or the launcher is gone)."""
        self.spinner.spin()

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Spin until ``predicate()`` is true (returns True) or the timeout passes (False)."""
        return self.spinner.spin_until(predicate, timeout_s)

    def drain(self, until: Callable[[], bool], timeout_s: float) -> bool:
        """Keep delivering after a shutdown request until ``until()`` holds and a turn delivers
        nothing more, or the timeout passes (a recorder taking what its readers still hold once
        the writers are gone). True if ``until()`` held."""
        return self.spinner.drain(until, timeout_s)

    def close(self) -> None:
        self.spinner.close()

"""The base class of every node of this project: an rclpy node with the rig's contract
(docs/design.md §3).

:class:`Node` *is* an ``rclpy.node.Node``. What it adds is what ROS does not provide and
every node of the rig needs: parameters declared once from a list of
:class:`~rig_runtime.params.Parameter` (each an rclpy parameter with its
``ParameterDescriptor``), the start barrier's readiness report, the anomaly log, the pause
watch, and every endpoint counted for the flow report and the barrier. A node module reads::

    PARAMETERS = [Parameter("fs", 200.0, "sample rate [Hz]", min=1.0)]

    class GeneratorNode(Node):
        NODE_NAME = "generator"
        PARAMETERS = PARAMETERS

        def __init__(self, argv: Sequence[str] | None = None) -> None:
            super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
            topic = EXPERIMENT_SEGMENT
            self.segment_pub = self.create_publisher(SegmentEvent, topic.name, topic_qos(topic))
            self.create_timer(1.0 / self.get_parameter("fs").value, self.tick)

    def main(argv=None) -> int:
        return run_node(GeneratorNode, argv, description=__doc__)

``create_publisher`` and ``create_subscription`` are rclpy's. Given a ROS type *name* (the
interface contract's ``Topic.type``) instead of a message class, they send and take the
serialized CDR of the runtime's messages (rosbags dataclasses with numpy sequences,
messages.py) through rclpy's serialized publish and ``raw=True`` subscriptions: the sample
streams, where rclpy's message conversion costs the most (bench/transport.py measures it).
"""

import logging
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, overload

from . import ros_environment
from .anomaly import Anomaly, AnomalyLog
from .barrier import Endpoint, ReadinessReport
from .endpoints import (
    CdrPublisher,
    CdrSubscription,
    MessagePublisher,
    MessageSubscription,
    message_class,
    offered_topics,
    type_name_of,
)
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
from .spinning import Spinner, events_executor, new_context

try:
    import rclpy.node
    from rclpy.executors import SingleThreadedExecutor
except ImportError as _exc:  # the one line every graph command prints (ros_environment)
    raise ImportError(ros_environment.NO_RCLPY) from _exc

__all__ = ["EXECUTOR_ENV", "PAUSE_WATCH_S", "CdrPublisher", "CdrSubscription", "Node"]

EXECUTOR_ENV = "RIG_RCLPY_EXECUTOR"


class Node(rclpy.node.Node):
    """An rclpy node with validated parameters, the start barrier, anomalies and a pause watch.

    Each instance owns its ``rclpy.Context`` and executor (rclpy's ``EventsExecutor``;
    ``RIG_RCLPY_EXECUTOR=single`` for its ``SingleThreadedExecutor``). A node module's
    subclass names itself and its parameter declarations for ``run_node``.
    """

    NODE_NAME: ClassVar[str] = ""
    PARAMETERS: ClassVar[Sequence[Parameter]] = ()
    # False while rclpy's own __init__ makes its endpoints (/parameter_events): those are
    # rclpy's, not counted or reported.
    _counting = False

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
            context = new_context(domain)
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
            # rcl's parsed overrides: rclpy keeps them in _parameter_overrides and has no
            # public getter for them (node_parameters.py).
            self.params = declare_parameters(self, parameters, self._parameter_overrides)
        except Exception:
            self.destroy_node()
            context.try_shutdown()
            raise
        self.logger = make_logger(self.fq_name, int(self.get_logger().get_effective_level()))
        self.logger.addHandler(self._log_handler())
        executor = (
            events_executor(context)
            if choice == "events"
            else SingleThreadedExecutor(context=context)
        )
        executor.add_node(self)
        self.rig_publishers: list[CdrPublisher] = []
        self.rig_subscriptions: list[CdrSubscription] = []
        self._counting = True
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

    def _log_handler(self) -> logging.Handler:
        handler = RosoutHandler(self.get_logger())
        handler.setFormatter(logging.Formatter("%(message)s"))
        return handler

    # -- publishers, subscriptions, timers: rclpy's ------------------------------------------
    @overload  # type: ignore[override]
    def create_publisher(
        self, msg_type: str, topic: str, qos_profile: Any = ..., *,
        depth: int | None = ..., **kwargs: Any,
    ) -> CdrPublisher: ...  # fmt: skip

    @overload
    def create_publisher(
        self, msg_type: type, topic: str, qos_profile: Any = ..., *,
        depth: int | None = ..., **kwargs: Any,
    ) -> MessagePublisher: ...  # fmt: skip

    # Both return the runtime's counted endpoint (endpoints.py), which wraps rclpy's Publisher
    # or Subscription (``handle``) instead of being one: hence the override of the return type.
    def create_publisher(
        self,
        msg_type: Any,
        topic: str,
        qos_profile: Any = "default",
        *,
        depth: int | None = None,
        **kwargs: Any,
    ) -> Any:
        """rclpy's ``create_publisher``, counted for the flow report and the start barrier, and
        lingering at ``close`` until its samples are acknowledged. ``msg_type``: an rclpy
        message class, or a ROS type name for the serialized path (``publish`` takes the
        runtime's messages, messages.py, and sends their CDR: the sample streams,
        bench/transport.py). ``qos_profile``: an rclpy ``QoSProfile``, a name (qos.py), a depth."""
        if not self._counting:
            return super().create_publisher(msg_type, topic, qos_profile, **kwargs)
        profile = resolve_qos(qos_profile, depth)
        if isinstance(msg_type, str):
            type_name = normalize_type_name(msg_type)
            pub = super().create_publisher(
                message_class(type_name), topic, to_rclpy_qos(profile), **kwargs
            )
            entity: CdrPublisher = CdrPublisher(
                pub, str(self.resolve_topic_name(topic)), type_name, profile
            )
        else:
            pub = super().create_publisher(msg_type, topic, to_rclpy_qos(profile), **kwargs)
            entity = MessagePublisher(
                pub, str(self.resolve_topic_name(topic)), type_name_of(msg_type), profile
            )
        self.rig_publishers.append(entity)
        return entity

    @overload  # type: ignore[override]
    def create_subscription(
        self, msg_type: str, topic: str, callback: Callable[[Any], None],
        qos_profile: Any = ..., *, depth: int | None = ..., raw: bool = ...,
        required: bool = ..., **kwargs: Any,
    ) -> CdrSubscription: ...  # fmt: skip

    @overload
    def create_subscription(
        self, msg_type: type, topic: str, callback: Callable[[Any], None],
        qos_profile: Any = ..., *, depth: int | None = ..., raw: bool = ...,
        required: bool = ..., **kwargs: Any,
    ) -> MessageSubscription: ...  # fmt: skip

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
        """rclpy's ``create_subscription``, counted and reported as ``create_publisher``.

        With an rclpy message class the callback takes rclpy's messages; with a ROS type name,
        the runtime's messages decoded from the CDR bytes, or with ``raw=True``
        ``(cdr_bytes, receive_time_ns)`` (the recorder). ``required=True``: an input without
        which the node cannot work; the start barrier waits until it has a publisher."""
        if not self._counting:
            return super().create_subscription(msg_type, topic, callback, qos_profile, **kwargs)
        profile = resolve_qos(qos_profile, depth)
        resolved = str(self.resolve_topic_name(topic))
        if required:
            self.readiness.required_inputs.append(resolved)
        if not isinstance(msg_type, str):
            if raw:
                raise TypeError("raw=True is for endpoints by ROS type name")

            def take(msg: Any) -> None:
                self.spinner.delivered += 1
                typed.took(msg)
                callback(msg)

            sub = super().create_subscription(
                msg_type, topic, take, to_rclpy_qos(profile), **kwargs
            )
            typed = MessageSubscription(sub, resolved, type_name_of(msg_type), profile)
            self.rig_subscriptions.append(typed)
            return typed
        type_name = normalize_type_name(msg_type)

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
        self.rig_subscriptions.append(subscription)
        return subscription

    # rclpy's destroy_*, for a counted endpoint too (then no longer counted or reported).
    def destroy_publisher(self, publisher: Any) -> bool:
        if isinstance(publisher, CdrPublisher):
            self.rig_publishers.remove(publisher)
            publisher = publisher.handle
        return bool(super().destroy_publisher(publisher))

    def destroy_subscription(self, subscription: Any) -> bool:
        if isinstance(subscription, CdrSubscription):
            self.rig_subscriptions.remove(subscription)
            subscription = subscription.handle
        return bool(super().destroy_subscription(subscription))

    def create_timer(self, timer_period_sec: float, callback: Any, *args: Any, **kw: Any) -> Any:
        if not timer_period_sec > 0:
            raise ValueError(f"timer period must be > 0 s, got {timer_period_sec}")
        return super().create_timer(timer_period_sec, callback, *args, **kw)

    def parameter_values(self) -> dict[str, Any]:
        """The current value (rclpy's ``get_parameter``) of each parameter this node declared."""
        return {name: self.get_parameter(name).value for name in self.params.declared}

    def new_message(self, type_name: str, **fields: Any) -> Any:
        """A runtime message by ROS type name (messages.py)."""
        return new_message(type_name, **fields)

    def topic_types(self) -> dict[str, tuple[str, QosProfile | None]]:
        """endpoints.offered_topics of this node's graph."""
        return offered_topics(self)

    # -- anomalies (anomaly.py) ------------------------------------------------------------
    @property
    def anomalies(self) -> AnomalyLog:
        """This node's anomaly log: records go to /experiment/anomaly and to the log."""
        if self._anomalies is None:
            from aero_rig_interfaces.msg import Anomaly as AnomalyMsg

            from .qos_profiles import topic_qos

            topic, qos = EXPERIMENT_ANOMALY.name, topic_qos(EXPERIMENT_ANOMALY)
            pub = self.create_publisher(AnomalyMsg, topic, qos)

            def send(anomaly: Anomaly) -> None:
                self.logger.warning("anomaly: %s", anomaly.describe())
                pub.publish(AnomalyMsg(**anomaly.to_fields()))

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

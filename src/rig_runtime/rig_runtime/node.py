"""The node API every node of this project is written against (docs/design.md §3).

A node module declares its parameters and a class that takes a :class:`Node`::

    PARAMETERS = [Parameter("fs", 200.0, "sample rate [Hz]", min=1.0)]

    class Generator:
        def __init__(self, node: Node) -> None:
            self.pub = node.create_publisher("sensor_msgs/msg/JointState", "/pitch/command")
            node.create_timer(1.0 / node.params["fs"], self.tick)

    def main(argv=None) -> int:
        return run_node(Generator, "generator", PARAMETERS, argv, description=__doc__)

The backend is chosen once per process: rclpy when it imports (the PyPI wheels or a sourced
ROS 2 Jazzy), the Cyclone DDS backend otherwise
(rclpy_backend.py, dds_backend.py); ``RIG_RUNTIME_BACKEND=dds|rclpy`` overrides. Both speak
ROS 2 on the wire.
"""

import logging
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

from . import ros_environment
from .anomaly import Anomaly, AnomalyLog
from .barrier import Endpoint, ReadinessReport
from .interface import EXPERIMENT_ANOMALY, GRAPH_READY
from .names import ArgumentError, RosArgs, normalize_namespace, parse_ros_args, resolve_name
from .params import Parameter, ParameterError, resolve_parameters
from .qos import QosProfile, resolve_qos

BACKEND_ENV = ros_environment.BACKEND_ENV
# Set by the launcher for its nodes: a node whose parent process is no longer the launcher
# (it was killed, even with SIGKILL) stops instead of running on unattended.
LAUNCHER_PID_ENV = "RIG_LAUNCHER_PID"
PAUSE_WATCH_S = 1.0  # the period of every node's pause watch (start_pause_watch)

# Exit codes: 0 ok, 2 configuration error (bad parameters/arguments), 1 runtime failure.
EXIT_CONFIG_ERROR = 2


class Publisher(Protocol):
    topic: str
    type_name: str

    def publish(self, msg: Any) -> None: ...

    def subscription_count(self) -> int: ...


class Subscription(Protocol):
    topic: str
    type_name: str

    def publisher_count(self) -> int: ...


class Timer(Protocol):
    def cancel(self) -> None: ...


class Backend(Protocol):
    """What a middleware must provide; see dds_backend.py and rclpy_backend.py."""

    name: str

    def create_publisher(self, topic: str, type_name: str, qos: QosProfile) -> Publisher: ...

    def create_subscription(
        self,
        topic: str,
        type_name: str,
        callback: Callable[[Any], None],
        qos: QosProfile,
        raw: bool = False,
    ) -> Subscription: ...

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> Timer: ...

    def new_message(self, type_name: str, **fields: Any) -> Any: ...

    def spin_once(self, timeout_s: float) -> int | None: ...

    def now_ns(self) -> int: ...

    def endpoints(self) -> list[Endpoint]: ...

    def match_signature(self) -> tuple[object, ...]: ...

    def topic_types(self) -> dict[str, tuple[str, QosProfile | None]]: ...

    def close(self) -> None: ...


def select_backend_name() -> str:
    """``rclpy`` where it imports, else ``dds``; ``RIG_RUNTIME_BACKEND`` chooses explicitly
    (ros_environment.backend_name; a clear error if the choice cannot be honoured)."""
    return ros_environment.backend_name()


class Node:
    """A named node with validated parameters, publishers, subscriptions and timers."""

    def __init__(
        self,
        name: str,
        parameters: Sequence[Parameter] = (),
        argv: Sequence[str] | None = None,
        namespace: str = "/",
        backend: str | None = None,
    ) -> None:
        args = list(sys.argv[1:] if argv is None else argv)
        backend_name = backend or ros_environment.check()
        if backend_name == "rclpy":
            # rcl parses --ros-args (names, remaps, -p, --params-file, --log-level) and holds
            # the parameters, with descriptors, for `ros2 param` (rclpy_backend.py).
            from .rclpy_backend import RclpyBackend

            rclpy_backend = RclpyBackend(name, namespace, args)
            try:
                self.ros_args = RosArgs()
                self.name = rclpy_backend.node_name
                self.namespace = rclpy_backend.namespace
                self.fq_name = _fq_name(self.namespace, self.name)
                self.params = rclpy_backend.declare_parameters(parameters)
            except Exception:
                rclpy_backend.close()
                raise
            self.logger = _make_logger(
                self.fq_name, rclpy_backend.log_level, rclpy_backend.log_handler()
            )
            rclpy_backend.on_parameter_change(
                lambda n, v: self.logger.info("parameter %s set to %r", n, v)
            )
            self._backend: Backend = rclpy_backend
        else:
            ros_args = parse_ros_args(args)
            self.ros_args = ros_args
            self.name = ros_args.node_name or name
            self.namespace = normalize_namespace(ros_args.namespace or namespace)
            self.fq_name = _fq_name(self.namespace, self.name)
            # Parameters are validated before any middleware entity exists (design.md §8).
            self.params = resolve_parameters(
                parameters, self.fq_name, ros_args.param_files, ros_args.overrides
            )
            level = ros_args.log_level or os.environ.get("RIG_LOG_LEVEL", "INFO")
            self.logger = _make_logger(self.fq_name, logging.getLevelName(level.upper()))
            from .dds_backend import DdsBackend

            self._backend = DdsBackend(self.name, self.namespace)
        self.exit_code = 0
        self._shutdown_requested = False
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
        self._ready_pub: Publisher | None = None
        self._last_report = ""
        self._last_signature: object = None
        self._anomalies: AnomalyLog | None = None
        # Pauses past the DDS lease (start_pause_watch): how long this process did not run.
        self.paused_s: list[float] = []
        self._on_paused: list[Callable[[float], None]] = []
        self._last_watch = 0.0

    @property
    def backend_name(self) -> str:
        return self._backend.name

    @property
    def backend_description(self) -> str:
        """``rclpy (rmw_fastrtps_cpp)`` or ``dds (Cyclone DDS backend)``, for the log; with
        rmw_fastrtps's publication mode when it was chosen (``rclpy (rmw_fastrtps_cpp,
        ASYNCHRONOUS publication)``)."""
        if self._backend.name == "rclpy":
            from rclpy.utilities import get_rmw_implementation_identifier

            rmw = get_rmw_implementation_identifier()
            mode = os.environ.get(ros_environment.PUBLICATION_MODE_ENV)
            if mode and rmw.startswith("rmw_fastrtps"):
                return f"rclpy ({rmw}, {mode} publication)"
            return f"rclpy ({rmw})"
        return "dds (Cyclone DDS backend)"

    def resolve_topic(self, topic: str) -> str:
        """The fully qualified topic name after expansion and remapping (rcl's on rclpy)."""
        resolve = getattr(self._backend, "resolve_topic", None)
        if resolve is not None:
            return str(resolve(topic))
        return resolve_name(topic, self.namespace, self.name, self.ros_args.remaps)

    def create_publisher(
        self,
        type_name: str,
        topic: str,
        qos: str | QosProfile = "default",
        depth: int | None = None,
    ) -> Publisher:
        return self._backend.create_publisher(
            self.resolve_topic(topic), type_name, resolve_qos(qos, depth)
        )

    def create_subscription(
        self,
        type_name: str,
        topic: str,
        callback: Callable[[Any], None],
        qos: str | QosProfile = "default",
        depth: int | None = None,
        raw: bool = False,
        required: bool = False,
    ) -> Subscription:
        """Deliver messages of ``topic`` to ``callback`` on the spin thread.

        ``raw=True`` delivers ``(cdr_bytes, receive_time_ns)`` instead of a message (recorder).
        ``required=True``: an input without which the node cannot work; the start barrier
        waits until it has a publisher.
        """
        resolved = self.resolve_topic(topic)
        if required:
            self._required_inputs.append(resolved)
        return self._backend.create_subscription(
            resolved, type_name, callback, resolve_qos(qos, depth), raw
        )

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> Timer:
        if not period_s > 0:
            raise ValueError(f"timer period must be > 0 s, got {period_s}")
        return self._backend.create_timer(period_s, callback)

    def new_message(self, type_name: str, **fields: Any) -> Any:
        """A message by ROS type name, native to the backend (same attributes on both)."""
        return self._backend.new_message(type_name, **fields)

    def now_ns(self) -> int:
        return self._backend.now_ns()

    def topic_types(self) -> dict[str, tuple[str, QosProfile | None]]:
        """Topics seen in the graph: name -> (type name, offered QoS if known)."""
        return self._backend.topic_types()

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

    def readiness_report(self) -> ReadinessReport:
        return ReadinessReport(
            node=self.fq_name,
            ready=self._ready,
            reason=self._ready_reason,
            endpoints=tuple(self._backend.endpoints()),
            required_inputs=tuple(self._required_inputs),
            records=self._records[0],
            excluded=self._records[1],
        )

    def start_readiness(self, period_s: float = 0.05) -> None:
        """Publish the readiness report now and whenever it changes (run_node calls this
        once the node is constructed). Every ``period_s`` only the matched endpoints'
        handles are compared (cheap); the report is rebuilt when they or the node's own
        readiness changed."""
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
        signature = (self._ready, self._ready_reason, self._backend.match_signature())
        if signature == self._last_signature:
            return
        self._last_signature = signature
        text = self.readiness_report().to_json()
        if text != self._last_report:
            self._last_report = text
            self._ready_pub.publish(self.new_message(GRAPH_READY.type, data=text))

    # -- pauses past the DDS lease (docs/design.md §3.10) ---------------------------------
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
        lease_s = ros_environment.participant_lease_s(self.backend_name)
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

    def on_shutdown(self, callback: Callable[[], None]) -> None:
        self._on_shutdown.append(callback)

    def request_shutdown(self, exit_code: int | None = None) -> None:
        if exit_code is not None:
            self.exit_code = exit_code
        self._shutdown_requested = True

    @property
    def shutdown_requested(self) -> bool:
        return self._shutdown_requested

    def spin_once(self, timeout_s: float = 0.05) -> None:
        self._backend.spin_once(timeout_s)

    def spin(self) -> None:
        """Handle callbacks until a shutdown is requested (or the launcher is gone)."""
        next_check = time.monotonic() + 0.5

        def keep_going() -> bool:
            nonlocal next_check
            if self._launcher_pid is not None and time.monotonic() >= next_check:
                next_check = time.monotonic() + 0.5
                if os.getppid() != self._launcher_pid:
                    self.logger.error(
                        "the launcher (pid %d) is gone: shutting down", self._launcher_pid
                    )
                    self.request_shutdown(1)
            return not self._shutdown_requested

        # One event per turn on both backends. rclpy's EventsExecutor.spin_until_future_complete
        # (its own loop) never returns without a timeout in rclpy 7.1.6, and was not faster in
        # the one measurement taken (on a machine disturbed by another process).
        while keep_going():
            self._backend.spin_once(0.05)

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Spin until ``predicate()`` is true (returns True) or the timeout passes (False)."""
        deadline = time.monotonic() + timeout_s
        while not predicate():
            remaining = deadline - time.monotonic()
            if remaining <= 0 or self._shutdown_requested:
                return predicate()
            self._backend.spin_once(min(0.05, remaining))
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
            delivered = self._backend.spin_once(0.0 if done else min(0.05, remaining))
            if done and not delivered:
                return True

    def close(self) -> None:
        for callback in reversed(self._on_shutdown):
            try:
                callback()
            except Exception:
                self.logger.exception("shutdown callback failed")
        self._on_shutdown.clear()
        if self._anomalies is not None:
            self._anomalies.close_all()  # an episode still open ends at its last stamp
        self._backend.close()


def _fq_name(namespace: str, name: str) -> str:
    prefix = "" if namespace == "/" else namespace
    return f"{prefix}/{name}"


def _make_logger(
    fq_name: str, level: int | str, handler: logging.Handler | None = None
) -> logging.Logger:
    """The node's Python logger. On rclpy ``handler`` hands each record to the node's rcl
    logger (console and /rosout); otherwise records go to stderr in rcutils' console format."""
    logger = logging.getLogger(f"rig{fq_name.replace('/', '.')}")
    for old in list(logger.handlers):  # a node of the same name made before in this process
        logger.removeHandler(old)
    if handler is None:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(
            logging.Formatter(
                f"[%(levelname)s] [%(created).3f] [{fq_name.lstrip('/')}]: %(message)s"
            )
        )
    logger.addHandler(handler)
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

    signalled: list[int] = []

    def _stop(signum: int, _frame: Any) -> None:
        if signalled:  # a terminal's Ctrl-C and ros2 launch both send SIGINT: one stop
            return
        signalled.append(signum)
        node.logger.info("received %s, shutting down", signal.Signals(signum).name)
        node.request_shutdown()

    previous = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            instance = factory(node)
        except (ParameterError, ValueError) as exc:
            print(f"[FATAL] [{node.fq_name}]: {exc}", file=sys.stderr)
            return EXIT_CONFIG_ERROR
        close = getattr(instance, "close", None)
        if callable(close):
            node.on_shutdown(close)
        node.start_readiness()
        node.start_pause_watch()
        node.logger.info("running on %s", node.backend_description)
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
        for sig, handler in previous.items():
            # Stopped by a signal, the process is on its way out: a second SIGINT (Ctrl-C in
            # the terminal's process group, then ros2 launch's own) must not kill it now.
            signal.signal(sig, signal.SIG_IGN if signalled else handler)
    return node.exit_code

"""A node process's main: ``--help`` from the parameter declarations, then the node built,
spun until SIGINT/SIGTERM and closed in order (``run_node``)."""

import os
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from . import ros_environment
from .node import Node
from .params import Parameter, ParameterError
from .ros_environment import ArgumentError
from .signals import StopSignals

__all__ = ["EXIT_CONFIG_ERROR", "format_parameter_help", "run_node"]

# Exit codes: 0 ok, 2 configuration error (bad parameters/arguments), 1 runtime failure.
EXIT_CONFIG_ERROR = 2


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


def middleware_description() -> str:
    """``rclpy (rmw_fastrtps_cpp)``, with rmw_fastrtps's publication mode when it was
    chosen (``rclpy (rmw_fastrtps_cpp, ASYNCHRONOUS publication)``), for the log."""
    from rclpy.utilities import get_rmw_implementation_identifier

    rmw = get_rmw_implementation_identifier()
    mode = os.environ.get(ros_environment.PUBLICATION_MODE_ENV)
    if mode and rmw.startswith("rmw_fastrtps"):
        return f"rclpy ({rmw}, {mode} publication)"
    return f"rclpy ({rmw})"


def run_node(
    node_class: "type[Node]",
    argv: Sequence[str] | None = None,
    description: str = "",
) -> int:
    """Parse arguments, build the node (``node_class(argv)``, a :class:`Node` subclass with
    ``NODE_NAME`` and ``PARAMETERS``), spin until SIGINT/SIGTERM, close it.

    Returns the process exit code: 0 on a clean stop, 2 on a configuration error (message on
    stderr naming the parameter), the node's ``exit_code`` otherwise.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    name = node_class.NODE_NAME
    if any(a in ("-h", "--help") for a in args):
        print(format_parameter_help(name, node_class.PARAMETERS, description))
        return 0

    def _stop(signal_name: str) -> None:
        if len(signalled.received) > 1:  # a terminal's Ctrl-C and ros2 launch's SIGINT: one
            return
        if built:  # during construction the flag alone; read once the node is built
            node.get_logger().info(f"received {signal_name}, shutting down")
            node.spinner.signal_shutdown()

    # Stopped by a signal, the process is on its way out: a second SIGINT (Ctrl-C in the
    # terminal's process group, then ros2 launch's own) must not kill it after the stop.
    built = False
    signalled = StopSignals(signal.SIGINT, signal.SIGTERM, on_signal=_stop, ignore_after=True)
    signalled.install()
    # Allocated first and initialised after, so that a subclass whose own __init__ refuses its
    # settings once the rclpy node exists can still be named by it and closed.
    node = node_class.__new__(node_class)
    try:
        try:
            node.__init__(args)  # type: ignore[misc]
        except (ParameterError, ArgumentError, ValueError) as exc:
            started = hasattr(node, "spinner")  # Node.__init__ done: the subclass refused
            print(f"[FATAL] [{node.fq_name if started else name}]: {exc}", file=sys.stderr)
            return EXIT_CONFIG_ERROR
        built = True
        if signalled:
            node.spinner.signal_shutdown()
        node.start_flow_report()
        node.start_readiness()
        node.start_pause_watch()
        node.get_logger().info(f"running on {middleware_description()}")
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
        if not hasattr(node, "spinner"):  # rclpy's node was never made: nothing to close
            raise
        node.logger.exception("node failed")
        node.exit_code = node.exit_code or 1
    finally:
        if hasattr(node, "spinner"):
            node.close()
        signalled.restore()
    return node.exit_code

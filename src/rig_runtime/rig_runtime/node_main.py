"""A node process's main: ``--help`` from the parameter declarations, then the node built,
spun until SIGINT/SIGTERM and closed in order (``run_node``)."""

import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

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
        node.spinner.signal_shutdown()

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

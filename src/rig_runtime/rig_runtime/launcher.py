"""Graph launcher: every node of a graph description as its own OS process.

``rig-launch GRAPH.yaml [--host NAME ...] [--duration S] [-p node.param:=value ...]``

- SIGINT/SIGTERM are forwarded to every node (SIGINT first, as ros2 launch does; SIGTERM
  after ``--grace`` seconds; SIGKILL after twice that) and every child is reaped.
- If a node exits non-zero, the others are stopped and the launcher exits non-zero, naming
  the node, its exit code and its own last error line (a bad parameter, a plan that does not
  validate, a start barrier that timed out).
- Node output goes to ``<log_dir>/<node>.log`` when a log directory is given (aero-rig
  campaign), else to the launcher's stderr with a ``[node]`` prefix on every line, as
  ``ros2 launch`` shows it. A node with ``stops_graph: true`` stops the graph when it exits.
- ``--duration S`` stops the graph after S seconds (exit 0 if every node stopped cleanly).
- ``--host NAME`` (repeatable) starts only the nodes the graph places on that machine
  (graph.py, ``host``); the other machines start theirs, and the start barrier waits for all.
- A node whose process is stopped (SIGSTOP, Ctrl-Z on its group, a debugger) is named once it
  has been stopped for longer than the DDS participant lease, past which its peers drop it
  with what they had not delivered; and again when it runs on (docs/design.md §3.10).
"""

import argparse
import importlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .graph import GraphError, GraphSpec, NodeSpec, entry_point, load_graph, yaml_scalar
from .params import ParameterError, resolve_parameters
from .ros_environment import (
    LAUNCHER_PID_ENV,
    PARTICIPANT_LEASE_S,
    RosEnvironmentError,
    require_rclpy,
)
from .signals import StopSignals


@dataclass
class NodeProcess:
    spec: NodeSpec
    process: subprocess.Popen[bytes]
    log_path: Path | None = None
    tail: deque[str] | None = None  # the last lines of its output (when forwarded)
    reader: threading.Thread | None = None

    @property
    def returncode(self) -> int | None:
        return self.process.poll()

    def output_tail(self) -> list[str]:
        if self.tail is not None:
            if self.reader is not None:
                self.reader.join(timeout=1.0)  # the pipe closes when the process is gone
            return list(self.tail)
        if self.log_path is None or not self.log_path.exists():
            return []
        with self.log_path.open("rb") as f:
            f.seek(max(0, f.seek(0, os.SEEK_END) - 16384))
            return f.read().decode(errors="replace").splitlines()[-50:]

    def is_stopped(self) -> bool:
        """Whether the process is stopped: SIGSTOP, job control or a debugger (psutil)."""
        import psutil

        try:
            return psutil.Process(self.process.pid).status() in (
                psutil.STATUS_STOPPED,
                psutil.STATUS_TRACING_STOP,
            )
        except psutil.Error:
            return False

    def error_line(self) -> str | None:
        """The node's own last error: a [FATAL]/[ERROR] log line or a traceback's last line."""
        for line in reversed(self.output_tail()):
            text = line.strip()
            if text.startswith(("[FATAL]", "[ERROR]")) or _EXCEPTION_LINE.match(text):
                return text
        return None


_EXCEPTION_LINE = re.compile(r"^[A-Za-z_][\w.]*(Error|Exception|Interrupt)\b.*")


def _forward(stream: Any, name: str, tail: deque[str]) -> None:
    """Copy a node's output to our stderr, each line prefixed with the node's name."""
    for raw in iter(stream.readline, b""):
        line = raw.decode(errors="replace").rstrip("\n")
        tail.append(line)
        try:
            sys.stderr.write(f"[{name}] {line}\n")
            sys.stderr.flush()
        except (OSError, ValueError):
            pass
    stream.close()


def node_command(spec: NodeSpec, extra_overrides: dict[str, Any] | None = None) -> list[str]:
    module, _, func = entry_point(spec.package, spec.executable).partition(":")
    bootstrap = f"import sys; from {module} import {func} as main; sys.exit(main())"
    return [sys.executable, "-c", bootstrap, *spec.ros_arguments(extra_overrides)]


class Launcher:
    """Start, watch and stop the processes of a graph."""

    def __init__(
        self,
        graph: GraphSpec,
        env: Mapping[str, str] | None = None,
        overrides: Mapping[str, dict[str, Any]] | None = None,
        log_dir: Path | None = None,
        grace_s: float = 5.0,
        hosts: Collection[str] | None = None,
    ) -> None:
        self.graph = graph
        # The machines whose nodes this launcher starts (None: every node of the graph).
        if hosts is not None:
            graph.check_hosts(hosts)
        self.hosts = None if hosts is None else frozenset(hosts)
        # RIG_LAUNCHER_PID: a node whose parent is no longer this process stops (Node.spin), so
        # a launcher killed with SIGKILL leaves no graph running on.
        self.env = {**os.environ, **(env or {}), LAUNCHER_PID_ENV: str(os.getpid())}
        # The start barrier's member list comes from the graph; explicit overrides win.
        self.overrides = {
            name: {**barrier, **dict(overrides or {}).get(name, {})}
            for name, barrier in graph.barrier_overrides().items()
        }
        for name, values in dict(overrides or {}).items():
            self.overrides.setdefault(name, dict(values))
        self.log_dir = log_dir
        self.grace_s = grace_s
        self.processes: list[NodeProcess] = []
        self.failure: str | None = None
        self.failed_node: str | None = None  # the node whose exit is the failure
        self.stopped_since: dict[str, float] = {}  # node: monotonic time it was seen stopped
        self._logs: list[Any] = []

    @property
    def local_nodes(self) -> tuple[NodeSpec, ...]:
        """The nodes this launcher starts."""
        return tuple(n for n in self.graph.nodes if n.on(self.hosts))

    def check(self) -> None:
        """Refuse before any node starts what a node would refuse at its start (GraphError)."""
        for spec in self.local_nodes:
            check_node(spec, self.overrides.get(spec.name))

    @property
    def remote_nodes(self) -> tuple[NodeSpec, ...]:
        """The graph's nodes that other machines start."""
        return tuple(n for n in self.graph.nodes if not n.on(self.hosts))

    def start(self) -> None:
        for spec in self.local_nodes:
            cmd = node_command(spec, self.overrides.get(spec.name))
            stdout: Any = subprocess.PIPE
            log_path = None
            if self.log_dir is not None:
                self.log_dir.mkdir(parents=True, exist_ok=True)
                log_path = self.log_dir / f"{spec.name}.log"
                log = log_path.open("wb")
                self._logs.append(log)
                stdout = log
            # Own process group: a terminal's Ctrl-C reaches the launcher only, which then
            # stops the nodes in order instead of all of them racing. The same session, though:
            # with the kernel's autogroup scheduling every session is one scheduling entity,
            # and a node's `nice` would have no effect against nodes in other sessions.
            process = subprocess.Popen(
                cmd,
                env=self.env,
                stdout=stdout,
                stderr=subprocess.STDOUT,
                process_group=0,
            )
            if spec.nice:  # relative to the launcher's own, like `nice -n` in the launch files
                try:
                    niceness = min(19, os.getpriority(os.PRIO_PROCESS, 0) + spec.nice)
                    os.setpriority(os.PRIO_PROCESS, process.pid, niceness)
                except OSError:
                    pass  # the process already exited: poll() reports it
            node = NodeProcess(spec, process, log_path)
            if log_path is None:
                node.tail = deque(maxlen=50)
                node.reader = threading.Thread(
                    target=_forward, args=(process.stdout, spec.name, node.tail), daemon=True
                )
                node.reader.start()
            self.processes.append(node)

    def poll(self) -> str | None:
        """None while the graph should keep running; else why it must stop."""
        for proc in self.processes:
            code = proc.returncode
            if code is None:
                continue
            if code != 0:
                self.failed_node = proc.spec.name
                self.failure = f"node {proc.spec.name!r} exited with code {code}"
                line = proc.error_line()
                if line:
                    self.failure += f": {line}"
                return self.failure
            if proc.spec.stops_graph:
                return f"node {proc.spec.name!r} finished"
        if self.processes and all(p.returncode is not None for p in self.processes):
            return "all nodes finished"
        return None

    def stopped(self, now: float | None = None) -> dict[str, float]:
        """{node: seconds it has been stopped} for the nodes whose process is stopped now
        (first seen at one of these calls: call it about once a second)."""
        now = time.monotonic() if now is None else now
        stopped = {p.spec.name for p in self.processes if p.is_stopped()}
        self.stopped_since = {n: self.stopped_since.get(n, now) for n in stopped}
        return {n: now - since for n, since in self.stopped_since.items()}

    def running(self) -> list[str]:
        return [p.spec.name for p in self.processes if p.returncode is None]

    def stop(self) -> dict[str, int]:
        """Stop every node (SIGINT, then SIGTERM, then SIGKILL) and reap it."""
        for sig, wait_s in (
            (signal.SIGINT, self.grace_s),
            (signal.SIGTERM, self.grace_s),
            (signal.SIGKILL, self.grace_s),
        ):
            alive = [p for p in self.processes if p.returncode is None]
            if not alive:
                break
            for p in alive:
                try:
                    os.kill(p.process.pid, sig)
                    # A stopped node (SIGSTOP, job control) handles its stop only once it runs.
                    os.kill(p.process.pid, signal.SIGCONT)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + wait_s
            while time.monotonic() < deadline and any(p.returncode is None for p in alive):
                time.sleep(0.02)
        codes = {}
        for p in self.processes:
            try:
                codes[p.spec.name] = p.process.wait(timeout=self.grace_s)
            except subprocess.TimeoutExpired:  # pragma: no cover - SIGKILL cannot be ignored
                codes[p.spec.name] = -9
        for log in self._logs:
            log.close()
        return codes

    def run(self, duration_s: float | None = None) -> int:
        """Start, wait for a stop reason (node exit, duration, signal), stop. Exit code."""
        # SIGHUP: the terminal closed.
        stop_reason = StopSignals(signal.SIGINT, signal.SIGTERM, signal.SIGHUP).install()
        try:
            self.start()
            deadline = None if duration_s is None else time.monotonic() + duration_s
            lease_s = PARTICIPANT_LEASE_S
            reported: set[str] = set()  # stopped nodes named past the lease
            checked = 0.0
            reason = None
            while reason is None and not stop_reason:
                reason = self.poll()
                if time.monotonic() - checked >= 1.0:
                    checked = time.monotonic()
                    self._report_stopped(lease_s, reported)
                if deadline is not None and time.monotonic() >= deadline:
                    reason = f"duration {duration_s:g} s reached"
                time.sleep(0.05)
            reason = reason or f"received {stop_reason.received[0]}"
            _log(f"stopping graph {self.graph.name!r}: {reason}")
        finally:
            codes = self.stop()
            stop_reason.restore()
        if self.failure:
            _log(f"error: {self.failure}")
            return 1
        bad = {n: c for n, c in codes.items() if c not in (0, -signal.SIGINT, 130)}
        if bad:
            _log(f"error: nodes did not stop cleanly: {bad}")
            return 1
        return 0

    def _report_stopped(self, lease_s: float, reported: set[str], now: float | None = None) -> None:
        """Name a node stopped past the DDS lease, once, and again when it runs on."""
        stopped = self.stopped(now)
        for name, seconds in stopped.items():
            if seconds > lease_s and name not in reported:
                reported.add(name)
                _log(
                    f"warning: node {name!r} has been stopped (SIGSTOP, job control or a "
                    f"debugger) for {seconds:.0f} s, past the DDS participant lease "
                    f"({lease_s:g} s): its peers have dropped it with what they had not "
                    "delivered to it"
                )
        for name in sorted(reported - stopped.keys()):
            reported.discard(name)
            _log(f"node {name!r} runs again (it was stopped for longer than the lease)")


def _log(text: str) -> None:
    print(f"[rig-launch] {text}", file=sys.stderr, flush=True)


def check_node(spec: NodeSpec, extra_overrides: Mapping[str, Any] | None = None) -> None:
    """What the node would refuse at its start, refused without starting it: its parameters
    (files, then overrides, as `NodeSpec.ros_arguments` passes them) against their
    declarations (the module's PARAMETERS), then the module's own ``check_parameters``
    (e.g. the generator's plan). Raises GraphError with the line the node would print; a
    module without PARAMETERS (not a rig_runtime node) is left to check itself."""
    module_name, _, _ = entry_point(spec.package, spec.executable).partition(":")
    module = importlib.import_module(module_name)
    declared = getattr(module, "PARAMETERS", None)
    if declared is None:
        return
    overrides = {**spec.parameter_overrides, **(extra_overrides or {})}
    try:
        params = resolve_parameters(
            declared,
            spec.fq_name,
            spec.parameters,
            [(key, yaml_scalar(value)) for key, value in overrides.items()],
            as_ros_args=True,
        )
    except ParameterError as exc:  # as run_node prints it
        raise GraphError(f"[FATAL] [{spec.name}]: {exc}") from None
    check = getattr(module, "check_parameters", None)
    try:
        if check is not None:
            check(params)
    except ValueError as exc:  # as run_node prints what the node class's __init__ raises
        raise GraphError(f"[FATAL] [{spec.fq_name}]: {exc}") from None


def parse_overrides(items: list[str]) -> dict[str, dict[str, Any]]:
    """``NODE.PARAM:=VALUE`` items (VALUE in YAML) as {node: {param: value}}."""
    import yaml

    result: dict[str, dict[str, Any]] = {}
    for item in items:
        key, sep, value = item.partition(":=")
        node, dot, param = key.partition(".")
        if not sep or not dot:
            raise GraphError(f"-p {item!r}: expected NODE.PARAM:=VALUE")
        result.setdefault(node, {})[param] = yaml.safe_load(value)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="rig-launch", description=__doc__.split("\n\n")[0])
    parser.add_argument("graph", help="graph description YAML")
    parser.add_argument("--duration", type=float, default=None, help="stop after S seconds")
    parser.add_argument(
        "-p", dest="overrides", action="append", default=[], help="NODE.PARAM:=VALUE override"
    )
    parser.add_argument("--grace", type=float, default=5.0, help="seconds per stop stage")
    parser.add_argument(
        "--host",
        dest="hosts",
        action="append",
        default=None,
        metavar="NAME",
        help="start only the nodes the graph places on host NAME (repeatable; default: all)",
    )
    args = parser.parse_args(argv)
    try:
        require_rclpy()
    except RosEnvironmentError as exc:
        _log(f"error: {exc}")
        return 2
    try:
        graph = load_graph(args.graph)
        launcher = Launcher(
            graph, overrides=parse_overrides(args.overrides), grace_s=args.grace, hosts=args.hosts
        )
        launcher.check()  # fail before starting anything
    except GraphError as exc:
        _log(f"error: {exc}")
        return 2
    if launcher.hosts is not None:
        here = ", ".join(n.name for n in launcher.local_nodes) or "no node"
        elsewhere = ", ".join(n.name for n in launcher.remote_nodes) or "none"
        _log(
            f"host {', '.join(sorted(launcher.hosts))}: starting {here}; the other hosts start "
            f"{elsewhere} (the start barrier waits for them)"
        )
    return launcher.run(args.duration)


if __name__ == "__main__":
    sys.exit(main())

"""Helpers for tests that run nodes as processes (like launch_testing, much smaller).

Every process started through :class:`Processes` is stopped and reaped when the context
exits, whatever happened in the test; every wait is bounded. Each test gets its own
``ROS_DOMAIN_ID`` so graphs never see each other, and loopback-only discovery.
"""

import itertools
import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

_counter = itertools.count()


def unique_domain_id() -> int:
    """A domain id in 100..229 unlikely to clash with another test run on this machine."""
    return 100 + (os.getpid() * 7 + next(_counter)) % 130


def graph_env(domain_id: int | None = None, **extra: str) -> dict[str, str]:
    """The environment of a test graph: its own domain and loopback discovery."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(unique_domain_id() if domain_id is None else domain_id)
    env.pop("RIG_DDS_NETWORK", None)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_STATIC_PEERS", None)
    env["PYTHONUNBUFFERED"] = "1"
    env.update(extra)
    return env


DDS_KEYS = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")


def join_graph(env: dict[str, str], setenv: Callable[[str, str], None] | None = None) -> None:
    """Point this process's own nodes at the graph of ``env`` (same domain and network).

    Tests pass ``monkeypatch.setenv`` so the change is undone after the test.
    """
    for key in DDS_KEYS:
        (setenv or os.environ.__setitem__)(key, env[key])


def start_port_printer(
    module: str, args: Sequence[str], stderr_path: Path, timeout_s: float = 30.0
) -> tuple[subprocess.Popen[str], int]:
    """Start ``python -m module *args``, a simulated device that prints its UDP port as its
    first line, and return the process and that port; stdout stays open for the rest.

    Raises RuntimeError (with the end of its stderr) and leaves no process behind if no port
    comes within ``timeout_s``.
    """
    with open(stderr_path, "w") as stderr:
        proc = subprocess.Popen(
            [sys.executable, "-m", module, *args], stdout=subprocess.PIPE, stderr=stderr, text=True
        )
    try:
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
        line = proc.stdout.readline() if ready else ""
        if not line.strip().isdigit():
            raise RuntimeError(
                f"{module} did not print its port within {timeout_s} s (got {line!r}); "
                f"stderr: {stderr_path.read_text()[-2000:]}"
            )
    except BaseException:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=5.0)
        if proc.stdout is not None:
            proc.stdout.close()
        raise
    return proc, int(line)


def descendants(pid: int) -> list[Any]:
    """Every live descendant process of ``pid`` (psutil.Process), [] once it is gone."""
    import psutil

    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.Error:
        return []


def process_gone(proc: Any) -> bool:
    """Whether a psutil.Process has exited (a zombie waiting to be reaped counts as exited)."""
    import psutil

    try:
        return not proc.is_running() or proc.status() == psutil.STATUS_ZOMBIE
    except psutil.Error:
        return True


def wait_for(predicate: Callable[[], bool], timeout_s: float, interval_s: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval_s)
    return predicate()


class Processes:
    """Start processes; on exit SIGINT, then SIGKILL after ``grace_s``, and reap all."""

    def __init__(self, env: dict[str, str] | None = None, log_dir: Path | None = None) -> None:
        self.env = env or graph_env()
        self.log_dir = log_dir
        self.procs: list[subprocess.Popen[bytes]] = []
        self._logs: list[Any] = []

    def start(self, args: Sequence[str], name: str | None = None) -> subprocess.Popen[bytes]:
        stdout: Any = subprocess.DEVNULL
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            log = (self.log_dir / f"{name or len(self.procs)}.log").open("wb")
            self._logs.append(log)
            stdout = log
        proc = subprocess.Popen(
            list(args),
            env=self.env,
            stdout=stdout,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self.procs.append(proc)
        return proc

    def start_python(self, code_or_module: str, *args: str, name: str | None = None) -> Any:
        if code_or_module.startswith("-m "):
            return self.start([sys.executable, "-m", code_or_module[3:], *args], name)
        return self.start([sys.executable, "-c", code_or_module, *args], name)

    def start_entry(
        self, package: str, executable: str, *args: str, name: str | None = None
    ) -> Any:
        from rig_runtime.graph import entry_point

        module, _, func = entry_point(package, executable).partition(":")
        code = f"import sys; from {module} import {func} as m; sys.exit(m())"
        return self.start([sys.executable, "-c", code, *args], name or executable)

    def log(self, name: str) -> str:
        if self.log_dir is None:
            return ""
        path = self.log_dir / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def stop_all(self, grace_s: float = 5.0) -> None:
        for sig in (signal.SIGINT, signal.SIGKILL):
            alive = [p for p in self.procs if p.poll() is None]
            for p in alive:
                try:
                    os.kill(p.pid, sig)
                except ProcessLookupError:
                    pass

            def exited(alive: list[subprocess.Popen[bytes]] = alive) -> bool:
                return all(p.poll() is not None for p in alive)

            wait_for(exited, grace_s)
        for p in self.procs:
            p.wait(timeout=grace_s)
        for log in self._logs:
            log.close()

    def __enter__(self) -> "Processes":
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop_all()


# -- fault injection (tests/test_faults.py, tests/test_campaign.py, bench/faults.py) --------------

# A node process is recognised by its module in the launcher's bootstrap command line.
NODE_MODULES = {
    "generator": "multisine_gen.generator_node",
    "sim_actuator": "pitch_actuator.sim_actuator_node",
    "sim_wing": "wing_sim.sim_wing_node",
    "lift": "pressure_scanner.lift_node",
    "identifier": "aero_identification.identifier_node",
    "recorder": "rig_runtime.recorder",
}


def node_process(root_pid: int, node: str) -> Any:
    """The psutil.Process of a graph node started under ``root_pid`` (None if not running)."""
    import psutil

    module = NODE_MODULES[node]
    for child in descendants(root_pid):
        try:
            if any(f"from {module} import" in part for part in child.cmdline()):
                return child
        except psutil.Error:
            continue
    return None


class BusyProcesses:
    """``count`` CPU-bound processes at niceness ``nice`` (a loaded machine), each ending by
    itself after ``limit_s`` and killed when the context exits."""

    def __init__(self, count: int, nice: int = 0, limit_s: float = 900.0) -> None:
        self.count = count
        self.nice = nice
        self.limit_s = limit_s
        self.procs: list[subprocess.Popen[bytes]] = []

    def __enter__(self) -> "BusyProcesses":
        code = (
            f"import time\nend = time.monotonic() + {self.limit_s}\n"
            "while time.monotonic() < end: pass"
        )
        for _ in range(self.count):
            proc = subprocess.Popen([sys.executable, "-c", code])
            self.procs.append(proc)
            if self.nice:
                try:
                    os.setpriority(os.PRIO_PROCESS, proc.pid, self.nice)
                except OSError:
                    pass
        return self

    def __exit__(self, *exc_info: object) -> None:
        for proc in self.procs:
            proc.kill()
        for proc in self.procs:
            proc.wait(timeout=10)


def pause(proc: Any, seconds: float) -> None:
    """SIGSTOP a process for ``seconds`` (a node frozen by the OS, a debugger, swapping), then
    SIGCONT it; it is continued even if the wait is interrupted. A process that ended while
    stopped (the launcher's stop resumes a stopped node so that it handles its SIGINT) is
    left as it is."""
    import psutil

    proc.suspend()
    try:
        time.sleep(seconds)
    finally:
        try:
            proc.resume()
        except psutil.NoSuchProcess:
            pass


def start_session(args: Sequence[str], env: dict[str, str]) -> "subprocess.Popen[str]":
    """Start a command in its own session (a graph under it can be killed as one group), with
    text pipes for its output; pair with :func:`finish`."""
    return subprocess.Popen(
        list(args),
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def finish(proc: "subprocess.Popen[str]", timeout_s: float) -> tuple[str, str]:
    """Wait for a :func:`start_session` process (bounded); its whole group is killed if it is
    still running then, or if the wait is interrupted. Returns (stdout, stderr)."""
    try:
        return proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

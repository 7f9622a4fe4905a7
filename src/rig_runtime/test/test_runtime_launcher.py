"""The launcher runs a graph as processes, stops all on a crash, and leaves nothing behind."""

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import psutil
import pytest
import yaml

from rig_runtime.graph import load_graph
from rig_testing.processes import descendants, finish, graph_env, process_gone, wait_for

pytestmark = pytest.mark.slow  # node processes talking DDS: `make test-fast` skips them


def _graph(tmp_path: Path, talker_exit: int, listener_result: Path) -> Path:
    params = tmp_path / "params.yaml"
    params.write_text(
        yaml.safe_dump({"listener": {"ros__parameters": {"result_file": str(listener_result)}}})
    )
    graph = {
        "name": "test",
        "nodes": [
            {
                "name": "listener",
                "package": "rig_testing",
                "executable": "listener",
                "parameters": ["params.yaml"],
            },
            {
                "name": "talker",
                "package": "rig_testing",
                "executable": "talker",
                "parameter_overrides": {"count": 200, "exit_code": talker_exit, "linger_s": 0.2},
            },
        ],
    }
    path = tmp_path / "graph.yaml"
    path.write_text(yaml.safe_dump(graph))
    return path


def _launch(graph: Path, *extra: str, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "rig_runtime.launcher", str(graph), *extra],
        env=env or graph_env(),
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
    )


def _launch_logged(graph: Path, log: Path, *extra: str) -> subprocess.Popen[str]:
    """The launcher with its output (every node's lines, prefixed) in ``log``."""
    with log.open("w") as stderr:
        return subprocess.Popen(
            [sys.executable, "-m", "rig_runtime.launcher", str(graph), *extra],
            env=graph_env(),
            stderr=stderr,
            stdout=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
        )


def _logged(log: Path, line: str) -> bool:
    return line in log.read_text(errors="replace")


def test_crashing_node_stops_graph_nonzero_naming_it(tmp_path: Path) -> None:
    result = tmp_path / "listener.json"
    proc = _launch(_graph(tmp_path, 3, result))
    try:
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode != 0
    assert "node 'talker' exited with code 3" in err
    # The listener was stopped cleanly (SIGINT) and wrote its summary: all 200 arrived.
    assert json.loads(result.read_text())["received"] == 200


def test_a_node_failing_at_start_is_named_with_its_own_error_line(tmp_path: Path) -> None:
    """A node that fails at its start (here: an executor its environment names that does not
    exist, which only the node reads): the launcher's last line carries the node's own
    [FATAL] line, and the node's output is shown with its [name] prefix, as ros2 launch
    shows it."""
    graph = _graph(tmp_path, 0, tmp_path / "listener.json")
    proc = _launch(graph, env=graph_env(RIG_RCLPY_EXECUTOR="bogus"))
    _, err = finish(proc, 60)
    assert proc.returncode != 0
    last = [line for line in err.splitlines() if line.startswith("[rig-launch] error")][-1]
    assert re.search(
        r"node '(talker|listener)' exited with code 2: \[FATAL\] \[(talker|listener)\]: "
        r"RIG_RCLPY_EXECUTOR='bogus'",
        last,
    ), err
    assert re.search(r"\[(talker|listener)\] \[FATAL\]", err), err


def test_a_bad_parameter_is_refused_before_any_node_starts(tmp_path: Path) -> None:
    """A parameter outside its declaration never reaches a node: exit 2, the node's own line."""
    graph = _graph(tmp_path, 0, tmp_path / "listener.json")
    proc = _launch(graph, "-p", "talker.count:=-5")
    _, err = finish(proc, 60)
    assert proc.returncode == 2, err
    assert (
        err.strip()
        .splitlines()[-1]
        .startswith(
            "[rig-launch] error: [FATAL] [talker]: parameter 'count' = -5 (from --ros-args "
            "(count:=-5)) is invalid"
        )
    ), err
    assert "[talker]" not in err.replace("[FATAL] [talker]", "") and "[listener]" not in err


def test_duration_and_sigterm_reap_every_child(tmp_path: Path) -> None:
    result = tmp_path / "listener.json"
    graph = _graph(tmp_path, 0, result)
    log = tmp_path / "launch.log"
    proc = _launch_logged(graph, log, "--duration", "30")
    try:
        # Both nodes spinning: the talker saw the listener's subscription.
        assert wait_for(lambda: _logged(log, "subscriber(s) matched"), 60), log.read_text()
        children = descendants(proc.pid)
        assert len(children) >= 2
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, log.read_text()
    assert all(process_gone(c) for c in children)


def test_graph_description_errors(tmp_path: Path) -> None:
    import pytest

    from rig_runtime.graph import GraphError

    bad = tmp_path / "bad.yaml"
    bad.write_text("nodes:\n  - name: a\n    package: rig_runtime\n")
    with pytest.raises(GraphError, match="'executable'"):
        load_graph(bad)
    missing = tmp_path / "missing.yaml"
    missing.write_text(
        "nodes:\n  - {name: a, package: rig_testing, executable: talker, parameters: [nope.yaml]}\n"
    )
    with pytest.raises(GraphError, match="does not exist"):
        load_graph(missing)
    proc = subprocess.run(
        [sys.executable, "-m", "rig_runtime.launcher", str(_unknown_exe(tmp_path))],
        env=graph_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and "has no executable 'nope'" in proc.stderr


def _unknown_exe(tmp_path: Path) -> Path:
    path = tmp_path / "unknown.yaml"
    path.write_text("nodes:\n  - {name: a, package: rig_runtime, executable: nope}\n")
    return path


def test_nice_lowers_a_node_priority(tmp_path: Path) -> None:
    import pytest

    from rig_runtime.graph import GraphError

    graph = yaml.safe_load(_graph(tmp_path, 0, tmp_path / "listener.json").read_text())
    graph["nodes"][0]["nice"] = 7  # the listener
    graph["nodes"][1]["parameter_overrides"]["linger_s"] = 30.0
    path = tmp_path / "nice.yaml"
    path.write_text(yaml.safe_dump(graph))
    proc = _launch(path, "--duration", "30")
    try:
        assert wait_for(lambda: len(descendants(proc.pid)) >= 2, 20)
        nice = {" ".join(c.cmdline()): c.nice() for c in descendants(proc.pid)}
    finally:
        proc.send_signal(signal.SIGTERM)  # the launcher stops its nodes
        try:
            proc.wait(timeout=30)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=30)
    base = os.nice(0)
    assert sorted(nice.values()) == [base, min(19, base + 7)], nice
    assert [v for k, v in nice.items() if "__node:=listener" in k] == [min(19, base + 7)]
    graph["nodes"][0]["nice"] = 20
    path.write_text(yaml.safe_dump(graph))
    with pytest.raises(GraphError, match=r"'nice' must be an integer 0\.\.19"):
        load_graph(path)


def test_nodes_stop_when_the_launcher_is_killed(tmp_path: Path) -> None:
    graph = yaml.safe_load(_graph(tmp_path, 0, tmp_path / "listener.json").read_text())
    graph["nodes"][1]["parameter_overrides"].update(count=1_000_000, rate_hz=50.0)
    path = tmp_path / "orphans.yaml"
    path.write_text(yaml.safe_dump(graph))
    log = tmp_path / "launch.log"
    proc = _launch_logged(path, log)
    children: list[psutil.Process] = []
    try:
        # Both nodes spinning: the listener has a message.
        assert wait_for(lambda: _logged(log, "receiving: first message"), 60), log.read_text()
        children = descendants(proc.pid)
        os.kill(proc.pid, signal.SIGKILL)  # no chance to stop anything
        proc.wait(timeout=10)
        assert wait_for(lambda: all(process_gone(c) for c in children), 10)
    finally:
        for c in children:
            try:
                c.kill()
            except psutil.Error:
                pass
    # The listener shut down cleanly (its summary is written on shutdown): what it received
    # came in order and once each (no more messages than sequence numbers up to its last).
    summary = json.loads((tmp_path / "listener.json").read_text())
    assert summary["received"] >= 1 and summary["out_of_order"] == 0, summary
    assert summary["received"] <= summary["last"] + 1, summary


def test_a_stopped_node_is_named_past_the_lease_and_still_stops_cleanly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A node stopped by SIGSTOP: seen stopped, named once past the lease and again when it
    runs on; the graph's stop resumes a stopped node so that it handles its SIGINT."""
    from rig_runtime.launcher import Launcher

    result = tmp_path / "listener.json"
    graph = load_graph(_graph(tmp_path, 0, result))
    graph = dataclasses.replace(graph, nodes=(graph.node("listener"),))
    launcher = Launcher(graph, env=graph_env(), grace_s=10.0)
    launcher.start()
    try:
        listener = launcher.processes[0].process
        tail = launcher.processes[0].tail
        assert tail is not None and wait_for(lambda: any("running on" in x for x in tail), 30)
        assert launcher.stopped() == {}
        os.kill(listener.pid, signal.SIGSTOP)
        assert wait_for(lambda: launcher.stopped() != {}, 10)
        t0 = launcher.stopped_since["listener"]
        reported: set[str] = set()
        launcher._report_stopped(10.0, reported, now=t0 + 9.0)
        assert "has been stopped" not in capsys.readouterr().err  # within the lease
        launcher._report_stopped(10.0, reported, now=t0 + 11.0)
        err = capsys.readouterr().err
        assert "node 'listener' has been stopped" in err and "for 11 s" in err
        launcher._report_stopped(10.0, reported, now=t0 + 12.0)
        assert "has been stopped" not in capsys.readouterr().err  # once
        os.kill(listener.pid, signal.SIGCONT)
        assert wait_for(lambda: launcher.stopped() == {}, 10)
        launcher._report_stopped(10.0, reported)
        assert "node 'listener' runs again" in capsys.readouterr().err
        os.kill(listener.pid, signal.SIGSTOP)
        assert wait_for(lambda: launcher.stopped() != {}, 10)
    finally:
        codes = launcher.stop()
    # resumed by the stop, it handled SIGINT itself
    assert codes["listener"] == 0, (codes, capsys.readouterr().err)
    assert result.exists()  # and wrote its summary on the way out


def _placed(tmp_path: Path, hosts: dict[str, str]) -> Path:
    """The talker/listener graph with ``{node: host}`` placed (a barrier lead on the talker)."""
    document = yaml.safe_load(_graph(tmp_path, 0, tmp_path / "listener.json").read_text())
    for node in document["nodes"]:
        if node["name"] in hosts:
            node["host"] = hosts[node["name"]]
    document["nodes"][1]["barrier"] = "lead"
    path = tmp_path / "placed.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_a_launch_by_host_starts_that_hosts_nodes_and_waits_for_all(tmp_path: Path) -> None:
    from rig_runtime.graph import GraphError
    from rig_runtime.launcher import Launcher

    graph = load_graph(_placed(tmp_path, {"listener": "workstation", "talker": "rig"}))
    assert graph.hosts == ("workstation", "rig")
    rig = Launcher(graph, hosts=["rig"])
    assert [n.name for n in rig.local_nodes] == ["talker"]
    assert [n.name for n in rig.remote_nodes] == ["listener"]
    # the start barrier's lead still waits for every member, wherever it runs
    assert rig.overrides["talker"]["barrier_nodes"] == ["/listener"]
    assert [n.name for n in Launcher(graph).local_nodes] == ["listener", "talker"]
    with pytest.raises(GraphError, match=r"no host 'tunnel'.*workstation, rig"):
        Launcher(graph, hosts=["tunnel"])
    unplaced = load_graph(_placed(tmp_path, {"talker": "rig"}))
    with pytest.raises(GraphError, match="places no host for listener"):
        Launcher(unplaced, hosts=["rig"])
    bad = tmp_path / "bad_host.yaml"
    bad.write_text("nodes:\n  - {name: a, package: rig_testing, executable: talker, host: 'a b'}\n")
    with pytest.raises(GraphError, match="'host' must be a name"):
        load_graph(bad)


def test_rig_launch_by_host_names_what_runs_here_and_elsewhere(tmp_path: Path) -> None:
    graph = _placed(tmp_path, {"listener": "workstation", "talker": "rig"})
    proc = _launch(graph, "--host", "workstation", "--duration", "30")
    try:
        # A child just forked still shows the launcher's command line until it execs its node.
        def started() -> list[str]:
            return [" ".join(c.cmdline()) for c in descendants(proc.pid)]

        assert wait_for(lambda: any("listener" in line for line in started()), 20), started()
        (line,) = started()  # the listener alone: the talker is the rig's
        assert "listener" in line
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert "host workstation: starting listener; the other hosts start talker" in err, err
    wrong = _launch(graph, "--host", "tunnel")
    try:
        _, err = wrong.communicate(timeout=60)
    finally:
        if wrong.poll() is None:
            os.killpg(wrong.pid, signal.SIGKILL)
    assert wrong.returncode == 2 and "has no host 'tunnel'" in err, err

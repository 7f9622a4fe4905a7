"""``ros2 launch aero_rig sim.launch.py`` (the real launch, launch_ros and ros2launch, Jazzy)
runs a campaign (the small plan) from the packages as colcon installs them.

Needs the ros2 tools and composition_interfaces in the venv (``make test`` installs them from
../shared/ros2-python); skips with one line otherwise. The nodes are the colcon install's
executables (``lib/<package>/<executable>``), found through the ament index, as on a ROS
machine after ``source install/setup.bash``.
"""

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from rig_runtime.graph import package_share
from rig_testing.processes import graph_env

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def _launch_ready() -> str | None:
    if not (BIN / "ros2").exists():
        return "the ros2 tools are not in the venv (make test installs them)"
    probe = subprocess.run(
        [sys.executable, "-c", "import launch_ros, composition_interfaces.srv, ros2launch"],
        capture_output=True,
        text=True,
    )
    if probe.returncode != 0:
        return f"launch_ros does not import: {probe.stderr.strip().splitlines()[-1:]}"
    return None


pytestmark = [
    pytest.mark.ci_required,
    pytest.mark.skipif(_launch_ready() is not None, reason=str(_launch_ready())),
]


@pytest.fixture(scope="module")
def colcon_install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``colcon build`` of the workspace into a temporary install (as a ROS user builds it)."""
    from test_colcon_workspace import _colcon

    tmp = tmp_path_factory.mktemp("colcon")
    build = _colcon(tmp, "build")
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    return tmp / "install"


def _sourced(install: Path, env: dict[str, str]) -> dict[str, str]:
    """What ``source install/setup.bash`` sets for these packages: the ament index prefixes."""
    prefixes = [str(p) for p in sorted(install.iterdir()) if (p / "share").is_dir()]
    old = env.get("AMENT_PREFIX_PATH", "")
    return {
        **env,
        "AMENT_PREFIX_PATH": ":".join([*prefixes, *([old] if old else [])]),
        "PATH": f"{BIN}:{env['PATH']}",
    }


def test_sim_launch_runs_a_campaign(colcon_install: Path, small_plan: Path, tmp_path: Path) -> None:
    """The small plan (conftest.small_plan): the launch, the nodes, the run directory and the
    identifier's exit are what this checks; the short plan's identification is test_campaign's."""
    sim = yaml.safe_load((package_share("aero_rig") / "config" / "sim.yaml").read_text())
    overrides: dict[str, dict[str, Any]] = {
        "generator": {
            "plan": str(small_plan),
            "real_time_factor": 0.0,
            "start_timeout_s": 120.0,
        },
        "sim_wing": {"preset": "repeatable_stall"},
        "identifier": {"exit_after_final": True},
    }
    for node in sim["nodes"]:
        node["parameter_overrides"] = {
            **(node.get("parameter_overrides") or {}),
            **overrides.get(node["name"], {}),
        }
    graph = tmp_path / "short_sim.yaml"
    graph.write_text(yaml.safe_dump(sim))
    run_dir = tmp_path / "run"
    env = _sourced(colcon_install, graph_env())
    env["TMPDIR"] = str(tmp_path)  # launch_ros leaves its launch_params_* files in TMPDIR
    proc = subprocess.Popen(
        [
            str(BIN / "ros2"),
            "launch",
            "aero_rig",
            "sim.launch.py",
            f"graph:={graph}",
            f"run_dir:={run_dir}",
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        out, _ = proc.communicate(timeout=400)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
        pytest.fail(f"ros2 launch did not finish within 400 s:\n{out[-4000:]}")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
    # The identifier's exit ended the launch (stops_graph), and every node stopped cleanly.
    assert "process[identifier-5] was required: shutting down launched system" in out, out[-4000:]
    assert out.count("process has finished cleanly") == 6, out[:3000] + out[-3000:]
    # Every node of the graph ran under launch, on rclpy.
    for name in ("generator", "sim_actuator", "sim_wing", "lift", "identifier", "recorder"):
        assert re.search(rf"\[{name}\]: running on rclpy", out), name
    models = json.loads((run_dir / "models.json").read_text())
    assert models["data_quality"]["clean"], models["data_quality"]
    assert (run_dir / "table1_all_levels.md").exists()
    assert (run_dir / "bag" / "metadata.yaml").exists()


def test_rig_launch_starts_the_hardware_nodes_against_the_simulated_devices(
    colcon_install: Path, tmp_path: Path
) -> None:
    """``ros2 launch aero_rig rig.launch.py``: the hardware actuator driver against the
    simulated controller (PWAC over UDP), the scanner driver against the simulated scanner,
    the generator streaming in real time through the start barrier. The controller applies
    the generator's setpoints, the recorder's bag holds states, taps and C_l, and Ctrl-C
    stops every node cleanly. Loopback only."""
    import threading

    from aero_rig.verdict import bag_topic_counts
    from rig_testing.processes import Processes, wait_for

    env = _sourced(colcon_install, graph_env())
    env["TMPDIR"] = str(tmp_path)  # launch_ros leaves its launch_params_* files in TMPDIR
    devices = Processes(env, log_dir=tmp_path)
    audit = tmp_path / "audit.jsonl"
    devices.start_python(
        "-m pitch_actuator.sim_controller",
        *("--host", "127.0.0.1", "--port", "0", "--audit-file", str(audit)),
        *("--min-deg", "-10", "--max-deg", "35"),
        name="controller",
    )
    proc: subprocess.Popen[str] | None = None
    lines: list[str] = []
    try:
        assert wait_for(lambda: devices.log("controller").strip() != "", 30), "controller silent"
        controller_port = int(devices.log("controller").split()[0])
        rig = yaml.safe_load((package_share("aero_rig") / "config" / "rig.yaml").read_text())
        overrides: dict[str, dict[str, Any]] = {
            "generator": {"plan": "short", "start_timeout_s": 120.0},
            "hw_actuator": {"controller_port": controller_port, "bind_host": "127.0.0.1"},
            "scanner": {"port": 0, "bind_host": "127.0.0.1"},
        }
        for node in rig["nodes"]:
            node["parameter_overrides"] = {
                **(node.get("parameter_overrides") or {}),
                **overrides.get(node["name"], {}),
            }
        graph = tmp_path / "rig_loopback.yaml"
        graph.write_text(yaml.safe_dump(rig))
        run_dir = tmp_path / "run"
        launch = [str(BIN / "ros2"), "launch", "aero_rig", "rig.launch.py"]
        proc = subprocess.Popen(
            [*launch, f"graph:={graph}", f"run_dir:={run_dir}"],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        stream = proc.stdout
        assert stream is not None
        reader = threading.Thread(target=lambda: lines.extend(iter(stream.readline, "")))
        reader.daemon = True
        reader.start()

        def said(pattern: str) -> re.Match[str] | None:
            return next((m for line in list(lines) if (m := re.search(pattern, line))), None)

        assert wait_for(lambda: said(r"scanner frames on UDP port (\d+)") is not None, 120), (
            "".join(lines)[-4000:]
        )
        scanner_port = said(r"scanner frames on UDP port (\d+)").group(1)  # type: ignore[union-attr]
        devices.start_python(
            "-m wing_sim.sim_scanner",
            *("--host", "127.0.0.1", "--port", scanner_port, "--rate", "200"),
            name="sim_scanner",
        )
        assert wait_for(lambda: said(r"start barrier passed") is not None, 120), "".join(lines)[
            -4000:
        ]

        def applied() -> int:
            text = audit.read_text() if audit.exists() else ""
            return text.count('"event": "apply"')

        # The scanner's stream has begun (its process starts slowly on a busy machine: numpy,
        # the plant), then two more seconds of the plan at 200 Hz applied by the controller
        # (generator -> driver -> UDP), so every stream has flowed for those two seconds.
        assert wait_for(lambda: "first_frame_sent" in devices.log("sim_scanner"), 120), devices.log(
            "sim_scanner"
        )[-2000:]
        start = applied()
        assert wait_for(lambda: applied() >= start + 400, 60), "".join(lines)[-4000:]
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C, as a user stops the launch
        proc.wait(timeout=120)
        reader.join(timeout=10)
    finally:
        if proc is not None and proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        devices.stop_all()
    out = "".join(lines)
    for name in ("generator", "hw_actuator", "scanner", "lift", "identifier", "recorder"):
        assert re.search(rf"\[{name}\]: running on rclpy", out), name
    ends = [line for line in out.splitlines() if "process has" in line or "process[" in line]
    assert out.count("process has finished cleanly") == 6, "\n".join(ends) + out[-3000:]
    # Every stream flowed through its node into the bag: a quarter of a second at 200 Hz at
    # least (how much more depends on the machine's load when Ctrl-C comes; C_l lags the
    # states by the lift's alignment window).
    counts = bag_topic_counts(run_dir / "bag")
    lift = [line for line in out.splitlines() if "[lift" in line or "[scanner" in line]
    for topic in ("/pitch/command", "/pitch/state", "/pressure/taps", "/wing/coefficients"):
        assert counts.get(topic, 0) >= 50, (topic, counts, lift[-30:])
    # The plan's commands are followed: no command held back by the wall-clock rate budget
    # (DDS delivers commands in bursts) is reported as not tracked.
    from rosbags.highlevel import AnyReader

    from rig_runtime.anomaly import Anomaly
    from rig_runtime.interface import EXPERIMENT_ANOMALY

    with AnyReader([run_dir / "bag"]) as bag:
        conns = [c for c in bag.connections if c.topic == EXPERIMENT_ANOMALY.name]
        kinds = [
            Anomaly.from_message(bag.deserialize(raw, c.msgtype)).kind
            for c, _, raw in bag.messages(connections=conns)
        ]
    assert "not_tracking" not in kinds, kinds

"""Generator -> simulated actuator -> simulated wing -> lift, as separate processes on DDS."""

import time
from pathlib import Path

import numpy as np
from graph_support import Observer, small_plan_design

from rig_runtime.interface import PITCH_STATE, PRESSURE_TAPS, WING_COEFFICIENTS
from rig_testing.processes import Processes, graph_env, join_graph

TOPICS = {
    PITCH_STATE.name: ("sensor_msgs/msg/JointState", "stream"),
    PRESSURE_TAPS.name: ("sensor_msgs/msg/PointCloud2", "stream"),
    WING_COEFFICIENTS.name: ("geometry_msgs/msg/Vector3Stamped", "stream"),
}


def test_every_state_gets_one_coefficients_sample(
    small_plan: Path, tmp_path: Path, monkeypatch
) -> None:
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    total = small_plan_design().total_samples
    observer = Observer(TOPICS)
    try:
        with Processes(env, log_dir=tmp_path) as procs:
            procs.start_entry("pitch_actuator", "sim_actuator", name="sim_actuator")
            procs.start_entry("wing_sim", "sim_wing", name="sim_wing")
            procs.start_entry("pressure_scanner", "lift", name="lift")
            assert observer.wait_matched(30), "nodes did not come up"
            # Matched from the readers' side is not enough: Fast DDS drops what a reliable,
            # volatile writer sends before its side has matched too. The observer joins the
            # generator's start barrier with its own readiness report, as a graph node does
            # (docs/design.md §3.5), so the first command waits for every link both ways.
            observer.node.start_readiness()
            t0 = time.monotonic()
            procs.start_entry(
                "multisine_gen",
                "generator",
                "--ros-args",
                "-p",
                f"plan:={small_plan}",
                "-p",
                "real_time_factor:=0.0",
                "-p",
                "flow_control:=true",
                "-p",
                "barrier_nodes:=[sim_actuator, sim_wing, lift, test_observer]",
                name="generator",
            )
            # Every observed stream complete: the big taps clouds may still be in the
            # observer's reader when the last (small) coefficients sample has been taken.
            done = observer.spin_until(
                lambda: all(len(observer.data[t]) >= total for t in TOPICS), 180
            )
            wall = time.monotonic() - t0
            logs = "".join(procs.log(n) for n in ("generator", "sim_actuator", "sim_wing", "lift"))
            assert done, observer.counts() + logs
    finally:
        observer.close()
    states = observer.stamps(PITCH_STATE.name)[:total]
    taps = observer.stamps(PRESSURE_TAPS.name)[:total]
    coeffs = observer.stamps(WING_COEFFICIENTS.name)[:total]
    np.testing.assert_array_equal(states, taps)
    np.testing.assert_array_equal(states, coeffs)
    assert len(np.unique(coeffs)) == total
    cl = np.array([m.vector.x for _, m in observer.data[WING_COEFFICIENTS.name][:total]])
    assert np.all(np.isfinite(cl))
    assert 0.2 < np.median(cl) < 2.0  # lift of a wing between 0° and 25°
    print(f"chain: {total} samples in {wall:.1f} s = {total / 200 / wall:.1f}x real time")

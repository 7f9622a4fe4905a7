"""Generator (the small plan) drives the simulated actuator, as separate processes on DDS."""

from pathlib import Path

import numpy as np
from graph_support import Observer, PeerReaders, small_plan_design

from multisine_gen.plan_format import read_plan_message, segment_event_from_message
from pitch_actuator.dynamics import ActuatorModel
from rig_runtime.interface import EXPERIMENT_PLAN, EXPERIMENT_SEGMENT, PITCH_COMMAND, PITCH_STATE
from rig_testing.processes import Processes, graph_env, join_graph

TOPICS = {
    PITCH_COMMAND.name: (PITCH_COMMAND.type, "stream"),
    PITCH_STATE.name: (PITCH_STATE.type, "stream"),
    EXPERIMENT_SEGMENT.name: (EXPERIMENT_SEGMENT.type, "events"),
    EXPERIMENT_PLAN.name: (EXPERIMENT_PLAN.type, "latched"),
}


def test_generator_drives_sim_actuator_every_sample_once(
    small_plan: Path, tmp_path: Path, monkeypatch
) -> None:
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    plan = small_plan_design()
    observer = Observer(TOPICS)
    try:
        with Processes(env, log_dir=tmp_path) as procs:
            procs.start_entry("pitch_actuator", "sim_actuator", "--ros-args", "-p", "seed:=5")
            # The actuator's /pitch/state writer must know this observer's reader before the
            # first command: what a writer sends before its side has matched is not delivered.
            peers = PeerReaders(observer.node)
            matched = observer.spin_until(lambda: peers.writers_matched([PITCH_STATE.name]), 60)
            assert matched, procs.log("sim_actuator")
            # The generator's writers too, seen from both sides, before its first command: the
            # observer joins the generator's start barrier with its own readiness report, as a
            # graph node does (docs/design.md §3.5). Fast DDS drops what a reliable, volatile
            # writer sends before the other side has matched.
            observer.node.start_readiness()
            gen = procs.start_entry(
                "multisine_gen",
                "generator",
                "--ros-args",
                "-p",
                f"plan:={small_plan}",
                "-p",
                "real_time_factor:=0.0",
                "-p",
                "flow_control:=false",
                "-p",
                "wait_for_subscribers:=2",
                "-p",
                "barrier_nodes:=[sim_actuator, test_observer]",
            )
            total = plan.total_samples
            done = observer.spin_until(
                lambda: (
                    len(observer.data[PITCH_STATE.name]) >= total
                    and len(observer.data[PITCH_COMMAND.name]) >= total
                    # The plan is published at t0 with the first commands: one large message,
                    # fragmented, which under load can arrive after the last command.
                    and len(observer.data[EXPERIMENT_PLAN.name]) >= 1
                    and any(
                        segment_event_from_message(m)["event"] == "plan_end"
                        for _, m in observer.data[EXPERIMENT_SEGMENT.name]
                    )
                ),
                120,
            )
            assert done, observer.counts() + procs.log("generator") + procs.log("sim_actuator")
            assert gen.poll() is None  # keeps the plan latched until stopped
    finally:
        observer.close()

    commands = observer.stamps(PITCH_COMMAND.name)
    states = observer.stamps(PITCH_STATE.name)[:total]
    assert len(commands) == total
    # One state per command, same stamp, in order, none lost or duplicated.
    np.testing.assert_array_equal(commands, states)
    assert np.all(np.diff(commands) == 5_000_000)

    # The plan on the wire rebuilds the commands exactly.
    sent, _ = read_plan_message(observer.data[EXPERIMENT_PLAN.name][0][1])
    assert sent.total_samples == total
    np.testing.assert_array_equal(sent.command_deg(), plan.command_deg())
    cmd = np.array([m.position[0] for _, m in observer.data[PITCH_COMMAND.name]])
    np.testing.assert_allclose(np.degrees(cmd), plan.command_deg(), atol=1e-9)

    # Measured pitch follows the command with the loop's gain and phase at excited lines.
    pos = np.array([m.position[0] for _, m in observer.data[PITCH_STATE.name][:total]])
    seg = next(s for s in plan.segments if s.kind == "multisine" and s.period == 1)
    N = seg.samples_per_period
    assert N is not None  # every multisine segment has it
    lines = plan.levels[0].realizations[0].excited_lines[:6]
    U = np.fft.rfft(cmd[seg.start_k : seg.start_k + N])[lines]
    Y = np.fft.rfft(pos[seg.start_k : seg.start_k + N])[lines]
    model = ActuatorModel(fs=plan.fs)
    expected = model.frf(lines * plan.fs / N)
    np.testing.assert_allclose(np.abs(Y / U), np.abs(expected), rtol=0.01)
    np.testing.assert_allclose(np.angle(Y / U / expected), 0.0, atol=0.01)

    events = [segment_event_from_message(m) for _, m in observer.data[EXPERIMENT_SEGMENT.name]]
    starts = [e for e in events if e.get("event") == "start"]
    assert len(starts) == len(plan.segments)

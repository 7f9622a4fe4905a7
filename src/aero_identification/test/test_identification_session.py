"""The identifier's work without a graph (identification_session.py): intake and gap tracking,
the refit schedule and what a refit's result does, and what the adaptive rules are given and
send. The refit itself is replaced by a stub (the pipeline is tested on its own)."""

import logging
import time
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import numpy as np
import pytest

from aero_identification import refit_worker
from aero_identification.campaign_source import level_so_far
from aero_identification.identification_session import (
    MAX_LOGGED_GAPS,
    IdentificationSession,
    PendingRefit,
    PeriodToJudge,
    RefitJob,
    RefitSchedule,
    refit_after,
)
from aero_identification.identifier_settings import PARAMETERS, identifier_settings
from aero_identification.period_assembly import CampaignAssembler
from aero_rig_interfaces.msg import Anomaly as AnomalyMsg
from aero_rig_interfaces.msg import ExperimentPlan as ExperimentPlanMsg
from multisine_gen.campaigns import short_plan
from multisine_gen.plan import ExperimentPlan
from multisine_gen.plan_format import plan_message, segment_event
from multisine_gen.revision import Adaptation, PlanRequest
from rig_runtime.anomaly import Anomaly
from rig_runtime.params import default_parameters

T0 = 1_000_000_000_000
PLAN = short_plan(seed=4)
LOGGER = "test.identifier"
BOUNDS = Adaptation().to_dict()  # the generator's defaults, published in an adaptive run


def _plan(adaptation: dict[str, int] | None = None, plan: ExperimentPlan = PLAN) -> Any:
    """The /experiment/plan message the generator publishes (generator_node.py)."""
    return ExperimentPlanMsg(**plan_message(plan, T0, adaptation, plan_id="short"))


class Outputs:
    """What the session hands its node, recorded."""

    def __init__(self) -> None:
        self.models: list[dict[str, Any]] = []
        self.stamps: list[int] = []
        self.statuses = 0
        self.requests: list[PlanRequest] = []
        self.stops: list[int] = []

    def publish_model(self, payload: dict[str, Any], stamp_ns: int) -> None:
        self.models.append(payload)
        self.stamps.append(stamp_ns)

    def publish_status(self) -> None:
        self.statuses += 1

    def send_request(self, request: PlanRequest) -> None:
        self.requests.append(request)

    def stop(self, exit_code: int) -> None:
        self.stops.append(exit_code)


def _session(outputs: Outputs, max_early: int = 20000, **values: Any) -> IdentificationSession:
    params = {**default_parameters(PARAMETERS).as_dict(), "use_worker": False, **values}
    return IdentificationSession(
        identifier_settings(params),
        logging.getLogger(LOGGER),
        outputs,
        max_early_samples=lambda: max_early,
        exit_after_final=lambda: True,
    )


def _stamp(k: int) -> int:
    return T0 + round(k * 1e9 / PLAN.fs)


def _feed(session: IdentificationSession, ks: range | list[int], channels: str = "uy") -> None:
    command = PLAN.command_deg()
    for k in ks:
        for channel in channels:  # a noise-free linear wing: C_l = 0.1 · pitch
            value = float(command[k]) * (1.0 if channel == "u" else 0.1)
            session.intake.add(channel, _stamp(k), value)


def _segment(
    plan: ExperimentPlan, kind: str, level: int, realization: int | None, period: int | None = None
) -> Any:
    return next(
        s
        for s in plan.segments
        if s.kind == kind and s.level == level and s.realization == realization
        and s.period == period
    )  # fmt: skip


def _end(segment: Any) -> dict[str, Any]:
    return segment_event(segment, "end", T0 / 1e9, PLAN.fs)


def _stub_refit(
    calls: list[tuple[bool, bool]],
    complete_when_final: bool = True,
    final_models: list[bool] | None = None,
) -> Any:
    """refit_worker.refit's stand-in: records (final, reuse) in ``calls`` and each job's
    final_models in ``final_models``, answers what a refit answers."""

    def refit(
        assembler: CampaignAssembler,
        config: Any,
        final: bool,
        out_dir: str,
        reuse: bool,
        fit_final_models: bool = False,
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        calls.append((final, reuse))
        if final_models is not None:
            final_models.append(fit_final_models)
        complete = final and complete_when_final
        summary = {
            "complete": complete,
            "warnings": [],
            "levels": [{"name": "low", "clusters": [1, [4]], "excluded": []}],
            "written": [],
            "data_quality": {"clean": True} if complete else {},
            "timings_s": {"bla": 0.01},
            "worker": {"cpu_s": 0.0, "start_mb": 0.0, "peak_mb": 0.0},
        }
        return {"table1": {"markdown": "| table |"}}, summary

    return refit


# -- intake and gap tracking -------------------------------------------------------------------
def test_samples_before_the_plan_wait_for_it_and_those_beyond_the_bound_are_reported() -> None:
    outputs = Outputs()
    session = _session(outputs, max_early=5)
    _feed(session, range(7), "u")
    assert len(session.intake.early) == 5 and session.intake.early_dropped == 2
    session.on_plan(_plan())
    assert session.intake.assembler is not None and not session.intake.early
    assert session.intake.samples == {"u": 5, "y": 0}
    assert session.errors == [
        "2 samples arrived before the plan and were dropped (max_early_samples = 5)"
    ]
    level, values = session.status([])
    assert level == 2 and values["errors"] == session.errors[0]


def test_an_unreadable_plan_stops_the_node() -> None:
    outputs = Outputs()
    session = _session(outputs)
    session.on_plan('{"no": "plan"}')
    assert outputs.stops == [1] and session.intake.assembler is None


def test_a_hole_in_the_plan_index_is_a_gap_logged_at_once_and_counted(caplog: Any) -> None:
    outputs = Outputs()
    session = _session(outputs)
    session.on_plan(plan_message(PLAN, T0)["plan_json"])  # its text, as bags held
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        _feed(session, [*range(10), *range(30, 40)], "u")
        _feed(session, range(40), "y")
    assert session.intake.gaps == {"u": [(10, 29)], "y": []}
    assert session.intake.have == 39
    (record,) = caplog.records
    assert record.getMessage().startswith(
        "/pitch/state: plan samples 10..29 (20) never arrived before sample 30"
    )
    level, values = session.status([])
    assert level == 1
    assert values["pitch gaps"] == "1 gap(s), 20 plan samples never arrived (last 10..29)"
    assert "C_l gaps" not in values


def test_gaps_beyond_the_logged_ones_are_counted_in_the_status_only(caplog: Any) -> None:
    session = _session(Outputs())
    session.on_plan(_plan())
    gaps = MAX_LOGGED_GAPS + 2
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        _feed(session, range(0, 2 * gaps + 1, 2), "y")  # every other sample: one-sample gaps
    assert session.intake.gaps["y"] == [(k, k) for k in range(1, 2 * gaps, 2)]
    messages = [r.getMessage() for r in caplog.records]
    assert len(messages) == MAX_LOGGED_GAPS
    assert messages[-1].endswith("(further gaps: in the status only)")
    assert "/wing/coefficients" in messages[0]
    _, values = session.status([])
    assert values["C_l gaps"].startswith(f"{gaps} gap(s), {gaps} plan samples never arrived")


def test_a_pause_past_the_lease_is_in_the_status() -> None:
    session = _session(Outputs())
    level, values = session.status([3.25])
    assert level == 1 and values["stopped"] == "1 time(s) past the DDS lease, last 3.2 s"


# -- the refit schedule ------------------------------------------------------------------------
def test_segment_events_make_their_refits_due() -> None:
    asm = CampaignAssembler(PLAN, T0)
    last = _segment(PLAN, "multisine", 0, 0, 3)
    assert refit_after(_end(last), asm) == PendingRefit(
        last.start_k + last.length - 1, False, "level 0 realization 0 complete", True
    )
    assert refit_after(_end(_segment(PLAN, "multisine", 0, 0, 2)), asm) is None
    sine = next(s for s in PLAN.segments if s.kind == "sine")
    assert refit_after(_end(sine), asm) == PendingRefit(
        sine.start_k + sine.length - 1,
        False,
        f"sine {sine.frequency_hz} Hz at {sine.offset_deg}°",
        False,  # a sine adds no multisine data: the models are only validated
    )
    assert refit_after({"event": "plan_end", "samples": 100}, asm) == PendingRefit(
        99, True, "plan end", False
    )
    assert refit_after({"event": "plan_aborted", "samples": 50}, asm) == PendingRefit(
        49, True, "plan aborted", True
    )
    # An adaptive run's realization ended early, at the period just judged.
    k = _segment(PLAN, "multisine", 1, 0, 1).start_k + 1999
    decision = {"event": "decision", "request": "end_realization", "after_k": k}
    assert refit_after({**decision, "from_k": k + 1}, asm) == PendingRefit(
        k, False, "level 1 realization 0 complete", True
    )
    assert refit_after({**decision, "from_k": k + 5}, asm) is None
    assert refit_after({"event": "start", "kind": "sine"}, asm) is None


def test_one_refit_covers_every_ready_one_in_their_order_and_a_final_wins() -> None:
    schedule = RefitSchedule()
    schedule.models_stale = False
    schedule.add(PendingRefit(200, False, "sine A", False))
    schedule.add(PendingRefit(100, False, "level 0 realization 0 complete", True))
    schedule.add(PendingRefit(300, True, "plan end", False))
    assert schedule.take_ready(99) is None
    ready = schedule.take_ready(250)
    assert ready is not None
    assert (ready.final, ready.reason) == (False, "sine A; level 0 realization 0 complete")
    assert schedule.models_stale  # new multisine data among them: fit afresh
    assert schedule.pending == [PendingRefit(300, True, "plan end", False)]
    schedule.models_stale = False
    ready = schedule.take_ready(300)
    assert ready is not None and ready.final and ready.reason == "plan end"
    assert not schedule.models_stale and not schedule.pending


@pytest.fixture
def stubbed(monkeypatch: pytest.MonkeyPatch) -> tuple[IdentificationSession, Outputs, list[Any]]:
    """A session given the plan, its refits done by the stub: (session, outputs, the stub's
    calls as (final, reuse))."""
    calls: list[tuple[bool, bool]] = []
    monkeypatch.setattr(refit_worker, "refit", _stub_refit(calls))
    outputs = Outputs()
    session = _session(outputs)
    session.on_plan(_plan())
    return session, outputs, calls


def test_refits_start_when_their_data_are_in_and_the_final_one_stops_the_node(
    stubbed: tuple[IdentificationSession, Outputs, list[Any]], caplog: Any
) -> None:
    session, outputs, calls = stubbed
    last = _segment(PLAN, "multisine", 0, 0, 3)
    end_k = last.start_k + last.length - 1
    _feed(session, range(end_k))  # one sample short
    session.on_segment(_end(last))
    session.on_timer()
    assert session.job is None and calls == []  # its data are not all in
    _feed(session, [end_k])
    with caplog.at_level(logging.INFO, logger=LOGGER):
        session.on_timer()  # starts it (inline: done at once)
        assert calls == [(False, False)] and session.job is not None
        session.on_timer()  # collects it
    assert session.job is None and session.refits == 1 and not session.schedule.models_stale
    (model,) = outputs.models
    assert model["refit"] == 1 and model["reason"] == "level 0 realization 0 complete"
    assert outputs.stamps == [_stamp(end_k)]  # the last sample its data had
    messages = [r.getMessage() for r in caplog.records]
    assert messages[0] == "refit 1 (level 0 realization 0 complete)"
    assert messages[1].startswith("refit 1 done in ")
    # A sine: its data unchanged, the kept models are validated again.
    sine = next(s for s in PLAN.segments if s.kind == "sine")
    session.on_segment(_end(sine))
    _feed(session, range(end_k + 1, sine.start_k + sine.length))
    session.on_timer()
    assert calls[-1] == (False, True)
    session.on_timer()
    assert session.refits == 2 and outputs.stops == []
    # The plan's end: the final identification, and the node stops (exit_after_final).
    _feed(session, range(sine.start_k + sine.length, PLAN.total_samples))
    session.on_segment({"event": "plan_end", "samples": PLAN.total_samples})
    session.on_timer()
    assert calls[-1] == (True, True)
    session.on_timer()
    assert session.final_done and outputs.stops == [0]
    assert session.status([])[1]["state"] == "done"


@pytest.mark.parametrize("anomaly_meanwhile", [False, True])
def test_once_every_multisine_period_is_in_its_refit_fits_the_final_models(
    monkeypatch: pytest.MonkeyPatch, caplog: Any, anomaly_meanwhile: bool
) -> None:
    calls: list[tuple[bool, bool]] = []
    final_models: list[bool] = []
    monkeypatch.setattr(refit_worker, "refit", _stub_refit(calls, final_models=final_models))
    outputs = Outputs()
    session = _session(outputs)
    session.on_plan(_plan())
    multisines = [s for s in PLAN.segments if s.kind == "multisine"]
    last = multisines[-1]
    before = [s for s in multisines if (s.level, s.realization) != (last.level, last.realization)][
        -1
    ]
    end_k = last.start_k + last.length - 1
    assert session.intake.assembler is not None
    assert end_k == session.intake.assembler.multisine_end_k < PLAN.total_samples - 1
    # A realization before the last: an online refit.
    _feed(session, range(before.start_k + before.length))
    session.on_segment(_end(before))
    session.on_timer()
    session.on_timer()
    assert final_models == [False]
    # The last one: the final models, fitted while the sines after it stream.
    _feed(session, range(before.start_k + before.length, end_k + 1))
    session.on_segment(_end(last))
    with caplog.at_level(logging.INFO, logger=LOGGER):
        session.on_timer()
    assert calls[-1] == (False, False) and final_models[-1] is True
    assert caplog.records[-1].getMessage().endswith("complete) [final models]")
    if anomaly_meanwhile:  # may exclude periods those models were fitted on
        anomaly = Anomaly("lift/invalid/1", "lift", "invalid", _stamp(5), None)
        session.on_anomaly(AnomalyMsg(**anomaly.to_fields()))  # as the node takes it
    session.on_timer()  # collects it
    assert session.schedule.models_stale is anomaly_meanwhile
    # The plan's end: the final identification validates those models, or fits afresh.
    _feed(session, range(end_k + 1, PLAN.total_samples))
    session.on_segment({"event": "plan_end", "samples": PLAN.total_samples})
    session.on_timer()
    assert calls[-1] == (True, anomaly_meanwhile is False) and final_models[-1] is False
    session.on_timer()
    assert session.final_done and outputs.stops == [0]


def test_a_final_identification_waiting_for_a_running_refit_says_so_once(
    stubbed: tuple[IdentificationSession, Outputs, list[Any]], caplog: Any
) -> None:
    session, outputs, calls = stubbed
    session.job = RefitJob(Future(), "level 1 realization 1 complete", False, time.monotonic(), 0)
    session.on_segment({"event": "plan_end", "samples": PLAN.total_samples})
    with caplog.at_level(logging.INFO, logger=LOGGER):
        _feed(session, range(PLAN.total_samples - 1))
        session.on_timer()  # its data are not all in
        _feed(session, [PLAN.total_samples - 1])
        session.on_timer()
        session.on_timer()
    said = [r.getMessage() for r in caplog.records if "final identification" in r.getMessage()]
    assert said == ["the final identification's data are in: it starts when refit 1 is done"]
    assert calls == [] and not session.final_done and outputs.stops == []


def test_an_adaptive_run_fits_no_final_models_before_its_end(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Its plan may still grow: a realization may be added after the last one planned."""
    calls: list[tuple[bool, bool]] = []
    final_models: list[bool] = []
    monkeypatch.setattr(refit_worker, "refit", _stub_refit(calls, final_models=final_models))
    session = _session(Outputs(), adaptive=True)
    session.on_plan(_plan(BOUNDS))
    last = [s for s in PLAN.segments if s.kind == "multisine"][-1]
    _feed(session, range(last.start_k + last.length))
    session.on_segment(_end(last))
    session.on_timer()
    assert calls == [(False, False)] and final_models == [False]


def test_a_dead_worker_is_replaced_and_its_job_queued_again() -> None:
    outputs = Outputs()
    session = _session(outputs)
    session.on_plan(_plan())
    restarts: list[bool] = []

    class DeadWorker:
        executor = object()  # a worker process (not inline)

        def restart(self) -> None:
            restarts.append(True)

    session.worker = DeadWorker()  # type: ignore[assignment]
    session.schedule.models_stale = False
    died: Future[Any] = Future()
    died.set_exception(BrokenProcessPool("killed"))
    session.job = RefitJob(died, "second", False, time.monotonic(), 0)
    session.collect()
    assert restarts == [True] and session.job is None and session.refits == 0
    assert session.errors[-1].startswith("refit failed (second): ")
    assert session.schedule.models_stale  # the new worker has no models
    assert session.schedule.pending == [PendingRefit(-1, False, "second", True)]
    assert outputs.statuses == 1 and outputs.models == []
    # A refit that failed by itself is not queued again.
    failed: Future[Any] = Future()
    failed.set_exception(ValueError("bad data"))
    session.job = RefitJob(failed, "third", True, time.monotonic(), 0)
    session.collect()
    assert restarts == [True] and len(session.schedule.pending) == 1
    assert session.errors[-1] == "refit failed (third): ValueError: bad data"


def test_an_anomaly_during_the_final_identification_runs_it_again(
    stubbed: tuple[IdentificationSession, Outputs, list[Any]],
) -> None:
    session, outputs, calls = stubbed
    session.start_refit(True, "plan end")
    session.on_anomaly(Anomaly("lift/invalid/1", "lift", "invalid", _stamp(3000), None))
    session.collect()
    assert not session.final_done and outputs.stops == []
    assert session.schedule.pending == [
        PendingRefit(-1, True, "anomaly during the final identification", True)
    ]
    session.on_timer()  # the final identification again, fitted afresh on the anomaly too
    session.on_timer()
    assert calls == [(True, False), (True, False)]
    assert session.final_done and outputs.stops == [0]


# -- adaptive runs -----------------------------------------------------------------------------
def test_the_rules_are_given_the_levels_valid_periods_so_far() -> None:
    asm = CampaignAssembler(PLAN, T0)
    session = _session(Outputs())
    session.intake.begin(asm)
    first = _segment(PLAN, "multisine", 0, 0, 0).start_k
    second = _segment(PLAN, "multisine", 0, 1, 0).start_k
    broken = _segment(PLAN, "multisine", 0, 0, 1).start_k + 7
    _feed(session, [k for k in range(first, first + 8000) if k != broken])
    _feed(session, range(second, second + 4000))
    # The first realization so far: no other to compare with.
    only = level_so_far(asm, 0, 0, 2)
    assert only.current.P == 2 and only.level_data is None and only.earlier_periods == 0
    assert only.realization_periods == 4 and only.planned_realizations == 2
    assert only.rank == (0, 2)
    block = asm.blocks[(0, 0)]
    np.testing.assert_array_equal(only.current.u[:, :, 0], block.u[:, [0, 2]])
    # The second realization after its period 1: two valid periods of each, the first
    # realization's latest two (period 1 lacks a sample).
    both = level_so_far(asm, 0, 1, 1)
    assert both.earlier_periods == 3 and both.current.P == 2
    assert both.level_data is not None and both.level_data.M == 2 and both.level_data.P == 2
    np.testing.assert_array_equal(both.level_data.period_index, [[2, 0], [3, 1]])
    np.testing.assert_array_equal(both.level_data.y[:, :, 0], block.y[:, [2, 3]])
    np.testing.assert_array_equal(both.current.excited_lines, both.level_data.excited_lines)
    high = _segment(PLAN, "multisine", 1, 0, 0)
    _feed(session, range(high.start_k, high.start_k + high.length))
    assert level_so_far(asm, 1, 0, 0).rank == (1, 2)  # the higher offset of two levels


def test_an_adaptive_session_judges_each_period_once_its_data_are_in(caplog: Any) -> None:
    outputs = Outputs()
    session = _session(outputs, adaptive=True)
    adaptation = {"min_periods": 2, "min_realizations": 3, "max_realizations": 4}
    session.on_plan(_plan(adaptation))
    assert session.judge is not None and session.judge.bounds.min_realizations == 3
    periods = [_segment(PLAN, "multisine", 0, 0, p) for p in (0, 1)]
    for segment in periods:
        session.on_segment(_end(segment))
    assert [p.period for p in session.judge.to_judge] == [0, 1]
    end_0 = periods[0].start_k + periods[0].length - 1
    end_1 = periods[1].start_k + periods[1].length - 1
    _feed(session, range(end_0 + 1))
    with caplog.at_level(logging.INFO, logger=LOGGER):
        session.on_timer()
        assert outputs.requests == [PlanRequest("go_on", 0, end_0, "1 of at least 2 periods")]
        _feed(session, range(end_0 + 1, end_1 + 1))
        session.on_timer()
    # Noise-free and linear: the realization ends after its second period; the level's
    # verdict on the same periods follows (more=True on the first), below its floor.
    end, level = outputs.requests[1:]
    assert (end.action, end.after_k, end.more) == ("end_realization", end_1, True)
    assert level == PlanRequest("go_on", 0, end_1, "1 realization(s): the floor is 3", False)
    messages = [r.getMessage() for r in caplog.records]
    assert messages[0] == "level 0 realization 0 period 0: go on (1 of at least 2 periods)"
    assert messages[1].startswith("level 0 realization 0 period 1: end realization (noise ")
    assert caplog.records[1].levelno == logging.WARNING


def test_rules_that_fail_leave_the_generator_going_on(caplog: Any) -> None:
    outputs = Outputs()
    session = _session(outputs, adaptive=True)
    session.on_plan(_plan(BOUNDS))
    assert session.judge is not None and session.intake.assembler is not None
    with caplog.at_level(logging.ERROR, logger=LOGGER):
        session.send_verdicts(session.intake.assembler, PeriodToJudge(10, 0, 9, 0))
    (request,) = outputs.requests
    assert request.action == "go_on" and request.reason.startswith("rules failed: KeyError")
    assert caplog.records[0].getMessage().startswith("adaptive rules failed on level 0: KeyError")


def test_a_request_that_cannot_be_sent_leaves_the_later_periods_waiting() -> None:
    outputs = Outputs()
    session = _session(outputs, adaptive=True)
    session.on_plan(_plan(BOUNDS))
    periods = [_segment(PLAN, "multisine", 0, 0, p) for p in (0, 1)]
    for segment in periods:
        session.on_segment(_end(segment))
    _feed(session, range(periods[1].start_k + periods[1].length))
    sent = outputs.send_request

    def fails_once(request: PlanRequest) -> None:
        outputs.send_request = sent  # type: ignore[method-assign]
        raise RuntimeError("service client gone")

    outputs.send_request = fails_once  # type: ignore[method-assign]
    with pytest.raises(RuntimeError, match="service client gone"):
        session.on_timer()
    assert session.judge is not None
    assert [p.period for p in session.judge.to_judge] == [1]  # not lost with the first
    session.on_timer()
    assert outputs.requests  # period 1's verdicts, sent
    assert {r.after_k for r in outputs.requests} == {periods[1].start_k + periods[1].length - 1}


def test_an_adaptive_session_says_once_that_the_generator_takes_no_requests(
    caplog: Any,
) -> None:
    """The plan of a generator whose parameter adaptive is false has no bounds: every request
    will be refused (generator_node.NOT_ADAPTIVE), an error in the status."""
    session = _session(Outputs(), adaptive=True)
    with caplog.at_level(logging.ERROR, logger=LOGGER):
        session.on_plan(_plan())
        session.on_plan(_plan())
    (record,) = caplog.records
    assert record.getMessage().startswith("the generator does not run adaptively")
    level, values = session.status([])
    assert level == 2 and values["errors"] == record.getMessage()
    fixed = _session(Outputs())
    fixed.on_plan(_plan())
    assert not fixed.errors


def test_a_fixed_plan_run_judges_nothing() -> None:
    session = _session(Outputs())
    session.on_plan(_plan())
    session.on_segment(_end(_segment(PLAN, "multisine", 0, 0, 0)))
    assert session.judge is None

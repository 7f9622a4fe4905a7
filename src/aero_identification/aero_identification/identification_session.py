"""The identifier's work, without ROS: intake, refit schedule, adaptive judging, the refit
worker and the status.

identifier_node.py is the rclpy shell around :class:`IdentificationSession`: it declares the
parameters, subscribes the topics, hands the session each message (the plan and anomaly
messages as they come, a segment event as its payload), runs its timer, and publishes what the
session gives it (:class:`SessionOutputs`). The parts:

- :class:`Intake`: the plan's samples and anomalies, aligned into its periods (period_assembly.py),
  held while the plan is not there yet; holes in the plan index are named as they open.
- :class:`RefitSchedule`: refits waiting for their data (:class:`PendingRefit`).
- :class:`RefitWorker`: the worker process the refits run in, and its restart.
- :class:`AdaptiveJudge`: an adaptive run's verdict after each measured multisine period.

Logs go to the logger given (the node's, whose records reach /rosout).
"""

import json
import logging
import multiprocessing
import time
import traceback
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple, Protocol

from multisine_gen.plan import PlanError
from multisine_gen.plan_format import read_plan_message
from multisine_gen.revision import PlanRequest
from rig_runtime.anomaly import Anomaly
from rig_runtime.interface import EXPERIMENT_PLAN, PITCH_STATE, WING_COEFFICIENTS

from . import adaptive, model_payload, refit_worker
from .campaign_source import level_so_far
from .hyperparameters import IdentificationConfig
from .identifier_settings import IdentifierSettings
from .period_assembly import CampaignAssembler
from .quality import data_quality_lines

RefitOutcome = tuple[dict[str, Any], dict[str, Any]]  # refit_worker.refit's (payload, summary)

MAX_LOGGED_GAPS = 10  # gaps logged one by one per channel; the status counts them all


class PendingRefit(NamedTuple):
    """A refit that waits until both channels have reached plan sample ``needed_k``."""

    needed_k: int  # -1: at once (its data are in)
    final: bool  # the final identification (the report)
    reason: str  # logged, and published with the models
    new_data: bool  # new multisine data: the models must be refitted, not only validated


class PeriodToJudge(NamedTuple):
    """An adaptive run's measured multisine period, judged once both channels have it."""

    end_k: int  # its last plan sample
    level: int
    realization: int
    period: int


class SessionOutputs(Protocol):
    """What the session hands its node to publish, and the node's stop."""

    def publish_model(self, payload: dict[str, Any], stamp_ns: int) -> None:
        """The models of a refit; ``stamp_ns``: the last plan sample its data had."""

    def publish_status(self) -> None: ...

    def send_request(self, request: PlanRequest) -> None: ...

    def stop(self, exit_code: int) -> None: ...


def refit_after(event: dict[str, Any], assembler: CampaignAssembler) -> PendingRefit | None:
    """The refit a ``/experiment/segment`` event makes due: the final one at the plan's end
    or abort, one after each completed multisine realization (also one the adaptive rules
    ended early) and one after each sine test (validation only: the models are unchanged)."""
    kind = event.get("event")
    if kind == "plan_end":
        return PendingRefit(int(event["samples"]) - 1, True, "plan end", False)
    if kind == "plan_aborted":
        return PendingRefit(int(event["samples"]) - 1, True, "plan aborted", True)
    if kind in ("decision", "refused"):
        if event.get("request") == "end_realization" and "from_k" in event:
            # The realization ended at the period just judged: its refit is due now.
            after_k = int(event["after_k"])
            if int(event["from_k"]) == after_k + 1:
                seg = assembler.plan.segment_at(after_k)
                reason = f"level {seg.level} realization {seg.realization} complete"
                return PendingRefit(after_k, False, reason, True)
        return None
    if kind == "end" and event.get("kind") == "multisine":
        level, real = int(event["level"]), int(event["realization"])
        block = assembler.blocks.get((level, real))
        if block is not None and int(event.get("period", -1)) == block.P - 1:
            end_k = int(event["start_k"]) + int(event["length"]) - 1
            return PendingRefit(end_k, False, f"level {level} realization {real} complete", True)
        return None
    if kind == "end" and event.get("kind") == "sine":
        end_k = int(event["start_k"]) + int(event["length"]) - 1
        reason = f"sine {event.get('frequency_hz')} Hz at {event.get('offset_deg')}°"
        return PendingRefit(end_k, False, reason, False)
    return None


def period_to_judge(event: dict[str, Any]) -> PeriodToJudge | None:
    """The multisine period a ``/experiment/segment`` end event reports as measured."""
    if not (event.get("event") == "end" and event.get("kind") == "multisine"):
        return None
    if event.get("period") is None:
        return None
    end_k = int(event["start_k"]) + int(event["length"]) - 1
    level, real = int(event["level"]), int(event["realization"])
    return PeriodToJudge(end_k, level, real, int(event["period"]))


class Intake:
    """The samples and anomalies as they arrive, into the plan's periods (CampaignAssembler).

    Before the plan, up to ``max_early_samples()`` samples wait for it; the rest are counted
    and reported when it comes, never silently dropped.
    """

    def __init__(self, logger: logging.Logger, max_early_samples: Callable[[], int]) -> None:
        self.logger = logger
        self.max_early_samples = max_early_samples  # live: ros2 param set
        self.assembler: CampaignAssembler | None = None
        self.early: list[tuple[str, int, float]] = []
        self.early_dropped = 0
        self.early_anomalies: list[Anomaly] = []
        self.anomalies_received = 0
        self.samples = {"u": 0, "y": 0}
        self.last_k = {"u": -1, "y": -1}
        # Holes in the plan sample index per channel, as they open (first k, last k): samples a
        # writer dropped (this reader paused past the DDS lease, a writer that vanished and came
        # back) or lost. Logged at once and in the next status (1 s); never patched: the final
        # identification excludes what they touch, and the campaign recovers them from the bag.
        self.gaps: dict[str, list[tuple[int, int]]] = {"u": [], "y": []}

    @property
    def have(self) -> int:
        """The last plan sample both channels have reached."""
        return min(self.last_k["u"], self.last_k["y"])

    def begin(self, assembler: CampaignAssembler) -> None:
        """Take the plan's assembler, and give it what arrived before it."""
        self.assembler = assembler
        for channel, stamp, value in self.early:
            self.add(channel, stamp, value)
        self.early.clear()
        for anomaly in self.early_anomalies:
            self.add_anomaly(anomaly)
        self.early_anomalies.clear()

    def add(self, channel: str, stamp: int, value: float) -> None:
        """One sample of channel ``u`` (pitch [deg]) or ``y`` (C_l), stamped [ns]."""
        if self.assembler is None:
            if len(self.early) < self.max_early_samples():
                self.early.append((channel, stamp, value))
            else:
                self.early_dropped += 1  # reported when the plan comes: never silently
            return
        self.assembler.add(channel, stamp, value)
        self.samples[channel] += 1
        k = self.assembler.index_of(stamp)
        if k > self.last_k[channel] + 1 and 0 <= k < self.assembler.total:
            self._gap(channel, self.last_k[channel] + 1, k - 1)
        self.last_k[channel] = max(self.last_k[channel], k)

    def add_anomaly(self, anomaly: Anomaly) -> bool:
        """Exclude what the anomaly touches (True), or keep it for the plan (False)."""
        if self.assembler is None:
            self.early_anomalies.append(anomaly)
            return False
        self.assembler.add_anomaly(anomaly.id, anomaly.first_ns, anomaly.last_ns, anomaly.label())
        self.anomalies_received += 1
        return True

    def _gap(self, channel: str, first: int, last: int) -> None:
        gaps = self.gaps[channel]
        gaps.append((first, last))
        topic = PITCH_STATE.name if channel == "u" else WING_COEFFICIENTS.name
        if len(gaps) <= MAX_LOGGED_GAPS:
            self.logger.warning(
                "%s: plan samples %d..%d (%d) never arrived before sample %d: dropped by the "
                "writer (this node paused past the DDS lease?) or lost; the recorder's bag may "
                "hold them%s",
                topic, first, last, last - first + 1, last + 1,
                "" if len(gaps) < MAX_LOGGED_GAPS else " (further gaps: in the status only)",
            )  # fmt: skip


class RefitSchedule:
    """Refits waiting for their data; one refit covers every one that is ready."""

    def __init__(self) -> None:
        self.pending: list[PendingRefit] = []
        self.models_stale = True  # new periods, an anomaly, a revision: fit afresh, not reuse
        # How often an anomaly or a revision made the models stale: one that comes while a
        # refit runs on the data before it leaves them stale after that refit too.
        self.changes = 0

    def mark_stale(self) -> None:
        self.models_stale = True
        self.changes += 1

    def add(self, refit: PendingRefit) -> None:
        self.pending.append(refit)

    def take_ready(self, have: int) -> PendingRefit | None:
        """The refits whose data are in (both channels at ``have``) as one, or None: final if
        any is, their reasons joined, new data if any has."""
        ready = [r for r in self.pending if r.needed_k <= have]
        if not ready:
            return None
        merged = PendingRefit(
            max(r.needed_k for r in ready),
            any(r.final for r in ready),
            "; ".join(r.reason for r in ready),
            any(r.new_data for r in ready),
        )
        self.models_stale |= merged.new_data
        self.pending = [r for r in self.pending if r.needed_k > have]
        return merged


@dataclass
class RefitJob:
    """The refit running now."""

    future: "Future[RefitOutcome]"
    reason: str
    final: bool
    started: float  # time.monotonic() when it was submitted
    anomalies: int  # anomalies its data snapshot includes (Intake.anomalies_received)
    changes: int = 0  # RefitSchedule.changes when it was submitted
    stamp_ns: int = 0  # the stamp of the last plan sample both channels had at its submission


class RefitWorker:
    """The one process the refits run in (spawned), so that intake never stalls; or none
    (``use_worker`` false): each refit runs inline, for debugging."""

    def __init__(self, use_worker: bool) -> None:
        self.executor: ProcessPoolExecutor | None = None
        if use_worker:
            self.start()

    def start(self) -> None:
        self.executor = ProcessPoolExecutor(
            max_workers=1,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=refit_worker.exit_with_parent,
        )
        # Start the worker now: its imports and compiled kernels load while the first
        # realization streams in, not inside the first refit. A failure shows at the refit.
        self.executor.submit(refit_worker.warm_up)

    def submit(
        self,
        assembler: CampaignAssembler,
        config: IdentificationConfig,
        final: bool,
        out_dir: str,
        reuse: bool,
        final_models: bool = False,
    ) -> "Future[RefitOutcome]":
        """refit_worker.refit in the worker; inline, a future that is already done."""
        args = (assembler, config, final, out_dir, reuse, final_models)
        if self.executor is not None:
            return self.executor.submit(refit_worker.refit, *args)
        done: Future[RefitOutcome] = Future()
        try:
            done.set_result(refit_worker.refit(*args))
        except Exception as exc:
            done.set_exception(exc)
        return done

    def restart(self) -> None:
        """A new worker after the old one died (killed, out of memory)."""
        assert self.executor is not None
        self.executor.shutdown(wait=False, cancel_futures=True)
        self.start()

    def close(self, idle: bool) -> None:
        if self.executor is not None:
            # Idle (the final identification done): wait for the worker, so that the
            # executor's manager thread has closed its wakeup pipe before the interpreter's
            # exit hook writes to it (CPython 3.11's concurrent.futures.process._python_exit
            # raced with it: "Exception ignored ... Bad file descriptor"). A refit still
            # running is cancelled without waiting for it.
            self.executor.shutdown(wait=idle, cancel_futures=True)


class AdaptiveJudge:
    """An adaptive run's rules (adaptive.py) after each measured multisine period: the
    periods waiting to be judged, the generator's bounds (from the plan message) and, per
    level, the BLA's errors on its newest realizations (the model-convergence rule)."""

    def __init__(self, rules: adaptive.AdaptiveRules, logger: logging.Logger) -> None:
        self.rules = rules
        self.logger = logger
        self.bounds = adaptive.Bounds()
        self.to_judge: list[PeriodToJudge] = []
        self.bla_errors: dict[int, list[float]] = {}

    def next_ready(self, have: int) -> PeriodToJudge | None:
        """The oldest period both channels have reached (``have``), taken; None if none has.
        One at a time: a period whose request cannot be sent leaves the later ones waiting."""
        if self.to_judge and self.to_judge[0].end_k <= have:
            return self.to_judge.pop(0)
        return None

    def verdicts(self, assembler: CampaignAssembler, item: PeriodToJudge) -> list[adaptive.Verdict]:
        """The verdict on the period; when it ends the realization, the level's verdict on the
        same periods after it. A failure of the rules is logged and becomes go on."""
        level, realization, period = item.level, item.realization, item.period
        try:
            verdicts = [self.verdict(assembler, level, realization, period)]
            if verdicts[0].action == "end_realization":
                # The realization ends here: the level's verdict too, on the same periods.
                verdicts.append(self.verdict(assembler, level, realization, period, last=True))
        except Exception as exc:  # the rules must never leave the generator waiting
            detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
            self.logger.error("adaptive rules failed on level %d: %s", level, detail)
            verdicts = [adaptive.Verdict("go_on", f"rules failed: {detail}")]
        return verdicts

    def verdict(
        self,
        assembler: CampaignAssembler,
        level: int,
        realization: int,
        period: int,
        last: bool = False,
    ) -> adaptive.Verdict:
        """The rules on the level's valid periods up to this one; ``last``: judge it as the
        realization's last period (it ends here)."""
        so_far = level_so_far(assembler, level, realization, period)
        position = adaptive.PeriodPosition(
            periods_done=period + 1,
            last_period=last or period == so_far.realization_periods - 1,
            realization=realization,
            planned_realizations=so_far.planned_realizations,
            rank=so_far.rank,
            earlier_periods=so_far.earlier_periods,
        )
        errors = self.bla_errors.setdefault(level, [])
        return adaptive.judge_period(
            so_far.current, so_far.level_data, position, self.rules, self.bounds, errors
        )


class IdentificationSession:
    """One identifier run: intake, refits as their data come in, the adaptive rules in an
    adaptive run, and the final identification; its status as diagnostic values."""

    def __init__(
        self,
        settings: IdentifierSettings,
        logger: logging.Logger,
        outputs: SessionOutputs,
        *,
        max_early_samples: Callable[[], int],
        exit_after_final: Callable[[], bool],
    ) -> None:
        self.settings = settings
        self.logger = logger
        self.outputs = outputs
        self.exit_after_final = exit_after_final  # live: ros2 param set
        self.intake = Intake(logger, max_early_samples)
        self.schedule = RefitSchedule()
        self.judge = AdaptiveJudge(settings.rules, logger) if settings.adaptive else None
        self.worker = RefitWorker(settings.use_worker)
        self.job: RefitJob | None = None
        self.refits = 0
        self.refit_times: list[float] = []
        self.last_summary: dict[str, Any] | None = None
        self.errors: list[str] = []
        self.final_done = False
        self.final_waits_said = False  # logged once: the final's data are in, a refit runs
        self.not_adaptive_said = False  # logged once: the generator takes no requests

    # -- intake ---------------------------------------------------------------------------
    def on_plan(self, msg: Any) -> None:
        """A ``/experiment/plan`` message (aero_rig_interfaces/ExperimentPlan, the std_msgs/String
        of a bag recorded before it, or its JSON text): the plan, or a revision of the running
        one."""
        try:
            plan, t0_ns = read_plan_message(msg)
        except PlanError as exc:
            self.logger.error("%s: %s; stopping", EXPERIMENT_PLAN.name, exc)
            self.outputs.stop(1)
            return
        text = msg if isinstance(msg, str) else getattr(msg, "plan_json", getattr(msg, "data", ""))
        # The generator's bounds, published only in an adaptive run (generator_node.py).
        adaptation = json.loads(text).get("adaptation")
        if self.judge is not None and adaptation:
            self.judge.bounds = adaptive.Bounds.from_dict(adaptation)
        elif self.judge is not None and not self.not_adaptive_said:
            self.not_adaptive_said = True
            self.errors.append(
                "the generator does not run adaptively (its parameter adaptive is false): it "
                "refuses every request and plays its plan as designed"
            )
            self.logger.error("%s", self.errors[-1])
        asm = self.intake.assembler
        if asm is not None and t0_ns == asm.t0_ns:
            if plan.revision > asm.plan.revision:
                try:
                    asm.revise(plan)
                except ValueError as exc:
                    self.errors.append(f"{EXPERIMENT_PLAN.name}: {exc}")
                    self.logger.error("%s; the previous revision is kept", self.errors[-1])
                    return
                self.schedule.mark_stale()
                self.logger.info(
                    "plan revision %d: %d samples (%.1f s), %d multisine blocks",
                    plan.revision,
                    plan.total_samples,
                    plan.duration_s,
                    len(asm.blocks),
                )
            return
        asm = CampaignAssembler(plan, t0_ns)
        self.logger.info(
            "plan received: %d segments, %d multisine blocks, %d sine tests",
            len(plan.segments),
            len(asm.blocks),
            len(asm.sines),
        )
        self.intake.begin(asm)
        if self.intake.early_dropped:
            self.errors.append(
                f"{self.intake.early_dropped} samples arrived before the plan and were dropped "
                f"(max_early_samples = {self.intake.max_early_samples()})"
            )
            self.logger.error("%s", self.errors[-1])

    def on_anomaly(self, msg: Any) -> None:
        """An ``/experiment/anomaly`` record (rig_runtime.anomaly): an Anomaly, its message
        (aero_rig_interfaces/Anomaly, or the std_msgs/String of an older bag) or its JSON."""
        try:
            if isinstance(msg, Anomaly):
                anomaly = msg
            elif isinstance(msg, str):
                anomaly = Anomaly.from_json(msg)
            else:
                anomaly = Anomaly.from_message(msg)
        except ValueError as exc:
            self.logger.error("%s", exc)
            return
        if self.intake.add_anomaly(anomaly):
            self.schedule.mark_stale()  # periods may be excluded now: fit afresh

    def on_segment(self, event: dict[str, Any]) -> None:
        """An ``/experiment/segment`` event: decisions, periods to judge, refits due."""
        asm = self.intake.assembler
        if asm is None:
            return
        if event.get("event") in ("decision", "refused"):
            asm.decisions.append(event)
        if self.judge is not None and (period := period_to_judge(event)) is not None:
            self.judge.to_judge.append(period)
        refit = refit_after(event, asm)
        if refit is not None:
            self.schedule.add(refit)

    # -- the timer: results, verdicts, refits -----------------------------------------------
    def on_timer(self) -> None:
        if self.job is not None and self.job.future.done():
            self.collect()
        asm = self.intake.assembler
        if self.judge is not None and asm is not None:
            while (item := self.judge.next_ready(self.intake.have)) is not None:
                self.send_verdicts(asm, item)
        if self.job is not None and not self.final_waits_said:
            if any(r.final and r.needed_k <= self.intake.have for r in self.schedule.pending):
                self.final_waits_said = True
                self.logger.info(
                    "the final identification's data are in: it starts when refit %d is done",
                    self.refits + 1,
                )
        if self.job is not None or asm is None:
            return
        ready = self.schedule.take_ready(self.intake.have)
        if ready is not None:
            self.start_refit(ready.final, ready.reason)

    def send_verdicts(self, assembler: CampaignAssembler, item: PeriodToJudge) -> None:
        """Judge the level after one measured period and send the generator its request."""
        assert self.judge is not None
        verdicts = self.judge.verdicts(assembler, item)
        for i, verdict in enumerate(verdicts):
            more = i < len(verdicts) - 1
            request = PlanRequest(verdict.action, item.level, item.end_k, verdict.reason, more)
            self.outputs.send_request(request)
            log = self.logger.info if verdict.action == "go_on" else self.logger.warning
            log(
                "level %d realization %d period %d: %s (%s)",
                item.level,
                item.realization,
                item.period,
                verdict.action.replace("_", " "),
                verdict.reason,
            )

    def start_refit(self, final: bool, reason: str) -> None:
        asm = self.intake.assembler
        assert asm is not None
        started = time.monotonic()
        # Only sines completed since the last refit: the worker keeps its models and validates
        # them again.
        reuse = not self.schedule.models_stale and self.refits > 0
        # Every multisine period of a fixed plan is in (an adaptive run's plan may still grow):
        # the final models are fitted now, while the last sines stream, and the final job
        # validates them (pipeline.identify's final_models).
        final_models = (
            not final and self.judge is None and 0 <= asm.multisine_end_k <= self.intake.have
        )
        self.logger.info(
            "%s %d (%s)%s",
            "validation" if reuse else "refit",
            self.refits + 1,
            reason,
            " [final]" if final else " [final models]" if final_models and not reuse else "",
        )
        anomalies = self.intake.anomalies_received
        last_k = min(max(self.intake.have, 0), asm.total - 1)
        stamp_ns = asm.t0_ns + round(last_k * asm.period_ns)
        future = self.worker.submit(
            asm, self.settings.config, final, self.settings.output_dir, reuse, final_models
        )
        self.job = RefitJob(
            future, reason, final, started, anomalies, self.schedule.changes, stamp_ns
        )

    def collect(self) -> None:
        """The finished refit's result: publish the models, or keep the previous ones."""
        job = self.job
        assert job is not None
        elapsed = time.monotonic() - job.started
        try:
            payload, summary = job.future.result()
        except Exception as exc:
            detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
            self.errors.append(f"refit failed ({job.reason}): {detail}")
            self.logger.error("%s; the previous models are kept", self.errors[-1])
            self.job = None
            if isinstance(exc, BrokenProcessPool) and self.worker.executor is not None:
                # The worker died: a new one, which fits afresh. The job it died in is queued
                # again (at once: its data are in), so a final identification is never lost.
                self.worker.restart()
                self.schedule.models_stale = True
                self.schedule.add(PendingRefit(-1, job.final, job.reason, True))
            self.outputs.publish_status()
            return
        self.job = None
        self.schedule.models_stale = self.schedule.changes != job.changes
        self.refits += 1
        self.refit_times.append(elapsed)
        self.last_summary = summary
        refit_worker.release_memory()  # the pickled job and its answer
        payload[model_payload.REFIT] = self.refits
        payload["refit_s"] = elapsed
        payload["reason"] = job.reason
        self.outputs.publish_model(payload, job.stamp_ns)
        worker = summary["worker"]
        self.logger.info(
            "refit %d done in %.2f s (%s; worker CPU %.2f s, resident %.0f MB at start, "
            "peak %.0f MB; node %.0f MB); %d warning(s)",
            self.refits,
            elapsed,
            ", ".join(f"{k} {v:.2f} s" for k, v in summary["timings_s"].items()),
            worker["cpu_s"],
            worker["start_mb"],
            worker["peak_mb"],
            refit_worker.status_mb("VmRSS"),
            len(summary["warnings"]),
        )
        for warning in summary["warnings"]:
            self.logger.warning("%s", warning)
        if summary["complete"] and self.intake.anomalies_received != job.anomalies:
            # An anomaly came in while the final identification ran on the data before it:
            # run it again, so the report names (and excludes) what the anomaly touches.
            self.logger.warning(
                "%d anomaly record(s) arrived during the final identification: running it again",
                self.intake.anomalies_received - job.anomalies,
            )
            self.schedule.add(
                PendingRefit(-1, True, "anomaly during the final identification", True)
            )
            self.outputs.publish_status()
            return
        if summary["complete"]:
            self.final_done = True
            if summary["written"]:
                out_dir = Path(self.settings.output_dir).resolve()
                self.logger.info("report written to %s", out_dir)
            self.logger.info(
                "final Table 1 (trained on all levels):\n%s", payload["table1"]["markdown"]
            )
            problems = data_quality_lines(summary.get("data_quality", {}))
            for line in problems:
                self.logger.error("data not clean: %s", line)
            if not problems:
                self.logger.info("data clean: every plan sample arrived once, no anomaly")
        self.outputs.publish_status()
        if summary["complete"] and self.exit_after_final():
            self.outputs.stop(0)

    # -- status ---------------------------------------------------------------------------
    def status(self, paused_s: list[float]) -> tuple[int, dict[str, str]]:
        """The diagnostic level (0 OK, 1 warn, 2 error) and values of ``/identification/status``;
        ``paused_s``: the node's pauses past the DDS lease (rig_runtime.node)."""
        intake = self.intake
        state = "done" if self.final_done else ("refitting" if self.job else "collecting")
        values: dict[str, str] = {
            "state": state,
            "refits": str(self.refits),
            "last_refit_s": f"{self.refit_times[-1]:.2f}" if self.refit_times else "",
            "max_refit_s": f"{max(self.refit_times):.2f}" if self.refit_times else "",
            "pitch_samples": str(intake.samples["u"]),
            "cl_samples": str(intake.samples["y"]),
        }
        if paused_s:
            values["stopped"] = (
                f"{len(paused_s)} time(s) past the DDS lease, last {paused_s[-1]:.1f} s"
            )
        for channel, name in (("u", "pitch"), ("y", "C_l")):
            gaps = intake.gaps[channel]
            if gaps:
                lost = sum(b - a + 1 for a, b in gaps)
                first, last = gaps[-1]
                values[f"{name} gaps"] = (
                    f"{len(gaps)} gap(s), {lost} plan samples never arrived (last {first}..{last})"
                )
        if intake.assembler is not None:
            for (level, real), block in sorted(intake.assembler.blocks.items()):
                valid = int(block.period_valid().sum())
                values[f"level {level} realization {real} valid periods"] = f"{valid}/{block.P}"
        excluded: list[str] = []
        if self.last_summary is not None:
            for lv in self.last_summary["levels"]:
                if lv["clusters"] is not None:
                    k, sizes = lv["clusters"]
                    values[f"{lv['name']} clusters"] = f"k={k}, sizes={sizes}"
                excluded += [f"{lv['name']}: {e}" for e in lv["excluded"]]
        if excluded:
            values["excluded periods"] = "; ".join(excluded)
        if self.errors:
            values["errors"] = "; ".join(self.errors[-3:])
        warnings = self.last_summary["warnings"] if self.last_summary else []
        if warnings:
            values["warnings"] = "; ".join(warnings)
        quality = self.last_summary.get("data_quality", {}) if self.last_summary else {}
        problems = data_quality_lines(quality)
        if quality:
            values["data"] = "clean" if not problems else f"NOT CLEAN: {len(problems)} problem(s)"
            for name, c in quality.get("samples", {}).items():
                values[f"{name} plan samples"] = (
                    f"{c['received']}/{c['expected']} once, {c['missing']} missing, "
                    f"{c['duplicated']} duplicated"
                )
        if quality.get("anomalies"):
            values["anomalies"] = "; ".join(quality["anomalies"])
        if quality.get("excluded_sines"):
            values["excluded sine records"] = "; ".join(quality["excluded_sines"])
        gapped = any(intake.gaps.values()) or bool(paused_s)
        level = 2 if self.errors else (1 if excluded or warnings or problems or gapped else 0)
        return level, values

    def close(self) -> None:
        self.worker.close(idle=self.job is None)

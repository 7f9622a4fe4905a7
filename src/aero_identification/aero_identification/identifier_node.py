"""Identifier node: buffers periods while the experiment runs and refits the models online.

Subscribes ``/experiment/plan`` (latched; gives t0 and the segments), ``/pitch/state``
(measured pitch -> input, degrees), ``/wing/coefficients`` (C_l -> output) and
``/experiment/segment``. Samples are aligned by stamp into the plan's periods (campaign.py);
periods with gaps, duplicates or invalid samples are excluded and reported. After every
completed multisine realization and every completed sine test it re-clusters and refits BLA,
BLA state space and PNLSS (pipeline.py) in a worker process, so intake never stalls, and
publishes ``/identification/model`` (JSON, latched) and ``/identification/status``
(DiagnosticArray, latched). After ``plan_end`` it runs the final identification, writes models
and the report (Table 1 Markdown/CSV, PNG figures) to ``output_dir`` and, with
``exit_after_final``, exits (the campaign's end).

Adaptive runs (``adaptive``; docs/design.md §7.9): after each measured multisine period the
node judges the level's periods so far by the stop and extend rules (adaptive.py) and sends
the generator a request on ``/experiment/control`` (end the realization, finish the level, add
a realization, go on; multisine_gen.revision). It follows the plan's revisions on
``/experiment/plan``, and models.json (``experiment``) gives the multisine time per level,
planned against executed, and every decision.

Data quality: ``/experiment/anomaly`` records (rig_runtime.anomaly) exclude the periods and sine
records they touch; every plan sample is accounted for on both channels. What was lost or
excluded is named in ``/identification/status``, ``models.json`` (``data_quality``), the
report (``data_quality.md``, and a note above Table 1) and the final log lines.
"""

import json
import math
import multiprocessing
import sys
import time
import traceback
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import numpy as np

from multisine_gen.plan import PlanError
from multisine_gen.plan_format import read_plan_message
from multisine_gen.revision import PlanRequest
from rig_runtime import Node, Parameter, run_node, stamp_to_ns
from rig_runtime.anomaly import Anomaly
from rig_runtime.diagnostics import diagnostic_array
from rig_runtime.interface import (
    EXPERIMENT_ANOMALY,
    EXPERIMENT_CONTROL,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_MODEL,
    IDENTIFICATION_STATUS,
    PITCH_JOINT,
    PITCH_STATE,
    WING_COEFFICIENTS,
    joint_position,
)

from . import adaptive, model_message, refit_worker
from .campaign import CampaignAssembler
from .campaign_dataset import equal_periods
from .config import config_from_parameters, config_parameters
from .data import PeriodicData
from .quality import data_quality_lines

RefitOutcome = tuple[dict[str, Any], dict[str, Any]]  # refit_worker.refit's (payload, summary)

TIMER_PERIOD_S = 0.1  # intake timer: refits start, worker results are collected
MAX_LOGGED_GAPS = 10  # gaps logged one by one per channel; the status counts them all

PARAMETERS = [
    Parameter("output_dir", "", "run directory for models.json and the report ('' = none)"),
    # The identification hyperparameters, declared with their ranges in config.py.
    *config_parameters(),
    # Adaptive runs: the switch and the rules' thresholds, declared in adaptive.py.
    *adaptive.PARAMETERS,
    Parameter("use_worker", True, "refit in a worker process (false: inline, for debugging)"),
    Parameter(
        "exit_after_final",
        True,
        "exit once the final identification is published (live: ros2 param set)",
        read_only=False,
    ),
    Parameter(
        "max_early_samples",
        20000,
        "samples kept while waiting for the plan (live: ros2 param set)",
        min=0,
        read_only=False,
    ),
    Parameter(
        "input_qos",
        "stream",
        "QoS of /pitch/state and /wing/coefficients (sensor on the rig: best effort)",
        choices=("stream", "sensor", "default"),
    ),
]


class Identifier:
    def __init__(self, node: Node) -> None:
        p = node.params
        self.node = node
        self.config = config_from_parameters(p.as_dict())
        self.out_dir = p["output_dir"]
        self.assembler: CampaignAssembler | None = None
        self.early: list[tuple[str, int, float]] = []
        self.early_dropped = 0
        self.early_anomalies: list[Anomaly] = []
        self.anomalies_received = 0
        self.anomalies_at_submit = 0  # anomalies the running refit's data snapshot includes
        self.last_k = {"u": -1, "y": -1}
        # Holes in the plan sample index per channel, as they open (first k, last k): samples a
        # writer dropped (this reader paused past the DDS lease, a writer that vanished and came
        # back) or lost. Logged at once and in the next status (1 s); never patched: the final
        # identification excludes what they touch, and the campaign recovers them from the bag.
        self.gaps: dict[str, list[tuple[int, int]]] = {"u": [], "y": []}
        # (needed k, final, reason, new multisine data: the models must be refitted)
        self.pending: list[tuple[int, bool, str, bool]] = []
        self.models_stale = True
        self.future: Future[RefitOutcome] | None = None
        self.future_reason = ""
        self.refit_started = 0.0
        self.refits = 0
        self.refit_times: list[float] = []
        self.last_summary: dict[str, Any] | None = None
        self.errors: list[str] = []
        self.final_done = False
        self.samples = {"u": 0, "y": 0}
        self.executor: ProcessPoolExecutor | None = None
        # Adaptive runs: the rules, the generator's bounds (from the plan message), the periods
        # waiting to be judged (end k, level, realization, period) and, per level, the BLA's
        # errors on its newest realizations (the model-convergence rule).
        self.rules = adaptive.AdaptiveRules.from_parameters(p.as_dict())
        self.bounds = adaptive.Bounds()
        self.to_judge: list[tuple[int, int, int, int]] = []
        self.bla_errors: dict[int, list[float]] = {}
        self.control_pub = (
            node.create_publisher(
                EXPERIMENT_CONTROL.type, EXPERIMENT_CONTROL.name, EXPERIMENT_CONTROL.qos
            )
            if p["adaptive"]
            else None
        )
        if p["use_worker"]:
            self._start_worker()
        self.model_pub = node.create_publisher(
            IDENTIFICATION_MODEL.type, IDENTIFICATION_MODEL.name, IDENTIFICATION_MODEL.qos
        )
        self.status_pub = node.create_publisher(
            IDENTIFICATION_STATUS.type, IDENTIFICATION_STATUS.name, IDENTIFICATION_STATUS.qos
        )
        node.create_subscription(
            EXPERIMENT_PLAN.type,
            EXPERIMENT_PLAN.name,
            self.on_plan,
            EXPERIMENT_PLAN.qos,
            required=True,
        )
        node.create_subscription(
            PITCH_STATE.type,
            PITCH_STATE.name,
            self.on_state,
            p["input_qos"],
            depth=None if p["input_qos"] == "stream" else 2000,
            required=True,
        )
        node.create_subscription(
            WING_COEFFICIENTS.type,
            WING_COEFFICIENTS.name,
            self.on_coefficients,
            p["input_qos"],
            depth=None if p["input_qos"] == "stream" else 2000,
            required=True,
        )
        node.create_subscription(
            EXPERIMENT_SEGMENT.type,
            EXPERIMENT_SEGMENT.name,
            self.on_segment,
            EXPERIMENT_SEGMENT.qos,
            required=True,
        )
        node.create_subscription(
            EXPERIMENT_ANOMALY.type,
            EXPERIMENT_ANOMALY.name,
            self.on_anomaly,
            EXPERIMENT_ANOMALY.qos,
        )
        self.future_final = False
        # A pause past the DDS lease (the node's pause watch, rig_runtime.node) is logged there
        # and goes into the next status at once; the holes it leaves follow as gaps.
        node.on_paused(lambda _seconds: self.publish_status())
        node.create_timer(TIMER_PERIOD_S, self.on_timer)
        node.create_timer(1.0, self.publish_status)
        self.publish_status()

    def _start_worker(self) -> None:
        self.executor = ProcessPoolExecutor(
            max_workers=1,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=refit_worker.exit_with_parent,
        )
        # Start the worker now: its imports and compiled kernels load while the first
        # realization streams in, not inside the first refit. A failure shows at the refit.
        self.executor.submit(refit_worker.warm_up)

    # -- intake ---------------------------------------------------------------------------
    def on_plan(self, msg: Any) -> None:
        try:
            plan, t0_ns = read_plan_message(msg.data)
        except PlanError as exc:
            self.node.logger.error("%s: %s; stopping", EXPERIMENT_PLAN.name, exc)
            self.node.request_shutdown(1)
            return
        adaptation = json.loads(msg.data).get("adaptation")
        if adaptation:
            self.bounds = adaptive.Bounds.from_dict(adaptation)
        if self.assembler is not None and t0_ns == self.assembler.t0_ns:
            if plan.revision > self.assembler.plan.revision:
                try:
                    self.assembler.revise(plan)
                except ValueError as exc:
                    self.errors.append(f"{EXPERIMENT_PLAN.name}: {exc}")
                    self.node.logger.error("%s; the previous revision is kept", self.errors[-1])
                    return
                self.models_stale = True
                self.node.logger.info(
                    "plan revision %d: %d samples (%.1f s), %d multisine blocks",
                    plan.revision,
                    plan.total_samples,
                    plan.duration_s,
                    len(self.assembler.blocks),
                )
            return
        self.assembler = CampaignAssembler(plan, t0_ns)
        self.node.logger.info(
            "plan received: %d segments, %d multisine blocks, %d sine tests",
            len(plan.segments),
            len(self.assembler.blocks),
            len(self.assembler.sines),
        )
        for channel, stamp, value in self.early:
            self._add(channel, stamp, value)
        self.early.clear()
        for anomaly in self.early_anomalies:
            self._add_anomaly(anomaly)
        self.early_anomalies.clear()
        if self.early_dropped:
            self.errors.append(
                f"{self.early_dropped} samples arrived before the plan and were dropped "
                f"(max_early_samples = {self.node.params['max_early_samples']})"
            )
            self.node.logger.error("%s", self.errors[-1])

    def on_anomaly(self, msg: Any) -> None:
        try:
            anomaly = Anomaly.from_json(msg.data)
        except ValueError as exc:
            self.node.logger.error("%s", exc)
            return
        if self.assembler is None:
            self.early_anomalies.append(anomaly)
        else:
            self._add_anomaly(anomaly)

    def _add_anomaly(self, anomaly: Anomaly) -> None:
        assert self.assembler is not None
        self.assembler.add_anomaly(anomaly.id, anomaly.first_ns, anomaly.last_ns, anomaly.label())
        self.anomalies_received += 1
        self.models_stale = True  # periods may be excluded now: the next refit fits afresh

    def _add(self, channel: str, stamp: int, value: float) -> None:
        if self.assembler is None:
            if len(self.early) < self.node.params["max_early_samples"]:
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

    def _gap(self, channel: str, first: int, last: int) -> None:
        gaps = self.gaps[channel]
        gaps.append((first, last))
        topic = PITCH_STATE.name if channel == "u" else WING_COEFFICIENTS.name
        if len(gaps) <= MAX_LOGGED_GAPS:
            self.node.logger.warning(
                "%s: plan samples %d..%d (%d) never arrived before sample %d: dropped by the "
                "writer (this node paused past the DDS lease?) or lost; the recorder's bag may "
                "hold them%s",
                topic, first, last, last - first + 1, last + 1,
                "" if len(gaps) < MAX_LOGGED_GAPS else " (further gaps: in the status only)",
            )  # fmt: skip

    def on_state(self, msg: Any) -> None:
        pitch = joint_position(msg, PITCH_JOINT)
        value = math.nan if pitch is None else math.degrees(pitch)
        self._add("u", stamp_to_ns(msg.header.stamp), value)

    def on_coefficients(self, msg: Any) -> None:
        self._add("y", stamp_to_ns(msg.header.stamp), float(msg.vector.x))

    def on_segment(self, msg: Any) -> None:
        event = json.loads(msg.data)
        if self.assembler is None:
            return
        kind = event.get("event")
        if kind == "plan_end":
            self.pending.append((int(event["samples"]) - 1, True, "plan end", False))
        elif kind == "plan_aborted":
            self.pending.append((int(event["samples"]) - 1, True, "plan aborted", True))
        elif kind in ("decision", "refused"):
            self.assembler.decisions.append(event)
            if event.get("request") == "end_realization" and "from_k" in event:
                # The realization ended at the period just judged: its refit is due now.
                after_k = int(event["after_k"])
                if int(event["from_k"]) == after_k + 1:
                    seg = self.assembler.plan.segment_at(after_k)
                    self.pending.append(
                        (
                            after_k,
                            False,
                            f"level {seg.level} realization {seg.realization} complete",
                            True,
                        )
                    )
        elif kind == "end" and event.get("kind") == "multisine":
            level, real = int(event["level"]), int(event["realization"])
            if self.control_pub is not None and event.get("period") is not None:
                end_k = int(event["start_k"]) + int(event["length"]) - 1
                self.to_judge.append((end_k, level, real, int(event["period"])))
            block = self.assembler.blocks.get((level, real))
            if block is not None and int(event.get("period", -1)) == block.P - 1:
                end_k = int(event["start_k"]) + int(event["length"]) - 1
                self.pending.append(
                    (end_k, False, f"level {level} realization {real} complete", True)
                )
        elif kind == "end" and event.get("kind") == "sine":
            end_k = int(event["start_k"]) + int(event["length"]) - 1
            self.pending.append(
                (
                    end_k,
                    False,
                    f"sine {event.get('frequency_hz')} Hz at {event.get('offset_deg')}°",
                    False,
                )
            )

    # -- refits ---------------------------------------------------------------------------
    def on_timer(self) -> None:
        if self.future is not None and self.future.done():
            self._collect()
        if self.to_judge and self.assembler is not None:
            have = min(self.last_k["u"], self.last_k["y"])
            while self.to_judge and self.to_judge[0][0] <= have:
                self._judge(*self.to_judge.pop(0))
        if self.future is not None or not self.pending or self.assembler is None:
            return
        have = min(self.last_k["u"], self.last_k["y"])
        ready = [item for item in self.pending if item[0] <= have]
        if not ready:
            return
        # One refit covers every realization completed so far; the final one wins.
        final = any(item[1] for item in ready)
        reason = "; ".join(item[2] for item in ready)
        self.models_stale |= any(item[3] for item in ready)
        self.pending = [item for item in self.pending if item[0] > have]
        self._start_refit(final, reason)

    # -- adaptive runs ----------------------------------------------------------------------
    def _judge(self, end_k: int, level: int, realization: int, period: int) -> None:
        """Judge the level after one measured period and send the generator its request."""
        assert self.assembler is not None and self.control_pub is not None
        try:
            verdicts = [self._verdict(level, realization, period)]
            if verdicts[0].action == "end_realization":
                # The realization ends here: the level's verdict too, on the same periods.
                verdicts.append(self._verdict(level, realization, period, last=True))
        except Exception as exc:  # the rules must never leave the generator waiting
            detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
            self.node.logger.error("adaptive rules failed on level %d: %s", level, detail)
            verdicts = [adaptive.Verdict("go_on", f"rules failed: {detail}")]
        for i, verdict in enumerate(verdicts):
            more = i < len(verdicts) - 1
            request = PlanRequest(verdict.action, level, end_k, verdict.reason, more)
            self.control_pub.publish(
                self.node.new_message(EXPERIMENT_CONTROL.type, data=request.to_json())
            )
            log = self.node.logger.info if verdict.action == "go_on" else self.node.logger.warning
            log(
                "level %d realization %d period %d: %s (%s)",
                level,
                realization,
                period,
                verdict.action.replace("_", " "),
                verdict.reason,
            )

    def _verdict(
        self, level: int, realization: int, period: int, last: bool = False
    ) -> adaptive.Verdict:
        """The rules on the level's valid periods up to this one; ``last``: judge it as the
        realization's last period (it ends here)."""
        assert self.assembler is not None
        asm = self.assembler
        plan_level = next(lv for lv in asm.plan.levels if lv.level == level)
        lines = np.asarray(plan_level.realizations[0].excited_lines)
        block = asm.blocks[(level, realization)]
        valid = np.flatnonzero(block.period_valid()[: period + 1])
        current = PeriodicData(block.u[:, valid, None], block.y[:, valid, None], asm.fs, lines)
        columns = [
            np.flatnonzero(asm.blocks[(level, m)].period_valid()) for m in range(realization)
        ]
        columns.append(valid)
        level_data = None
        if min(len(c) for c in columns) >= 2 and len(columns) >= 2:
            blocks = [asm.blocks[(level, m)] for m in range(realization + 1)]
            level_data = equal_periods(blocks, columns, asm.fs, lines)
        offsets = sorted(lv.offset_deg for lv in asm.plan.levels)
        return adaptive.judge_period(
            current,
            level_data,
            periods_done=period + 1,
            last_period=last or period == block.P - 1,
            realization=realization,
            planned_realizations=len(plan_level.realizations),
            rank=(offsets.index(plan_level.offset_deg), len(offsets)),
            rules=self.rules,
            bounds=self.bounds,
            errors=self.bla_errors.setdefault(level, []),
            earlier_periods=min((len(c) for c in columns[:-1]), default=0),
        )

    def _start_refit(self, final: bool, reason: str) -> None:
        assert self.assembler is not None
        self.refit_started = time.monotonic()
        self.future_reason = reason
        self.anomalies_at_submit = self.anomalies_received
        # Only sines completed since the last refit: the worker keeps its models and validates
        # them again.
        reuse = not self.models_stale and self.refits > 0
        self.node.logger.info(
            "%s %d (%s)%s",
            "validation" if reuse else "refit",
            self.refits + 1,
            reason,
            " [final]" if final else "",
        )
        self.future_final = final
        args = (self.assembler, self.config, final, self.out_dir, reuse)
        if self.executor is not None:
            self.future = self.executor.submit(refit_worker.refit, *args)
        else:
            done: Future[RefitOutcome] = Future()
            try:
                done.set_result(refit_worker.refit(*args))
            except Exception as exc:
                done.set_exception(exc)
            self.future = done

    def _collect(self) -> None:
        assert self.future is not None
        elapsed = time.monotonic() - self.refit_started
        try:
            payload, summary = self.future.result()
        except Exception as exc:
            detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
            self.errors.append(f"refit failed ({self.future_reason}): {detail}")
            self.node.logger.error("%s; the previous models are kept", self.errors[-1])
            self.future = None
            if isinstance(exc, BrokenProcessPool) and self.executor is not None:
                # The worker died (killed, out of memory): a new one, which fits afresh. The
                # job it died in is queued again (at once: its data are in), so a final
                # identification is never lost with its worker.
                self.executor.shutdown(wait=False, cancel_futures=True)
                self._start_worker()
                self.models_stale = True
                self.pending.append((-1, self.future_final, self.future_reason, True))
            self.publish_status()
            return
        self.future = None
        self.models_stale = False
        self.refits += 1
        self.refit_times.append(elapsed)
        self.last_summary = summary
        refit_worker.release_memory()  # the pickled job and its answer
        payload[model_message.REFIT] = self.refits
        payload["refit_s"] = elapsed
        payload["reason"] = self.future_reason
        self.model_pub.publish(
            self.node.new_message("std_msgs/msg/String", data=json.dumps(payload, allow_nan=True))
        )
        worker = summary["worker"]
        self.node.logger.info(
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
            self.node.logger.warning("%s", warning)
        if summary["complete"] and self.anomalies_received != self.anomalies_at_submit:
            # An anomaly came in while the final identification ran on the data before it:
            # run it again, so the report names (and excludes) what the anomaly touches.
            self.node.logger.warning(
                "%d anomaly record(s) arrived during the final identification: running it again",
                self.anomalies_received - self.anomalies_at_submit,
            )
            self.pending.append((-1, True, "anomaly during the final identification", True))
            self.publish_status()
            return
        if summary["complete"]:
            self.final_done = True
            if summary["written"]:
                self.node.logger.info("report written to %s", Path(self.out_dir).resolve())
            self.node.logger.info(
                "final Table 1 (trained on all levels):\n%s", payload["table1"]["markdown"]
            )
            problems = data_quality_lines(summary.get("data_quality", {}))
            for line in problems:
                self.node.logger.error("data not clean: %s", line)
            if not problems:
                self.node.logger.info("data clean: every plan sample arrived once, no anomaly")
        self.publish_status()
        if summary["complete"] and self.node.params["exit_after_final"]:
            self.node.request_shutdown(0)

    # -- status ---------------------------------------------------------------------------
    def publish_status(self) -> None:
        values: dict[str, str] = {
            "state": "done" if self.final_done else ("refitting" if self.future else "collecting"),
            "refits": str(self.refits),
            "last_refit_s": f"{self.refit_times[-1]:.2f}" if self.refit_times else "",
            "max_refit_s": f"{max(self.refit_times):.2f}" if self.refit_times else "",
            "pitch_samples": str(self.samples["u"]),
            "cl_samples": str(self.samples["y"]),
        }
        paused = self.node.paused_s
        if paused:
            values["stopped"] = f"{len(paused)} time(s) past the DDS lease, last {paused[-1]:.1f} s"
        for channel, name in (("u", "pitch"), ("y", "C_l")):
            gaps = self.gaps[channel]
            if gaps:
                lost = sum(b - a + 1 for a, b in gaps)
                first, last = gaps[-1]
                values[f"{name} gaps"] = (
                    f"{len(gaps)} gap(s), {lost} plan samples never arrived (last {first}..{last})"
                )
        if self.assembler is not None:
            for (level, real), block in sorted(self.assembler.blocks.items()):
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
        gapped = any(self.gaps.values()) or bool(self.node.paused_s)
        level = 2 if self.errors else (1 if excluded or warnings or problems or gapped else 0)
        message = values["state"]
        msg = diagnostic_array(
            self.node,
            f"{self.node.name}: identification",
            level,
            message,
            "identifier",
            values,
        )
        self.status_pub.publish(msg)

    def close(self) -> None:
        if self.executor is not None:
            # Idle (the final identification done): wait for the worker, so that the
            # executor's manager thread has closed its wakeup pipe before the interpreter's
            # exit hook writes to it (CPython 3.11's concurrent.futures.process._python_exit
            # raced with it: "Exception ignored ... Bad file descriptor"). A refit still
            # running is cancelled without waiting for it.
            self.executor.shutdown(wait=self.future is None, cancel_futures=True)


def main(argv: list[str] | None = None) -> int:
    return run_node(Identifier, "identifier", PARAMETERS, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())

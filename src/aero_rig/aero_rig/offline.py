"""Offline fits from a rosbag2 recording: the same pipeline as the identifier node.

Reads ``/experiment/plan``, ``/pitch/state`` and ``/wing/coefficients`` from a bag (MCAP or
sqlite3, recorded by this graph's recorder or by ``ros2 bag record``), rebuilds the plan's
periods from the stamps exactly as the node does (aero_identification.period_assembly) and runs the
final identification (aero_identification.pipeline). A damaged bag is read through a salvaged
copy: every intact chunk, with a warning naming each gap (time span, messages lost per topic)
and a file's damaged tail; a bag without the needed topics is refused, naming them. The
anomalies recorded on ``/experiment/anomaly`` exclude what they touch, as in the node.

The plan, the segment events, the anomalies and the models are aero_rig_interfaces messages,
each read through its topic's one reader (multisine_gen.plan_format.read_plan_message and
segment_event_from_message, rig_runtime.anomaly.Anomaly.from_message,
aero_identification.model_message.model_from_message); these also read the std_msgs/String
JSON of bags recorded before those messages existed, so such a bag fits as it did.
"""

import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aero_identification.campaign_source import campaign_dataset
from aero_identification.hyperparameters import IdentificationConfig
from aero_identification.identification_result import IdentificationResult
from aero_identification.model_message import model_from_message
from aero_identification.period_assembly import CampaignAssembler
from aero_identification.pipeline import identify
from aero_identification.report import write_report
from multisine_gen.plan import ExperimentPlan, PlanError
from multisine_gen.plan_format import read_plan_message, segment_event_from_message
from rig_runtime.anomaly import Anomaly
from rig_runtime.interface import (
    EXPERIMENT_ANOMALY,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_MODEL,
    PITCH_JOINT,
    PITCH_STATE,
    WING_COEFFICIENTS,
    joint_position,
)
from rig_runtime.messages import stamp_to_ns, typestore

REQUIRED_TOPICS = (EXPERIMENT_PLAN.name, PITCH_STATE.name, WING_COEFFICIENTS.name)


class BagError(ValueError):
    """A bag that cannot be fitted (missing topics, unreadable)."""


@dataclass
class BagData:
    plan: ExperimentPlan
    assembler: CampaignAssembler
    messages: int = 0
    warnings: list[str] = field(default_factory=list)
    # The identifier's hyperparameters as the run used them (the "config" of the last
    # /identification/model message in the bag), or None when the bag holds no model.
    recorded_config: dict[str, Any] | None = None


def read_campaign_bag(bag: str | Path) -> BagData:
    """Plan and samples of a campaign bag, cut into periods.

    A bag that rosbags cannot open (a file without its footer) or that fails while it is read
    (a damaged chunk) is read again through a salvaged copy (:func:`_recovered_view`): every
    intact chunk, with a warning per gap (its time span and the messages lost per topic). The
    samples of a lost chunk are then missing from their periods, and the data-quality account
    names them.
    """
    path = Path(bag)
    if not path.exists():
        raise BagError(f"bag {path} does not exist")
    data, failure = _read_bag(path, path)
    if failure is None:
        assert data is not None
        return data
    view, warnings = _recovered_view(path, failure)
    if view is None:  # nothing to salvage (not MCAP, or no damaged chunk found)
        if data is None:
            raise BagError(f"cannot open bag {path}: {failure}") from failure
        data.warnings.append(_damaged_after(path, data.messages, failure))
        return data
    try:
        salvaged, failure2 = _read_bag(view, path)
    except BagError as exc:  # e.g. the plan message was in a lost chunk
        raise BagError(f"{exc}; {' '.join(warnings)}") from exc
    finally:
        shutil.rmtree(view.parent, ignore_errors=True)
    if salvaged is None:
        raise BagError(
            f"cannot open bag {path}: {failure}; recovered copy: {failure2}"
        ) from failure2
    salvaged.warnings[:0] = warnings
    if failure2 is not None:
        salvaged.warnings.append(_damaged_after(path, salvaged.messages, failure2))
    return salvaged


def _read_bag(source: Path, path: Path) -> tuple[BagData | None, Exception | None]:
    """Read the bag at ``source`` (``path`` names it in messages): the data and the error that
    stopped the read (None: read to the end). No data when the read stopped before the plan
    and the samples (cannot open, plan unreadable); the samples read up to the error when it
    stopped among them. A bag that cannot be fitted whatever its state raises BagError."""
    from rosbags.highlevel import AnyReader

    warnings: list[str] = []
    try:
        reader = AnyReader([source], default_typestore=typestore())
        reader.open()
    except Exception as exc:
        return None, exc
    try:
        topics = {c.topic for c in reader.connections}
        missing = [t for t in REQUIRED_TOPICS if t not in topics]
        if missing:
            raise BagError(
                f"bag {path} lacks topic(s) {missing} needed for a fit; it has {sorted(topics)}"
            )
        try:
            plan_conns = [c for c in reader.connections if c.topic == EXPERIMENT_PLAN.name]
            messages: list[Any] = []  # ExperimentPlan, or an older bag's std_msgs/String
            for conn, _, raw in reader.messages(connections=plan_conns):
                messages.append(reader.deserialize(raw, conn.msgtype))
            # An adaptive run's decisions (multisine_gen.revision), for its report.
            segment_conns = [c for c in reader.connections if c.topic == EXPERIMENT_SEGMENT.name]
            decisions: list[dict[str, Any]] = []
            for conn, _, raw in reader.messages(connections=segment_conns) if segment_conns else ():
                segment_msg: Any = reader.deserialize(raw, conn.msgtype)  # a SegmentEvent
                try:
                    event = segment_event_from_message(segment_msg)
                except PlanError as exc:
                    warnings.append(f"bag {path}: {exc}")  # the error names the topic
                    continue
                if event.get("event") in ("decision", "refused"):
                    decisions.append(event)
            recorded_config = None
            model_conns = [c for c in reader.connections if c.topic == IDENTIFICATION_MODEL.name]
            # (no connection at all would mean every message to rosbags)
            for conn, _, raw in reader.messages(connections=model_conns) if model_conns else ():
                model_msg: Any = reader.deserialize(raw, conn.msgtype)  # IdentificationModel
                try:
                    recorded_config = model_from_message(model_msg).get("config") or recorded_config
                except ValueError as exc:
                    warnings.append(f"bag {path}: {exc}")  # the error names the topic
        except Exception as exc:  # a damaged chunk
            return None, exc
        if not messages:
            raise BagError(f"bag {path}: /experiment/plan holds no message")
        # The run's plans: the last run's (its t0) as first published, and its latest revision
        # (an adaptive run's executed plan, every sample before each change unchanged).
        try:
            plans = [read_plan_message(m) for m in messages]
        except PlanError as exc:
            raise BagError(f"bag {path}: {exc}") from exc
        t0_ns = plans[-1][1]
        revisions = [p for p, t0 in plans if t0 == t0_ns]
        assembler = CampaignAssembler(revisions[0], t0_ns)
        latest = max(revisions, key=lambda p: p.revision)
        if latest.revision > revisions[0].revision:
            assembler.revise(latest)
        plan = assembler.plan
        assembler.decisions = [d for d in decisions if d.get("t0_ns") == t0_ns]
        wanted = [
            c
            for c in reader.connections
            if c.topic in (*REQUIRED_TOPICS[1:], EXPERIMENT_ANOMALY.name)
        ]
        data = BagData(plan, assembler, 0, warnings, recorded_config)
        try:
            for conn, _, raw in reader.messages(connections=wanted):
                msg: Any = reader.deserialize(raw, conn.msgtype)  # a message, typed at runtime
                if conn.topic == EXPERIMENT_ANOMALY.name:
                    a = Anomaly.from_message(msg)  # a later record of the same id replaces it
                    assembler.add_anomaly(a.id, a.first_ns, a.last_ns, a.label())
                    continue
                stamp = stamp_to_ns(msg.header.stamp)
                if conn.topic == PITCH_STATE.name:
                    pitch = joint_position(msg, PITCH_JOINT)
                    assembler.add("u", stamp, math.nan if pitch is None else math.degrees(pitch))
                else:
                    assembler.add("y", stamp, float(msg.vector.x))
                data.messages += 1
        except Exception as exc:  # a damaged chunk: what was read so far, and why it stopped
            return data, exc
    finally:
        reader.close()
    return data, None


def _damaged_after(path: Path, count: int, exc: Exception) -> str:
    return (
        f"bag {path} is damaged after {count} messages ({type(exc).__name__}: {exc}); "
        "fitting the data up to the damage"
    )


def _recovered_view(path: Path, exc: Exception) -> tuple[Path | None, list[str]]:
    """A readable copy of a damaged MCAP bag, and the warnings that say what it lacks.

    A recording cut short (kill -9 or power loss of the recorder, a copy cut short) leaves an
    MCAP file without its footer and summary, which rosbags refuses whole; a damaged chunk (a
    bad sector, a stray write) stops rosbags at that chunk. The whole files are linked and the
    damaged ones rewritten with every intact chunk (rig_runtime.bag_recover, what
    ``aero-rig bag recover`` does in place) into a temporary directory; None if that is not an
    MCAP bag, no file is damaged, or nothing in it is readable.
    """
    from rig_runtime.bag_recover import (
        describe_gap,
        describe_unknown_channels,
        format_stamp,
        last_readable_ns,
        recovered_view,
    )

    try:
        view, reports = recovered_view(path)
    except Exception:
        return None, []
    damaged = [r for r in reports if not r.intact]
    if not damaged or not any(r.stats.count for r in reports):
        shutil.rmtree(view.parent, ignore_errors=True)
        return None, []
    cause = f"{type(exc).__name__}: {exc}"
    warnings = []
    for r in damaged:
        warnings += [
            f"bag {path}: {r.name}: {describe_gap(g)}; fitting every readable chunk" for g in r.gaps
        ]
        warnings += [f"bag {path}: {r.name}: {line}" for line in describe_unknown_channels(r)]
    cut = [r for r in damaged if r.error]
    if cut:
        files = ", ".join(f"{r.name} ({r.error}, {r.stats.count} messages readable)" for r in cut)
        warnings.append(
            f"bag {path} has damaged file(s) {files} ({cause}); fitting the data up to the "
            f"damage: last readable time {format_stamp(last_readable_ns(cut))}"
        )
    if not warnings:
        names = ", ".join(r.name for r in damaged)
        warnings.append(f"bag {path}: {names} read through a rewritten copy ({cause})")
    warnings[-1] += f". `aero-rig bag recover {path}` repairs the bag in place"
    return view, warnings


def fit_bag(
    bag: str | Path,
    out_dir: str | Path | None = None,
    config: IdentificationConfig | None = None,
    data: BagData | None = None,
) -> tuple[IdentificationResult, BagData]:
    """The final identification of a campaign bag (the identifier's pipeline on the same
    dataset). ``config``: default the hyperparameters recorded in the bag
    (`BagData.recorded_config`), else IdentificationConfig()."""
    data = data or read_campaign_bag(bag)
    if config is None:
        config = recorded_config(data)
    dataset = campaign_dataset(data.assembler, final=True, min_periods=config.min_periods,
                               source=f"bag {Path(bag)}")  # fmt: skip
    result = identify(dataset, config, final=True)
    result.warnings[:0] = data.warnings
    if out_dir is not None:
        write_report(result, out_dir)
    return result, data


def recorded_config(data: BagData) -> IdentificationConfig:
    """The hyperparameters the run used (from the bag), or the defaults when it has none."""
    if data.recorded_config is None:
        return IdentificationConfig()
    return IdentificationConfig.from_dict(data.recorded_config)

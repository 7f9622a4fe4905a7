"""Offline fits from a rosbag2 recording: the same pipeline as the identifier node.

Reads ``/experiment/plan``, ``/pitch/state`` and ``/wing/coefficients`` from a bag (MCAP or
sqlite3, recorded by this graph's recorder or by ``ros2 bag record``), rebuilds the plan's
periods from the stamps exactly as the node does (aero_identification.campaign) and runs the
final identification (aero_identification.pipeline). A bag whose tail is damaged is read up
to the damage, with a warning; a bag without the needed topics is refused, naming them. The
anomalies recorded on ``/experiment/anomaly`` exclude what they touch, as in the node.
"""

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aero_identification.campaign import CampaignAssembler
from aero_identification.pipeline import (
    IdentificationConfig,
    IdentificationResult,
    identify,
    write_report,
)
from rig_runtime.anomaly import Anomaly
from rig_runtime.interface import (
    EXPERIMENT_ANOMALY,
    EXPERIMENT_PLAN,
    PITCH_JOINT,
    PITCH_STATE,
    WING_COEFFICIENTS,
    joint_position,
)
from rig_runtime.messages import stamp_to_ns

REQUIRED_TOPICS = (EXPERIMENT_PLAN.name, PITCH_STATE.name, WING_COEFFICIENTS.name)


class BagError(ValueError):
    """A bag that cannot be fitted (missing topics, unreadable)."""


@dataclass
class BagData:
    plan: dict[str, Any]
    assembler: CampaignAssembler
    messages: int = 0
    warnings: list[str] = field(default_factory=list)


def read_campaign_bag(bag: str | Path) -> BagData:
    """Plan and samples of a campaign bag, cut into periods."""
    from rosbags.highlevel import AnyReader

    path = Path(bag)
    if not path.exists():
        raise BagError(f"bag {path} does not exist")
    warnings: list[str] = []
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as exc:
        readable, damaged = _readable_view(path)
        if readable is None:
            raise BagError(f"cannot open bag {path}: {exc}") from exc
        warnings.append(
            f"bag {path} has damaged file(s) {damaged} ({exc}); fitting the data of the "
            "readable files, i.e. up to the damage"
        )
        reader = AnyReader([readable])
        reader.open()
    try:
        topics = {c.topic for c in reader.connections}
        missing = [t for t in REQUIRED_TOPICS if t not in topics]
        if missing:
            raise BagError(
                f"bag {path} lacks topic(s) {missing} needed for a fit; it has {sorted(topics)}"
            )
        plan_conns = [c for c in reader.connections if c.topic == EXPERIMENT_PLAN.name]
        plan: dict[str, Any] | None = None
        for conn, _, raw in reader.messages(connections=plan_conns):
            plan_msg: Any = reader.deserialize(raw, conn.msgtype)  # a std_msgs/String
            plan = json.loads(plan_msg.data)
        if plan is None or "t0_ns" not in plan:
            raise BagError(f"bag {path}: /experiment/plan holds no plan with t0_ns")
        assembler = CampaignAssembler(plan, int(plan["t0_ns"]))
        wanted = [
            c
            for c in reader.connections
            if c.topic in (*REQUIRED_TOPICS[1:], EXPERIMENT_ANOMALY.name)
        ]
        count = 0
        try:
            for conn, _, raw in reader.messages(connections=wanted):
                msg: Any = reader.deserialize(raw, conn.msgtype)  # a message, typed at runtime
                if conn.topic == EXPERIMENT_ANOMALY.name:
                    a = Anomaly.from_json(msg.data)  # a later record of the same id replaces it
                    assembler.add_anomaly(a.id, a.first_ns, a.last_ns, a.label())
                    continue
                stamp = stamp_to_ns(msg.header.stamp)
                if conn.topic == PITCH_STATE.name:
                    pitch = joint_position(msg, PITCH_JOINT)
                    assembler.add("u", stamp, math.nan if pitch is None else math.degrees(pitch))
                else:
                    assembler.add("y", stamp, float(msg.vector.x))
                count += 1
        except Exception as exc:  # a damaged tail: keep what was read
            warnings.append(
                f"bag {path} is damaged after {count} messages ({type(exc).__name__}: {exc}); "
                "fitting the data up to the damage"
            )
    finally:
        reader.close()
    return BagData(plan, assembler, count, warnings)


def _readable_view(path: Path) -> tuple[Path | None, list[str]]:
    """A copy of a rosbag2 directory's metadata listing only the files that open.

    A recording cut short (power loss, kill -9 of a writer that does not split) leaves an MCAP
    file without its footer, which rosbags refuses whole. The view links the good files into a
    temporary directory beside a trimmed metadata.yaml; None if nothing is readable.
    """
    import tempfile

    import yaml
    from rosbags.rosbag2.storage_mcap import McapReader

    meta_path = path / "metadata.yaml"
    if not meta_path.exists():
        return None, []
    meta = yaml.safe_load(meta_path.read_text())
    info = meta["rosbag2_bagfile_information"]
    if info.get("storage_identifier") != "mcap":
        return None, []
    good, damaged = [], []
    for name in info["relative_file_paths"]:
        file = path / Path(name).name
        probe = McapReader(file)
        try:
            probe.open()
            probe.close()
            good.append(name)
        except Exception:
            damaged.append(Path(name).name)
    if not good or not damaged:
        return None, damaged
    view = Path(tempfile.mkdtemp(prefix="aero_rig_fit_")) / path.name
    view.mkdir()
    for name in good:
        (view / Path(name).name).symlink_to((path / Path(name).name).resolve())
    info["relative_file_paths"] = good
    info["files"] = [f for f in info.get("files", []) if f["path"] in good]
    info["message_count"] = sum(f["message_count"] for f in info["files"])
    for topic in info.get("topics_with_message_count", []):
        topic["message_count"] = 0  # unknown per file; the reader counts the messages itself
    (view / "metadata.yaml").write_text(yaml.safe_dump(meta))
    return view, damaged


def fit_bag(
    bag: str | Path, out_dir: str | Path | None = None, config: IdentificationConfig | None = None
) -> tuple[IdentificationResult, BagData]:
    data = read_campaign_bag(bag)
    result = identify(data.assembler, config or IdentificationConfig(), final=True)
    result.warnings[:0] = data.warnings
    if out_dir is not None:
        write_report(result, data.assembler, out_dir)
    return result, data

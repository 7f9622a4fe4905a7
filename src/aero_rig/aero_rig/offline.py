"""Offline fits from a rosbag2 recording: the same pipeline as the identifier node.

Reads ``/experiment/plan``, ``/pitch/state`` and ``/wing/coefficients`` from a bag (MCAP or
sqlite3, recorded by this graph's recorder or by ``ros2 bag record``), rebuilds the plan's
periods from the stamps exactly as the node does (aero_identification.campaign) and runs the
final identification (aero_identification.pipeline). A bag whose tail is damaged is read up
to the damage, with a warning; a bag without the needed topics is refused, naming them.
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
from rig_runtime.messages import stamp_to_ns

REQUIRED_TOPICS = ("/experiment/plan", "/pitch/state", "/wing/coefficients")


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
        raise BagError(f"cannot open bag {path}: {exc}") from exc
    try:
        topics = {c.topic for c in reader.connections}
        missing = [t for t in REQUIRED_TOPICS if t not in topics]
        if missing:
            raise BagError(
                f"bag {path} lacks topic(s) {missing} needed for a fit; it has {sorted(topics)}"
            )
        plan_conns = [c for c in reader.connections if c.topic == "/experiment/plan"]
        plan: dict[str, Any] | None = None
        for conn, _, raw in reader.messages(connections=plan_conns):
            plan = json.loads(reader.deserialize(raw, conn.msgtype).data)
        if plan is None or "t0_ns" not in plan:
            raise BagError(f"bag {path}: /experiment/plan holds no plan with t0_ns")
        assembler = CampaignAssembler(plan, int(plan["t0_ns"]))
        wanted = [c for c in reader.connections if c.topic in REQUIRED_TOPICS[1:]]
        count = 0
        try:
            for conn, _, raw in reader.messages(connections=wanted):
                msg = reader.deserialize(raw, conn.msgtype)
                stamp = stamp_to_ns(msg.header.stamp)
                if conn.topic == "/pitch/state":
                    names = list(msg.name)
                    i = names.index("pitch") if "pitch" in names else 0
                    assembler.add("u", stamp, math.degrees(float(msg.position[i])))
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


def fit_bag(
    bag: str | Path, out_dir: str | Path | None = None, config: IdentificationConfig | None = None
) -> tuple[IdentificationResult, BagData]:
    data = read_campaign_bag(bag)
    result = identify(data.assembler, config or IdentificationConfig(), final=True)
    result.warnings[:0] = data.warnings
    if out_dir is not None:
        write_report(result, data.assembler, out_dir)
    return result, data

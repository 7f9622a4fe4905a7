"""Whether a finished campaign can be trusted: what it lost or excluded, in one list.

Read from the run directory after the graph has stopped:

- ``models.json``: the identification's data-quality record (aero_identification.quality):
  plan samples missing or duplicated on the pitch and C_l channels, the anomalies that touch
  the plan (free runs, commands not followed, stamp jumps, gaps, frame loss, ...), the excluded
  periods and sine records;
- ``bag/metadata.yaml``: how many samples of each stream topic the recorder wrote, against the
  plan's sample count (the bag is what offline fits read).

An empty list means the run is clean. ``aero-rig campaign`` prints the list on its last lines
and exits non-zero unless ``--allow-excluded``.
"""

import json
from pathlib import Path

import yaml

from aero_identification.quality import data_quality_lines
from rig_runtime.interface import PITCH_COMMAND, PITCH_STATE, PRESSURE_TAPS, WING_COEFFICIENTS

STREAM_TOPICS = (PITCH_COMMAND.name, PITCH_STATE.name, PRESSURE_TAPS.name, WING_COEFFICIENTS.name)


def bag_topic_counts(bag: Path) -> dict[str, int]:
    """Messages per topic as metadata.yaml lists them ({} if there is no metadata)."""
    meta = bag / "metadata.yaml"
    if not meta.exists():
        return {}
    info = (yaml.safe_load(meta.read_text()) or {}).get("rosbag2_bagfile_information", {})
    return {
        t["topic_metadata"]["name"]: int(t["message_count"])
        for t in info.get("topics_with_message_count", [])
    }


def bag_problems(bag: Path, total_samples: int) -> list[str]:
    """Stream topics with fewer messages in the bag than the plan has samples.

    More is not a loss: after the plan's end the simulated actuator runs on in real time while
    the graph stops, and its states are recorded too.
    """
    counts = bag_topic_counts(bag)
    if not counts:
        return [f"bag {bag}: no metadata.yaml (the recorder did not finalise it)"]
    return [
        f"bag: {topic} holds {counts.get(topic, 0)} of {total_samples} plan samples"
        for topic in STREAM_TOPICS
        if counts.get(topic, 0) < total_samples
    ]


def run_problems(run_dir: Path, total_samples: int | None) -> list[str]:
    """Everything a run lost or excluded (empty: clean)."""
    models = run_dir / "models.json"
    if not models.exists():
        return [f"{models}: missing (the identifier wrote no report)"]
    quality = json.loads(models.read_text()).get("data_quality")
    if quality is None:
        return [f"{models}: no data_quality record"]
    problems = data_quality_lines(quality)
    if total_samples:
        problems += bag_problems(run_dir / "bag", total_samples)
    return problems

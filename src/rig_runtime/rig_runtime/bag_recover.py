"""Recover a rosbag2 MCAP bag whose writer died (``kill -9``, power loss, a copy cut short) or
whose file was damaged in the middle (a bad sector, a stray write).

A file that ends without its footer and summary is refused whole by indexed readers (rosbags,
``mcap``'s seeking reader); a damaged chunk stops them at that chunk. Every intact chunk is still
there: :func:`read_records` reads them all with :mod:`rig_runtime.bag_salvage` (CRCs checked;
the chunk index drives the read when the summary is there, else a walk of the records that
skips a damaged chunk and goes on with the next readable one) and names each stretch it could
not read (:class:`~rig_runtime.bag_salvage.Gap`: time span, messages lost per topic).
:func:`recover_bag` rewrites each damaged file through the ``mcap`` writer (same schemas,
channels, messages and chunk compression; written beside it, then renamed over it) and rewrites
``metadata.yaml`` from what the files hold, like ``ros2 bag reindex``. :func:`recovered_view`
does the same into a temporary directory and leaves the bag untouched (``aero-rig fit`` of a
damaged bag).
"""

import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import yaml
from mcap.records import Channel, Message, Schema

from .bag import FileStats, TopicInfo, open_file_writer, write_metadata
from .bag_salvage import Gap, Scan, file_summary, salvage_records
from .messages import typestore

_Scan = Scan  # the name the tests and older callers use


@dataclass
class FileReport:
    """What one file of a bag held and what was done with it."""

    name: str
    intact: bool  # footer, summary and every chunk readable: left as it was
    stats: FileStats
    error: str = ""  # why the read stopped early ('' if it read to the end)
    rewritten: bool = False
    gaps: list[Gap] = field(default_factory=list)  # stretches that could not be read
    # Messages of channels whose definition was lost with a damaged chunk (no summary).
    unknown_channels: dict[int, int] = field(default_factory=dict)

    @property
    def last_ns(self) -> int | None:
        return self.stats.end_ns if self.stats.count else None


def format_stamp(ns: int | None) -> str:
    """A receive/log time as UTC ISO 8601 with the raw nanoseconds."""
    if ns is None:
        return "no message"
    iso = datetime.fromtimestamp(ns / 1e9, tz=UTC).isoformat(timespec="microseconds")
    return f"{iso.replace('+00:00', 'Z')} ({ns} ns)"


def read_records(path: Path, scan: Scan) -> Iterator[Message]:
    """The messages of every readable chunk of an MCAP file, in file order; schemas, channels,
    the chunk compression, the unreadable stretches (``scan.gaps``) and why the read stopped
    early (``scan.error``) are collected into ``scan``. Only whole chunks yield messages."""
    return salvage_records(path, scan)


def _summary(path: Path) -> Any:
    """The file's MCAP summary (footer, and summary section with a matching CRC), or None."""
    return file_summary(path)


def is_intact(path: Path) -> bool:
    """Whether the file has a valid footer and summary (what indexed readers need)."""
    return _summary(path) is not None


def _intact_stats(summary: Any, name: str, topics: dict[str, TopicInfo]) -> FileStats:
    stats = FileStats(name)
    for channel in summary.channels.values():
        _topic_of(channel, summary.schemas, topics)
    if summary.statistics is not None and summary.statistics.message_count:
        st = summary.statistics
        stats.start_ns, stats.end_ns, stats.count = (
            st.message_start_time,
            st.message_end_time,
            st.message_count,
        )
        for cid, n in st.channel_message_counts.items():
            topic = summary.channels[cid].topic
            stats.counts[topic] = stats.counts.get(topic, 0) + n
    return stats


def _topic_of(
    channel: Channel, schemas: dict[int, Schema], topics: dict[str, TopicInfo]
) -> TopicInfo:
    if channel.topic in topics:
        return topics[channel.topic]
    schema = schemas.get(channel.schema_id)
    msgtype = schema.name if schema else ""
    qos = yaml.safe_load(channel.metadata.get("offered_qos_profiles", "") or "[]") or []
    digest = channel.metadata.get("topic_type_hash", "")
    if not digest and msgtype:
        try:
            digest = typestore().hash_rihs01(msgtype)
        except Exception:
            digest = ""
    info = TopicInfo(channel.topic, msgtype, qos, digest, channel.message_encoding or "cdr")
    topics[channel.topic] = info
    return info


def recover_file(src: Path, dst: Path, topics: dict[str, TopicInfo]) -> FileReport:
    """Write what is readable of ``src`` to ``dst`` (a new, whole MCAP file)."""
    scan = _Scan()
    stats = FileStats(src.name)
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    with dst.open("xb") as out:
        writer = None
        for msg in read_records(src, scan):
            if writer is None:
                writer = open_file_writer(out, scan.compression)
            channel = channel_ids.get(msg.channel_id)
            if channel is None:
                old = scan.channels[msg.channel_id]
                schema = schema_ids.get(old.schema_id)
                if schema is None and old.schema_id in scan.schemas:
                    s = scan.schemas[old.schema_id]
                    schema = writer.register_schema(s.name, s.encoding, s.data)
                    schema_ids[old.schema_id] = schema
                channel = writer.register_channel(
                    old.topic, old.message_encoding, schema or 0, dict(old.metadata)
                )
                channel_ids[msg.channel_id] = channel
                _topic_of(old, scan.schemas, topics)
            writer.add_message(channel, msg.log_time, msg.data, msg.publish_time, msg.sequence)
            stats.add(scan.channels[msg.channel_id].topic, msg.log_time)
        if writer is None:  # nothing readable: an empty, whole file
            writer = open_file_writer(out, scan.compression)
        for cid, channel_rec in scan.channels.items():  # channels without a message too
            if cid not in channel_ids:
                _topic_of(channel_rec, scan.schemas, topics)
        writer.finish()
        out.flush()
        os.fsync(out.fileno())
    return FileReport(
        src.name, False, stats, scan.error, True, scan.gaps, dict(scan.unknown_channels)
    )


def check_file(path: Path) -> Scan:
    """Read every chunk of a file (decompressed, CRCs checked) without writing anything: its
    ``gaps`` and ``error`` say whether it needs recovering."""
    scan = Scan()
    for _ in read_records(path, scan):
        pass
    return scan


def _bag_files(bag: Path) -> tuple[list[str], dict[str, TopicInfo]]:
    """File names the bag lists (else its *.mcap in order) and the topics metadata.yaml has."""
    topics: dict[str, TopicInfo] = {}
    meta_path = bag / "metadata.yaml"
    names: list[str] = []
    if meta_path.exists():
        info = (yaml.safe_load(meta_path.read_text()) or {}).get("rosbag2_bagfile_information")
        info = info or {}
        if info.get("storage_identifier", "mcap") != "mcap":
            raise ValueError(f"bag {bag}: storage {info.get('storage_identifier')!r} is not mcap")
        names = [Path(n).name for n in info.get("relative_file_paths", [])]
        for t in info.get("topics_with_message_count", []):
            m = t["topic_metadata"]
            qos = m.get("offered_qos_profiles", [])
            if isinstance(qos, str):  # metadata versions before 9 keep a YAML string
                qos = yaml.safe_load(qos) or []
            topics[m["name"]] = TopicInfo(
                m["name"],
                m["type"],
                qos,
                m.get("type_description_hash", ""),
                m.get("serialization_format", "cdr"),
            )
    listed = set(names)

    def index(p: Path) -> tuple[int, str]:
        tail = p.stem.rpartition("_")[2]
        return (int(tail) if tail.isdigit() else 0, p.name)

    names += [p.name for p in sorted(bag.glob("*.mcap"), key=index) if p.name not in listed]
    if not names:
        raise ValueError(f"bag {bag}: no MCAP file (no metadata.yaml listing one, no *.mcap)")
    return names, topics


def recover_bag(bag: str | Path, into: str | Path | None = None) -> list[FileReport]:
    """Make every file of ``bag`` readable and rewrite its metadata.yaml.

    ``into`` None: damaged files are replaced in place (each written beside the original, then
    renamed over it). Otherwise ``into`` (an empty or new directory) receives the view: whole
    files linked, damaged ones recovered, and a metadata.yaml; the bag is not touched.
    """
    bag = Path(bag)
    if not bag.is_dir():
        raise ValueError(f"bag {bag} is not a directory")
    names, topics = _bag_files(bag)
    out_dir = Path(into) if into is not None else bag
    out_dir.mkdir(parents=True, exist_ok=True)
    reports = []
    for name in names:
        src = bag / name
        if not src.exists():
            reports.append(FileReport(name, False, FileStats(name), "file missing"))
            continue
        summary = _summary(src)
        if summary is not None and _whole(src):
            reports.append(FileReport(name, True, _intact_stats(summary, name, topics)))
            if into is not None:
                (out_dir / name).symlink_to(src.resolve())
            continue
        tmp = out_dir / f"{name}.recovering"
        tmp.unlink(missing_ok=True)
        report = recover_file(src, tmp, topics)
        tmp.replace(out_dir / name)
        reports.append(report)
    present = [r.stats for r in reports if r.error != "file missing"]
    write_metadata(out_dir, present, list(topics.values()))
    return reports


def _whole(path: Path) -> bool:
    scan = check_file(path)
    return not scan.gaps and not scan.error and not scan.unknown_channels


def recovered_view(bag: str | Path) -> tuple[Path, list[FileReport]]:
    """A readable copy of ``bag`` in a new temporary directory (the caller removes it)."""
    view = Path(tempfile.mkdtemp(prefix="rig_bag_view_")) / Path(bag).name
    return view, recover_bag(bag, into=view)


def describe(reports: list[FileReport]) -> list[str]:
    """Lines for people: per file what was readable, each gap, per topic how many messages."""
    lines = []
    for r in reports:
        if r.intact:
            state = "whole (footer, summary and every chunk readable), left as it was"
        elif r.error == "file missing":
            state = "missing"
        else:
            what = [f"{len(r.gaps)} unreadable stretch(es) skipped"] if r.gaps else []
            what += [r.error] if r.error else []
            state = f"damaged ({'; '.join(what) or 'summary'}); rewritten with a footer"
        lines.append(
            f"{r.name}: {state}; {r.stats.count} messages, last readable time "
            f"{format_stamp(r.last_ns)}"
        )
        lines += [f"  gap: {describe_gap(g)}" for g in r.gaps]
        lines += [f"  {line}" for line in describe_unknown_channels(r)]
        lines += [f"  {topic}: {n}" for topic, n in sorted(r.stats.counts.items())]
    return lines


def describe_gap(gap: Gap) -> str:
    """One gap for people: where, why, the time span and the messages lost per topic."""
    where = f"bytes {gap.offset}..{gap.end_offset} unreadable ({gap.error})"
    if gap.exact:
        assert gap.start_ns is not None and gap.end_ns is not None
        span = (
            f"messages logged {format_stamp(gap.start_ns)} .. {format_stamp(gap.end_ns)} "
            f"({(gap.end_ns - gap.start_ns) / 1e9:.3f} s, from the {gap.span_from})"
        )
    elif gap.start_ns is None and gap.end_ns is None:
        span = "messages logged at unknown times (no readable message around it)"
    elif gap.end_ns is None:
        span = f"messages logged after {format_stamp(gap.start_ns)} (to the end of the file)"
    elif gap.start_ns is None:
        span = f"messages logged before {format_stamp(gap.end_ns)}"
    else:
        span = (
            f"messages logged between {format_stamp(gap.start_ns)} and "
            f"{format_stamp(gap.end_ns)} (the neighbouring readable messages, "
            f"{(gap.end_ns - gap.start_ns) / 1e9:.3f} s)"
        )
    if gap.lost is None:
        lost = "an unknown count of messages (no readable message index for it)"
    else:
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(gap.lost.items()))
        lost = f"{gap.lost_count} messages ({per_topic})"
    return f"{where}: {span}; lost {lost}"


def describe_unknown_channels(report: FileReport) -> list[str]:
    if not report.unknown_channels:
        return []
    ids = ", ".join(f"{cid} ({n})" for cid, n in sorted(report.unknown_channels.items()))
    n = sum(report.unknown_channels.values())
    return [
        f"{n} readable message(s) of channel(s) {ids} dropped: their channel record was in an "
        "unreadable stretch and the file has no summary to name them"
    ]


def last_readable_ns(reports: list[FileReport]) -> int | None:
    ends = [r.last_ns for r in reports if r.last_ns is not None]
    return max(ends) if ends else None

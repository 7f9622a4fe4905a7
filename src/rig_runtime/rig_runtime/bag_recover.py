"""Recover a rosbag2 MCAP bag whose writer died (``kill -9``, power loss, a copy cut short).

Such a file ends without its footer and summary: indexed readers (rosbags, ``mcap``'s seeking
reader) refuse it whole. Its complete chunks are still there: :func:`read_records` walks the
file record by record with ``mcap``'s streaming reader (CRCs checked) up to the first record
that is cut or corrupt. :func:`recover_bag` rewrites each such file through the ``mcap``
writer (same schemas, channels, messages and chunk compression; written beside it, then
renamed over it) and rewrites ``metadata.yaml`` from what the files hold, like
``ros2 bag reindex``. :func:`recovered_view` does the same into a temporary directory and
leaves the bag untouched (``aero-rig fit`` of a damaged bag).
"""

import os
import struct
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import yaml
from mcap.exceptions import EndOfFile
from mcap.records import Channel, Chunk, Footer, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from .bag import FileStats, TopicInfo, open_file_writer, write_metadata
from .messages import typestore

_COMPRESSION_NAMES = {"zstd": "zstd", "lz4": "lz4", "": "none"}


@dataclass
class FileReport:
    """What one file of a bag held and what was done with it."""

    name: str
    intact: bool  # had its footer and summary: left as it was
    stats: FileStats
    error: str = ""  # why the read stopped early ('' if the file was whole)
    rewritten: bool = False

    @property
    def last_ns(self) -> int | None:
        return self.stats.end_ns if self.stats.count else None


@dataclass
class _Scan:
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    compression: str = "zstd"
    error: str = ""
    complete: bool = False  # the footer was reached


def format_stamp(ns: int | None) -> str:
    """A receive/log time as UTC ISO 8601 with the raw nanoseconds."""
    if ns is None:
        return "no message"
    iso = datetime.fromtimestamp(ns / 1e9, tz=UTC).isoformat(timespec="microseconds")
    return f"{iso.replace('+00:00', 'Z')} ({ns} ns)"


def read_records(path: Path, scan: _Scan) -> Iterator[Message]:
    """The messages of an MCAP file in file order, up to the first record that is cut or
    corrupt; schemas and channels (and the chunk compression) are collected into ``scan``, and
    why the walk stopped into ``scan.error``. Only whole chunks yield messages."""
    with path.open("rb") as f:
        reader = StreamReader(f, emit_chunks=True, validate_crcs=True)
        try:
            for record in reader.records:
                if isinstance(record, Chunk):
                    scan.compression = _COMPRESSION_NAMES.get(record.compression, "zstd")
                    inner = breakup_chunk(record, validate_crc=True)
                    # A chunk is written whole, then its messages count (the walk may stop at
                    # the next record).
                    for rec in inner:
                        _collect(rec, scan)
                    yield from (r for r in inner if isinstance(r, Message))
                elif isinstance(record, Message):
                    yield record
                elif isinstance(record, Footer):
                    scan.complete = True
                else:
                    _collect(record, scan)
        except (EndOfFile, struct.error):  # a record cut short: the end of what was written
            scan.error = "cut short, no footer"
        except Exception as exc:  # a corrupt record: the end of what is readable
            scan.error = f"{type(exc).__name__}: {exc}".rstrip(": ")
        if not scan.complete and not scan.error:
            scan.error = "no footer"


def _collect(record: Any, scan: _Scan) -> None:
    if isinstance(record, Schema):
        scan.schemas[record.id] = record
    elif isinstance(record, Channel):
        scan.channels[record.id] = record


def _summary(path: Path) -> Any:
    """The file's MCAP summary (footer and summary section), or None when it has none."""
    from mcap.reader import make_reader

    try:
        with path.open("rb") as f:
            return make_reader(f).get_summary()
    except Exception:
        return None


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
    return FileReport(src.name, False, stats, scan.error, rewritten=True)


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
        if summary is not None:
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


def recovered_view(bag: str | Path) -> tuple[Path, list[FileReport]]:
    """A readable copy of ``bag`` in a new temporary directory (the caller removes it)."""
    view = Path(tempfile.mkdtemp(prefix="rig_bag_view_")) / Path(bag).name
    return view, recover_bag(bag, into=view)


def describe(reports: list[FileReport]) -> list[str]:
    """Lines for people: per file what was readable, per topic how many messages."""
    lines = []
    for r in reports:
        if r.intact:
            state = "whole (footer and summary present), left as it was"
        elif r.error == "file missing":
            state = "missing"
        else:
            state = f"damaged ({r.error}); rewritten with a footer"
        lines.append(
            f"{r.name}: {state}; {r.stats.count} messages, last readable time "
            f"{format_stamp(r.last_ns)}"
        )
        lines += [f"  {topic}: {n}" for topic, n in sorted(r.stats.counts.items())]
    return lines


def last_readable_ns(reports: list[FileReport]) -> int | None:
    ends = [r.last_ns for r in reports if r.last_ns is not None]
    return max(ends) if ends else None

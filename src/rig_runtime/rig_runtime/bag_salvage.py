"""Read every intact chunk of a damaged MCAP file, and name what the damaged ones held.

A bad sector, a copy that went wrong or a stray write can corrupt a chunk in the middle of a
file: its decompression or its CRC fails. Readers that stop there (rosbags, ``mcap``'s own
readers) lose everything after it, though the later chunks are whole. :func:`salvage_records`
yields the messages of every chunk that decompresses with a matching CRC and records each
stretch it could not read as a :class:`Gap` (byte range, time span, messages lost per topic).

- **With a summary** (footer present, summary CRC valid): the chunk index drives the read. Each
  chunk is read at its indexed offset; a damaged one is skipped, its time span is the index's
  first..last log time and its per-topic message counts come from its message index records
  (offsets from the chunk index), when those are readable.
- **Without one** (the writer died, the file was cut, or the summary itself is damaged): the
  records are walked in file order with ``mcap``'s :class:`~mcap.stream_reader.StreamReader`.
  A chunk whose decompression or CRC fails is skipped and the walk goes on with the record after
  it; its counts come from the message index records that follow it in the data section. When
  the record framing itself is broken, the walk resynchronises on the next chunk record that
  decompresses with a matching CRC (found by its compression field). The time span is the
  chunk header's when it lies between the neighbouring readable messages, else the open
  interval between those messages; counts that no index gives are reported as unknown.

:mod:`rig_runtime.bag_recover` writes the result as a new, whole file (``aero-rig bag recover``,
and the temporary view ``aero-rig fit`` reads a damaged bag through).
"""

import mmap
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError, RecordLengthLimitExceeded
from mcap.opcode import Opcode
from mcap.reader import FOOTER_SIZE
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Message,
    MessageIndex,
    Schema,
)
from mcap.stream_reader import MAGIC_SIZE, StreamReader, breakup_chunk, read_magic
from mcap.summary import Summary

COMPRESSION_NAMES = {"zstd": "zstd", "lz4": "lz4", "": "none"}  # MCAP name -> BagWriter's
# Bytes from a chunk record's opcode to its compression string's length prefix: opcode (1),
# record length (8), message start and end time (8 + 8), uncompressed size (8) and CRC (4).
_COMPRESSION_FIELD = 1 + 8 + 8 + 8 + 8 + 4


@dataclass
class Gap:
    """A stretch of a file that could not be read: one damaged chunk, or damaged bytes up to
    the next readable chunk."""

    offset: int  # byte offset where the unreadable stretch starts
    end_offset: int  # where reading resumed (or the end of the file)
    error: str  # why it could not be read
    # The log (receive) times of the lost messages: first..last when ``exact``, else the open
    # interval between the neighbouring readable messages (None: no such message).
    start_ns: int | None = None
    end_ns: int | None = None
    exact: bool = False
    span_from: str = ""  # "chunk index", "chunk header", "neighbouring readable messages"
    lost: dict[str, int] | None = None  # messages lost per topic; None: unknown
    # The damaged chunk's header (start, end), checked against the neighbours before use.
    _header: tuple[int, int] | None = field(default=None, repr=False)

    @property
    def lost_count(self) -> int | None:
        return None if self.lost is None else sum(self.lost.values())


@dataclass
class Scan:
    """What a walk of one file found: schemas, channels, chunk compression, the unreadable
    stretches, and why it stopped early ('' when it read to the end)."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    compression: str = "zstd"
    error: str = ""
    complete: bool = False  # the footer was reached (or the summary was read)
    indexed: bool = False  # read through the summary's chunk index
    chunks: int = 0  # chunks read
    gaps: list[Gap] = field(default_factory=list)
    # Messages of a channel whose Channel record was lost with a damaged chunk (no summary).
    unknown_channels: dict[int, int] = field(default_factory=dict)

    def topic(self, channel_id: int) -> str:
        channel = self.channels.get(channel_id)
        return channel.topic if channel is not None else f"channel {channel_id}"


def describe_error(exc: BaseException) -> str:
    if isinstance(exc, (EndOfFile, struct.error)):
        return "cut short"
    return f"{type(exc).__name__}: {exc}".rstrip(": ")


def summary_of(data: Any) -> tuple[Summary | None, str]:
    """The file's summary when its footer is there and its summary CRC matches, else None and
    why not ('' for a whole file written without a summary)."""
    from mcap.reader import SeekingReader

    size = len(data)
    if size < 2 * MAGIC_SIZE + FOOTER_SIZE:
        return None, "no footer"
    try:
        data.seek(size - MAGIC_SIZE)
        read_magic(ReadDataStream(data))
        data.seek(size - MAGIC_SIZE - FOOTER_SIZE)
        footer = next(StreamReader(data, skip_magic=True, record_size_limit=FOOTER_SIZE).records)
    except Exception:
        return None, "no footer"
    if not isinstance(footer, Footer):
        return None, "no footer"
    if footer.summary_start == 0:
        return None, ""
    crc_end = size - MAGIC_SIZE - 4  # the summary CRC covers up to the footer's CRC field
    if footer.summary_start >= crc_end:
        return None, "footer damaged"
    if (
        footer.summary_crc
        and zlib.crc32(data[footer.summary_start : crc_end]) != footer.summary_crc
    ):
        return None, "summary damaged (CRC mismatch)"
    try:
        data.seek(0)
        summary = SeekingReader(data).get_summary()
    except Exception as exc:
        return None, f"summary unreadable ({describe_error(exc)})"
    return summary, ""


def file_summary(path: str | Path) -> Summary | None:
    """The summary of an MCAP file when its footer is there and its summary CRC matches."""
    try:
        with Path(path).open("rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return summary_of(data)[0]
    except (OSError, ValueError):  # unreadable, or empty (mmap refuses an empty file)
        return None


def salvage_records(path: str | Path, scan: Scan) -> Iterator[Message]:
    """The messages of every readable chunk of an MCAP file (in file order); schemas,
    channels, compression, the unreadable stretches and why the read stopped early go into
    ``scan``."""
    path = Path(path)
    with path.open("rb") as f:
        if path.stat().st_size == 0:
            scan.error = "empty file"
            return
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            try:
                read_magic(ReadDataStream(data))  # type: ignore[arg-type]
            except Exception as exc:
                scan.error = describe_error(exc)
                return
            summary, why = summary_of(data)
            if summary is not None and summary.chunk_indexes:
                yield from _indexed(data, summary, scan)
            else:
                yield from _walk(data, scan, why)


def _indexed(data: Any, summary: Summary, scan: Scan) -> Iterator[Message]:
    scan.indexed = scan.complete = True
    scan.schemas.update(summary.schemas)
    scan.channels.update(summary.channels)
    for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        try:
            data.seek(ci.chunk_start_offset)
            reader = StreamReader(data, skip_magic=True, emit_chunks=True,
                                  record_size_limit=ci.chunk_length)  # fmt: skip
            chunk = next(reader.records)
            if not isinstance(chunk, Chunk):
                raise McapError(f"no chunk record at byte {ci.chunk_start_offset}")
            records = breakup_chunk(chunk, validate_crc=True)
        except Exception as exc:
            scan.gaps.append(
                Gap(
                    ci.chunk_start_offset,
                    ci.chunk_start_offset + ci.chunk_length,
                    describe_error(exc),
                    ci.message_start_time,
                    ci.message_end_time,
                    exact=True,
                    span_from="chunk index",
                    lost=_indexed_lost(data, ci, scan),
                )
            )
            continue
        scan.compression = COMPRESSION_NAMES.get(chunk.compression, "zstd")
        scan.chunks += 1
        for rec in records:
            if isinstance(rec, Message):
                yield rec
            else:
                _collect(rec, scan)


def _indexed_lost(data: Any, ci: ChunkIndex, scan: Scan) -> dict[str, int] | None:
    """Messages per topic of a chunk, from its message index records (None if unreadable)."""
    lost: dict[str, int] = {}
    try:
        for cid, offset in ci.message_index_offsets.items():
            data.seek(offset)
            reader = StreamReader(data, skip_magic=True,
                                  record_size_limit=ci.message_index_length)  # fmt: skip
            index = next(reader.records)
            if not _index_fits(index, cid, (ci.message_start_time, ci.message_end_time)):
                return None
            assert isinstance(index, MessageIndex)
            topic = scan.topic(cid)
            lost[topic] = lost.get(topic, 0) + len(index.records)
    except Exception:
        return None
    return lost


def _index_fits(index: Any, channel_id: int | None, span: tuple[int, int] | None) -> bool:
    """A message index record that belongs to the chunk (its times within the chunk's)."""
    if not isinstance(index, MessageIndex):
        return False
    if channel_id is not None and index.channel_id != channel_id:
        return False
    return span is None or all(span[0] <= t <= span[1] for t, _ in index.records)


def _walk(data: Any, scan: Scan, why: str) -> Iterator[Message]:
    """Records in file order, skipping what cannot be read (see the module docstring)."""
    size = len(data)
    pos = MAGIC_SIZE
    last_ns: int | None = None  # the latest log time read so far
    pending: list[Gap] = []  # gaps waiting for the first readable message after them
    counting: Gap | None = None  # a damaged chunk whose message index records come next
    after_data = False  # past the DataEnd record: the summary section
    index_end: int | None = None  # where the last readable chunk's message index ends
    while True:
        data.seek(pos)
        reader = StreamReader(data, skip_magic=True, emit_chunks=True, record_size_limit=size - pos)
        try:
            for record in reader.records:
                start, pos = pos, data.tell()
                if counting is not None and not isinstance(record, MessageIndex):
                    if counting.lost == {}:  # no message index followed it
                        counting.lost = None
                    counting = None
                if isinstance(record, Chunk):
                    try:
                        records = breakup_chunk(record, validate_crc=True)
                    except Exception as exc:
                        counting = Gap(start, pos, describe_error(exc), lost={})
                        counting._header = (record.message_start_time, record.message_end_time)
                        index_end = None
                        _open(counting, last_ns, scan, pending)
                        continue
                    scan.compression = COMPRESSION_NAMES.get(record.compression, "zstd")
                    scan.chunks += 1
                    messages = []
                    for rec in records:
                        if isinstance(rec, Message):
                            messages.append(rec)
                        else:
                            _collect(rec, scan)
                    # Its message index records (one per channel) end here, if the writer
                    # put them right after it, as the spec lays out.
                    per_channel: dict[int, int] = {}
                    for m in messages:
                        per_channel[m.channel_id] = per_channel.get(m.channel_id, 0) + 1
                    index_end = pos + sum(15 + 16 * n for n in per_channel.values())
                    if messages:
                        _close(pending, min(m.log_time for m in messages))
                        last_ns = max(last_ns or 0, *(m.log_time for m in messages))
                    yield from _known(messages, scan)
                elif isinstance(record, MessageIndex):
                    if counting is not None and counting.lost is not None:
                        if _index_fits(record, None, counting._header):
                            topic = scan.topic(record.channel_id)
                            counting.lost[topic] = counting.lost.get(topic, 0) + len(record.records)
                        else:
                            counting.lost = None
                elif isinstance(record, Message):  # a file written without chunks
                    _close(pending, record.log_time)
                    last_ns = max(last_ns or 0, record.log_time)
                    yield from _known([record], scan)
                elif isinstance(record, Footer):
                    scan.complete = True
                else:
                    if isinstance(record, DataEnd):
                        after_data = True
                    if not after_data or isinstance(record, (Schema, Channel)):
                        _collect(record, scan)
            break  # the footer was read
        except Exception as exc:
            if after_data:  # the messages are all read; the summary is what is damaged
                scan.error = why or f"summary section unreadable ({describe_error(exc)})"
                break
            resume_from = pos
            if counting is not None and pos < size:  # (pos == size: the file just ends)
                resume_from = counting.offset  # its length may be what is damaged: search
                counting.lost = None  # inside it; what follows it may be lost too: the span
                counting._header = None  # is the one between the neighbouring messages
            nxt = _next_chunk(data, resume_from + 1, scan)
            if nxt is None:  # the tail: a record that runs past the end, or garbage
                cut = isinstance(exc, (EndOfFile, struct.error, RecordLengthLimitExceeded))
                scan.error = "cut short, no footer" if cut else describe_error(exc)
                if counting is not None:
                    counting.end_offset = size
                break
            if counting is not None:
                counting.end_offset = nxt
            elif nxt == index_end:
                pass  # only the message index records of the chunk before were damaged
            else:
                gap = Gap(pos, nxt, describe_error(exc))
                _open(gap, last_ns, scan, pending)
            counting = None
            pos = nxt
    _close(pending, None)
    if not scan.error and (why or not scan.complete):
        scan.error = why or "no footer"  # e.g. the footer was read but the summary is damaged


def _open(gap: Gap, last_ns: int | None, scan: Scan, pending: list[Gap]) -> None:
    gap.start_ns = last_ns
    scan.gaps.append(gap)
    pending.append(gap)


def _close(pending: list[Gap], next_ns: int | None) -> None:
    """The first readable message after these gaps is at ``next_ns`` (None: there is none):
    their span is the chunk header's when it lies between the neighbours, else the interval
    between the neighbours."""
    for gap in pending:
        before = gap.start_ns
        header = gap._header
        if (
            header is not None
            and header[0] <= header[1]
            and (before is None or before <= header[0])
            and (next_ns is None or header[1] <= next_ns)
        ):
            gap.start_ns, gap.end_ns = header
            gap.exact, gap.span_from = True, "chunk header"
        else:
            gap.end_ns = next_ns
            gap.span_from = "neighbouring readable messages"
            if gap.lost is not None and header is not None:
                gap.lost = None  # counted against a header that is not plausible
    pending.clear()


def _known(messages: list[Message], scan: Scan) -> Iterator[Message]:
    for m in messages:
        if m.channel_id in scan.channels:
            yield m
        else:
            scan.unknown_channels[m.channel_id] = scan.unknown_channels.get(m.channel_id, 0) + 1


def _collect(record: Any, scan: Scan) -> None:
    if isinstance(record, Schema):
        scan.schemas[record.id] = record
    elif isinstance(record, Channel):
        scan.channels[record.id] = record


def _next_chunk(data: Any, start: int, scan: Scan) -> int | None:
    """The offset of the next chunk record at or after ``start`` that decompresses with a
    matching CRC (a chunk without CRC is not trusted here), found by its compression field."""
    names = [n for n, ours in COMPRESSION_NAMES.items() if ours == scan.compression]
    if not scan.chunks:  # no chunk read yet: any compression
        names = list(COMPRESSION_NAMES)
    patterns = [struct.pack("<I", len(n)) + n.encode() for n in names]
    pos = start
    while True:
        hits = [
            i - _COMPRESSION_FIELD
            for p in patterns
            if (i := data.find(p, pos + _COMPRESSION_FIELD)) >= 0
        ]
        if not hits:
            return None
        candidate = min(hits)
        if _chunk_at(data, candidate):
            return candidate
        pos = candidate + 1


def _chunk_at(data: Any, offset: int) -> bool:
    if data[offset] != Opcode.CHUNK:
        return False
    (length,) = struct.unpack_from("<Q", data, offset + 1)
    if offset + 9 + length > len(data):
        return False
    try:
        chunk = Chunk.read(ReadDataStream(BytesIO(data[offset + 9 : offset + 9 + length])))
        if not chunk.uncompressed_crc:
            return False
        breakup_chunk(chunk, validate_crc=True)
    except Exception:
        return False
    return True

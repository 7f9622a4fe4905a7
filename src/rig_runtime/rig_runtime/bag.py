"""A rosbag2 (MCAP) writer that survives ``kill -9``: the bag is split into files.

rosbags' MCAP writer makes a file readable only when it is closed (the footer and summary
come last). So the recorder rotates files: every ``split_seconds`` of wall time (or
``split_bytes``) the current ``<bag>_<i>.mcap`` is closed and ``metadata.yaml`` is rewritten
atomically (temp file + rename) to list the closed files. After SIGINT/SIGTERM the last file
is closed too. After ``kill -9`` the bag holds every closed file: what is lost is at most the
last ``split_seconds`` of data (the open file, not listed in metadata.yaml). This is what
``ros2 bag record --max-bag-duration`` does, with a short default.
"""

import struct
import time
from dataclasses import dataclass, field
from io import StringIO
from pathlib import Path
from typing import Any

from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    MessageDefinition,
    MessageDefinitionFormat,
)
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.rosbag2.storage_mcap import McapWriter
from ruamel.yaml import YAML

from .messages import normalize_type_name, typestore
from .qos import PROFILES, QosProfile

BAG_VERSION = 9


class _McapFile(McapWriter):
    """rosbags' MCAP storage writer, but with a file name of our choosing (for splits)."""

    def __init__(self, file: Path) -> None:
        # McapWriter names its single file after the bag directory; reuse all of its record
        # writing by letting it create the file in a scratch dir, then moving it in place.
        scratch = file.with_suffix(".opening")
        scratch.mkdir()
        super().__init__(scratch, CompressionMode.NONE)
        self.bio.close()
        created = self.path
        created.replace(file)
        scratch.rmdir()
        self.path = file
        self.bio = file.open("ab")

    # MCAP Message record (opcode 0x05): u64 length, u16 channel, u32 sequence, u64 log time,
    # u64 publish time, data. The same bytes as McapWriter.write builds field by field, packed
    # at once: the recorder writes thousands of messages per second.
    _MESSAGE_HEAD = struct.Struct("<BQHIQQ")

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        self.message_start_time = min(timestamp, self.message_start_time)
        self.message_end_time = max(timestamp, self.message_end_time)
        self.channel_stats[connection.id] += 1
        chunk = self.chunk
        chunk.message_start_time = min(timestamp, chunk.message_start_time)
        chunk.message_end_time = max(timestamp, chunk.message_end_time)
        chunk.msgs[connection.id].append((timestamp, chunk.bio.tell()))
        length = 2 + 4 + 8 + 8 + len(data)
        chunk.bio.write(
            self._MESSAGE_HEAD.pack(0x05, length, connection.id, 0, timestamp, timestamp)
        )
        chunk.bio.write(data)
        if chunk.bio.tell() > 2**20:
            self.close_chunk()


@dataclass
class _FileStats:
    name: str
    start_ns: int = 2**63 - 1
    end_ns: int = 0
    count: int = 0
    counts: dict[int, int] = field(default_factory=dict)


class SplitBagWriter:
    """Write a rosbag2 directory of MCAP files that stays readable at every split."""

    def __init__(
        self, path: str | Path, split_seconds: float = 5.0, split_bytes: int = 256 * 2**20
    ) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise FileExistsError(f"bag {self.path} exists already; choose a new output path")
        self.path.mkdir(parents=True)
        self.split_seconds = split_seconds
        self.split_bytes = split_bytes
        self.connections: list[Connection] = []
        self._by_topic: dict[str, Connection] = {}
        self._closed: list[_FileStats] = []
        self._committed_counts: dict[int, int] = {}
        self._file: _McapFile | None = None
        self._stats: _FileStats | None = None
        self._file_types: set[str] = set()
        self._file_conns: set[int] = set()
        self._opened_at = 0.0
        self._index = 0
        self._write_metadata()

    def add_connection(self, topic: str, type_name: str, qos: QosProfile | None = None) -> int:
        """Register a topic; returns the connection id to pass to :meth:`write`."""
        if topic in self._by_topic:
            return self._by_topic[topic].id
        msgtype = normalize_type_name(type_name)
        msgdef, _ = typestore().generate_msgdef(msgtype, ros_version=2)
        conn = Connection(
            id=len(self.connections) + 1,
            topic=topic,
            msgtype=msgtype,
            msgdef=MessageDefinition(MessageDefinitionFormat.MSG, msgdef),
            digest=typestore().hash_rihs01(msgtype),
            msgcount=0,
            ext=ConnectionExtRosbag2(
                serialization_format="cdr",
                offered_qos_profiles=[(qos or PROFILES["default"]).to_rosbags_qos()],
            ),
            owner=self,
        )
        self.connections.append(conn)
        self._by_topic[topic] = conn
        self._committed_counts[conn.id] = 0
        return conn.id

    def write(self, connection_id: int, timestamp_ns: int, data: bytes | memoryview) -> None:
        if self._file is not None and self._should_split():
            self.split()
        if self._file is None:
            self._open_file()
        assert self._file is not None and self._stats is not None
        conn = self.connections[connection_id - 1]
        if conn.msgtype not in self._file_types:
            self._file.add_msgtype(conn)
            self._file_types.add(conn.msgtype)
        if conn.id not in self._file_conns:
            self._file.add_connection(conn, _qos_yaml(conn))
            self._file_conns.add(conn.id)
        self._file.write(conn, timestamp_ns, data)
        stats = self._stats
        stats.start_ns = min(stats.start_ns, timestamp_ns)
        stats.end_ns = max(stats.end_ns, timestamp_ns)
        stats.count += 1
        stats.counts[conn.id] = stats.counts.get(conn.id, 0) + 1

    def _should_split(self) -> bool:
        assert self._file is not None
        return (
            time.monotonic() - self._opened_at >= self.split_seconds
            or self._file.bio.tell() + self._file.chunk.bio.tell() >= self.split_bytes
        )

    def maybe_split(self) -> None:
        """Close the open file if it is due (call from a timer so quiet periods finalise)."""
        if self._file is not None and self._should_split():
            self.split()

    def _open_file(self) -> None:
        name = f"{self.path.name}_{self._index}.mcap"
        self._index += 1
        self._file = _McapFile(self.path / name)
        self._stats = _FileStats(name)
        self._file_types = set()
        self._file_conns = set()
        self._opened_at = time.monotonic()

    def split(self) -> None:
        """Close the open file and list it in metadata.yaml (it is readable from now on)."""
        if self._file is None or self._stats is None:
            return
        self._file.close(BAG_VERSION, _yaml_dump(self._info(extra=self._stats)))
        self._closed.append(self._stats)
        for cid, count in self._stats.counts.items():
            self._committed_counts[cid] += count
        self._file = None
        self._stats = None
        self._write_metadata()

    def close(self) -> None:
        self.split()
        self._write_metadata()

    @property
    def message_count(self) -> int:
        return sum(self._committed_counts.values()) + (self._stats.count if self._stats else 0)

    def _info(self, extra: _FileStats | None = None) -> dict[str, Any]:
        files = [*self._closed, *([extra] if extra else [])]
        counts = dict(self._committed_counts)
        if extra:
            for cid, count in extra.counts.items():
                counts[cid] = counts.get(cid, 0) + count
        written = [f for f in files if f.count]
        start = min((f.start_ns for f in written), default=0)
        end = max((f.end_ns for f in written), default=0)
        return {
            "version": BAG_VERSION,
            "storage_identifier": "mcap",
            "relative_file_paths": [f.name for f in files],
            "duration": {"nanoseconds": max(0, end - start)},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": sum(f.count for f in files),
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": c.topic,
                        "type": c.msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": dump_qos_v9(c.ext.offered_qos_profiles),  # type: ignore[union-attr]
                        "type_description_hash": c.digest,
                    },
                    "message_count": counts.get(c.id, 0),
                }
                for c in self.connections
            ],
            "compression_format": "",
            "compression_mode": "",
            "files": [
                {
                    "path": f.name,
                    "starting_time": {"nanoseconds_since_epoch": f.start_ns if f.count else 0},
                    "duration": {"nanoseconds": max(0, f.end_ns - f.start_ns) if f.count else 0},
                    "message_count": f.count,
                }
                for f in files
            ],
            "custom_data": None,
            "ros_distro": "jazzy",
        }

    def _write_metadata(self) -> None:
        text = _yaml_dump({"rosbag2_bagfile_information": self._info()})
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(text)
        tmp.replace(self.path / "metadata.yaml")


def _qos_yaml(conn: Connection) -> str:
    return _yaml_dump(dump_qos_v9(conn.ext.offered_qos_profiles)).strip()  # type: ignore[union-attr]


def _yaml_dump(data: Any) -> str:
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    stream = StringIO()
    yaml.dump(data, stream)
    return stream.getvalue()

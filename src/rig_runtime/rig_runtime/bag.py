"""A rosbag2 (MCAP) writer: chunk-compressed, split on demand, readable after ``kill -9``.

Files are written by Foxglove's ``mcap`` writer (the MCAP reference library) with zstd (or lz4,
or no) chunk compression, as ``ros2 bag record -s mcap`` does with a compressing storage preset.
Like rosbag2, ``metadata.yaml`` then says ``compression_format: ''`` and
``compression_mode: ''``: those fields describe rosbag2's own file/message compression, and the
chunk compression lives inside the MCAP storage (rosbags writes the same for its storage-level
compression).

One file per bag, unless the user asks for splits: ``max_bag_size`` [bytes] and
``max_bag_duration`` [ns of recorded time] start a new ``<bag>_<i>.mcap`` when the open file
reaches them (0: off), as ``ros2 bag record --max-bag-size/--max-bag-duration`` do.

Crash safety: :meth:`BagWriter.flush` closes the open chunk and hands it to the OS; the recorder
calls it every ``flush_s``, so after ``kill -9`` every message older than that is in a complete
chunk on disk. Such a file has no footer or summary; ``metadata.yaml`` (rewritten atomically
whenever a file is opened or closed) lists it. :mod:`rig_runtime.bag_recover` reads it up to
its last complete chunk and rewrites it with a footer (``aero-rig bag recover``, like
``ros2 bag reindex``).
"""

from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib.metadata import version
from io import StringIO
from pathlib import Path
from typing import IO, Any

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    MessageDefinition,
    MessageDefinitionFormat,
)
from rosbags.rosbag2.metadata import dump_qos_v9
from ruamel.yaml import YAML

from .messages import normalize_type_name, typestore
from .qos import PROFILES, QosProfile

BAG_VERSION = 9  # rosbag2 Jazzy's metadata.yaml version
COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
CHUNK_SIZE = 2**20  # uncompressed bytes per chunk (the mcap writer's default)
LIBRARY = f"rig_runtime; mcap {version('mcap')}"


@dataclass
class FileStats:
    """What metadata.yaml says about one file of the bag."""

    name: str
    start_ns: int = 2**63 - 1
    end_ns: int = 0
    count: int = 0
    counts: dict[str, int] = field(default_factory=dict)  # per topic

    def add(self, topic: str, timestamp_ns: int) -> None:
        self.start_ns = min(self.start_ns, timestamp_ns)
        self.end_ns = max(self.end_ns, timestamp_ns)
        self.count += 1
        self.counts[topic] = self.counts.get(topic, 0) + 1


@dataclass
class TopicInfo:
    """A topic as metadata.yaml lists it."""

    name: str
    type: str
    offered_qos_profiles: list[Any]  # rosbag2 v9: a list of QoS mappings
    type_description_hash: str
    serialization_format: str = "cdr"


def open_file_writer(
    stream: IO[bytes], compression: str, chunk_size: int = CHUNK_SIZE
) -> McapWriter:
    writer = McapWriter(stream, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
    writer.start(profile="ros2", library=LIBRARY)
    return writer


class BagWriter:
    """Write a rosbag2 directory of chunk-compressed MCAP files."""

    def __init__(
        self,
        path: str | Path,
        compression: str = "zstd",
        max_bag_size: int = 0,
        max_bag_duration_ns: int = 0,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(
                f"compression {compression!r} unknown: one of {', '.join(COMPRESSIONS)}"
            )
        if max_bag_size < 0 or max_bag_duration_ns < 0:
            raise ValueError("max_bag_size and max_bag_duration must be >= 0 (0: no split)")
        self.path = Path(path)
        if self.path.exists():
            raise FileExistsError(f"bag {self.path} exists already; choose a new output path")
        self.path.mkdir(parents=True)
        self.compression = compression
        self.max_bag_size = max_bag_size
        self.max_bag_duration_ns = max_bag_duration_ns
        # A file is checked against max_bag_size as its chunks are written: chunks of at most a
        # quarter of it keep the overshoot small.
        self.chunk_size = (
            min(CHUNK_SIZE, max(max_bag_size // 4, 4096)) if max_bag_size else CHUNK_SIZE
        )
        self.connections: list[Connection] = []
        self._by_topic: dict[str, Connection] = {}
        self._files: list[FileStats] = []
        self._stream: IO[bytes] | None = None
        self._mcap: McapWriter | None = None
        self._stats: FileStats | None = None
        self._schemas: dict[str, int] = {}  # msgtype -> schema id in the open file
        self._channels: dict[int, int] = {}  # connection id -> channel id in the open file
        self._closed = False
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
        return conn.id

    def write(self, connection_id: int, timestamp_ns: int, data: bytes | memoryview) -> None:
        mcap = self._mcap
        stats = self._stats
        if (
            mcap is None
            or stats is None
            or ((self.max_bag_size or self.max_bag_duration_ns) and self._split_due(timestamp_ns))
        ):
            mcap, stats = self._next_file()
        channel = self._channels.get(connection_id)
        if channel is None:
            channel = self._add_channel(self.connections[connection_id - 1])
        mcap.add_message(channel, timestamp_ns, bytes(data), timestamp_ns)
        stats.add(self.connections[connection_id - 1].topic, timestamp_ns)

    def _split_due(self, timestamp_ns: int) -> bool:
        stats = self._stats
        if stats is None or not stats.count:
            return False
        if self.max_bag_duration_ns and timestamp_ns - stats.start_ns >= self.max_bag_duration_ns:
            return True
        return bool(self.max_bag_size and self._file_size() >= self.max_bag_size)

    def _file_size(self) -> int:
        """Bytes of the open file written so far (closed chunks: a file may pass max_bag_size
        by up to one chunk, a quarter of max_bag_size at most)."""
        assert self._stream is not None
        return self._stream.tell()

    def _next_file(self) -> tuple[McapWriter, FileStats]:
        self._close_file()
        name = f"{self.path.name}_{len(self._files)}.mcap"
        self._stream = (self.path / name).open("xb")
        self._mcap = open_file_writer(self._stream, self.compression, self.chunk_size)
        self._stats = FileStats(name)
        self._files.append(self._stats)
        self._schemas = {}
        self._channels = {}
        self._write_metadata()
        return self._mcap, self._stats

    def _add_channel(self, conn: Connection) -> int:
        assert self._mcap is not None
        schema = self._schemas.get(conn.msgtype)
        if schema is None:
            schema = self._mcap.register_schema(conn.msgtype, "ros2msg", conn.msgdef.data.encode())
            self._schemas[conn.msgtype] = schema
        channel = self._mcap.register_channel(
            conn.topic,
            "cdr",
            schema,
            {"offered_qos_profiles": _qos_yaml(conn), "topic_type_hash": conn.digest},
        )
        self._channels[conn.id] = channel
        return channel

    def flush(self) -> None:
        """Close the open chunk and hand it to the OS: everything written so far survives
        ``kill -9`` of this process (the recorder calls this every flush_s). metadata.yaml,
        rewritten whenever a file is opened or closed, lists the open file already; its counts
        are those of the closed files until :func:`rig_runtime.bag_recover.recover_bag`."""
        if self._mcap is not None:
            self._mcap.flush()

    def _close_file(self) -> None:
        if self._mcap is not None and self._stream is not None:
            self._mcap.finish()
            self._stream.close()
        self._mcap = None
        self._stream = None
        self._stats = None

    def close(self) -> None:
        if self._closed:
            return
        self._close_file()
        self._closed = True
        self._write_metadata()

    @property
    def message_count(self) -> int:
        return sum(f.count for f in self._files)

    @property
    def files(self) -> list[str]:
        return [f.name for f in self._files]

    def topics(self) -> list[TopicInfo]:
        return [
            TopicInfo(
                c.topic,
                c.msgtype,
                dump_qos_v9(c.ext.offered_qos_profiles),  # type: ignore[union-attr]
                c.digest,
            )
            for c in self.connections
        ]

    def _write_metadata(self) -> None:
        write_metadata(self.path, self._files, self.topics())


def bag_info(files: Sequence[FileStats], topics: Sequence[TopicInfo]) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of metadata.yaml (version 9, Jazzy)."""
    written = [f for f in files if f.count]
    start = min((f.start_ns for f in written), default=0)
    end = max((f.end_ns for f in written), default=0)
    counts: dict[str, int] = {}
    for f in files:
        for topic, n in f.counts.items():
            counts[topic] = counts.get(topic, 0) + n
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
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": t.serialization_format,
                    "offered_qos_profiles": t.offered_qos_profiles,
                    "type_description_hash": t.type_description_hash,
                },
                "message_count": counts.get(t.name, 0),
            }
            for t in topics
        ],
        # rosbag2's own (file/message) compression: none. The MCAP chunks carry theirs.
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


def write_metadata(bag: Path, files: Sequence[FileStats], topics: Sequence[TopicInfo]) -> None:
    """Write metadata.yaml atomically (temp file + rename)."""
    text = _yaml_dump({"rosbag2_bagfile_information": bag_info(files, topics)})
    tmp = bag / "metadata.yaml.tmp"
    tmp.write_text(text)
    tmp.replace(bag / "metadata.yaml")


def _qos_yaml(conn: Connection) -> str:
    return _yaml_dump(dump_qos_v9(conn.ext.offered_qos_profiles)).strip()  # type: ignore[union-attr]


def _yaml_dump(data: Any) -> str:
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    stream = StringIO()
    yaml.dump(data, stream)
    return stream.getvalue()

"""Recording streams (``open_recording``/``close_recording``) and bag replay (``view_bag``)."""

from pathlib import Path
from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from rig_runtime.interface import (
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_MODEL,
    IDENTIFICATION_STATUS,
    PITCH_COMMAND,
    PITCH_STATE,
    PRESSURE_TAPS,
    WING_COEFFICIENTS,
)

from .logger import RigViewLogger

# -- recordings ------------------------------------------------------------------------------

MODES = ("save", "spawn", "serve", "connect", "none")


def open_recording(
    application_id: str,
    mode: str,
    rrd_path: str | Path | None = None,
    *,
    port: int = 0,
    url: str = "",
    bind_ip: str = "127.0.0.1",
    blueprint: rrb.Blueprint | None = None,
) -> tuple[rr.RecordingStream, str]:
    """A recording stream with its sinks for ``mode``; returns it and a line saying where to."""
    if mode not in MODES:
        raise ValueError(f"mode {mode!r}: expected one of {list(MODES)}")
    if mode == "save" and not rrd_path:
        raise ValueError(
            "mode 'save' needs rrd_path (e.g. -p rrd_path:=run.rrd), or use -p mode:=spawn"
        )
    rec = rr.RecordingStream(application_id, default_enabled=mode != "none")
    if mode == "none":
        return rec, "rerun off: counting messages only"
    sinks: list[Any] = []
    where = []
    if mode == "spawn":
        rr.spawn(port=port or 9876, connect=False, recording=rec)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{port or 9876}/proxy"))
        where.append(f"spawned viewer on port {port or 9876}")
    elif mode == "serve":
        server = rr.GrpcServerSink(bind_ip, port or 9876)
        sinks.append(server)
        where.append(f"serving at {server.uri}")
    elif mode == "connect":
        sinks.append(rr.GrpcSink(url or None))
        where.append(f"streaming to {url or 'the default viewer address'}")
    if rrd_path:
        path = Path(rrd_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        sinks.append(rr.FileSink(str(path)))
        where.append(f"saving to {path}")
    rec.set_sinks(*sinks, default_blueprint=blueprint)
    return rec, ", ".join(where)


def close_recording(rec: rr.RecordingStream, timeout_s: float = 10.0) -> None:
    """Flush everything logged so far and finalise the sinks (an .rrd gets its footer)."""
    rec.flush(timeout_sec=timeout_s)
    rec.disconnect()


# -- offline ---------------------------------------------------------------------------------

TOPICS: dict[str, tuple[str, str]] = {
    # topic: (type, handler), from the interface contract. QoS for the live node in ViewNode.QOS.
    # A handler named *_cdr (takes_cdr) takes the serialized message: the view draws only
    # every taps_decimation-th Cp distribution, the other tap samples are only counted.
    PITCH_COMMAND.name: (PITCH_COMMAND.type, "on_command"),
    PITCH_STATE.name: (PITCH_STATE.type, "on_state"),
    PRESSURE_TAPS.name: (PRESSURE_TAPS.type, "on_taps_cdr"),
    WING_COEFFICIENTS.name: (WING_COEFFICIENTS.type, "on_coefficients"),
    EXPERIMENT_SEGMENT.name: (EXPERIMENT_SEGMENT.type, "on_segment"),
    IDENTIFICATION_MODEL.name: (IDENTIFICATION_MODEL.type, "on_model"),
    IDENTIFICATION_STATUS.name: (IDENTIFICATION_STATUS.type, "on_status"),
}


# Topics that bags recorded before the rig had its own messages (aero_rig_interfaces) carry
# as std_msgs/String JSON: the handlers read both (RigViewLogger.on_segment, on_model).
LEGACY_TYPES: dict[str, str] = {
    EXPERIMENT_SEGMENT.name: "std_msgs/msg/String",
    IDENTIFICATION_MODEL.name: "std_msgs/msg/String",
}


def _readable(topic: str, msgtype: str) -> bool:
    """Whether the handler of ``topic`` (a TOPICS key) reads a bag's ``msgtype``."""
    return msgtype in (TOPICS[topic][0], LEGACY_TYPES.get(topic))


def takes_cdr(handler: str) -> bool:
    """Whether a ``TOPICS`` handler takes the serialized message (CDR bytes): the live node
    subscribes its topic raw, the bag replay passes the bag's bytes."""
    return handler.endswith("_cdr")


def _route(topic: str) -> str | None:
    """The known topic a bag topic is (exactly, or under a namespace: ``/rig/pitch/state``)."""
    if topic in TOPICS:
        return topic
    return next((t for t in TOPICS if topic.endswith(t)), None)


def view_bag(
    bag_path: str | Path,
    rrd_path: str | Path | None = None,
    spawn: bool = False,
    *,
    application_id: str = "aero_rig",
    taps_decimation: int = 10,
    series_decimation: int = 1,
) -> Path | None:
    """Replay a rosbag2 directory (MCAP or sqlite3) through :class:`RigViewLogger`.

    Writes ``rrd_path`` (default: ``<bag>.rrd`` beside the bag unless ``spawn``), and/or streams
    to a spawned viewer. Returns the .rrd path (None when only spawning). Messages go in bag
    order; an unreadable message is skipped and reported on ``/events/view``. A bag recorded
    before the rig's own messages (segment events and models as std_msgs/String) is drawn too.
    """
    from rosbags.highlevel import AnyReader

    from rig_runtime.messages import typestore

    bag = Path(bag_path)
    if not bag.exists():
        raise FileNotFoundError(f"no bag at {bag}")
    if rrd_path is None and not spawn:
        rrd_path = bag.with_name(bag.name + ".rrd") if bag.is_dir() else bag.with_suffix(".rrd")
    rec, _ = open_recording(application_id, "spawn" if spawn else "save", rrd_path)
    try:
        view = RigViewLogger(
            rec, taps_decimation=taps_decimation, series_decimation=series_decimation
        )
        with AnyReader([bag], default_typestore=typestore()) as reader:
            conns = []
            for conn in reader.connections:
                topic = _route(conn.topic)
                if topic is not None and _readable(topic, conn.msgtype):
                    conns.append((conn, getattr(view, TOPICS[topic][1])))
            handlers = {c.id: h for c, h in conns}
            serialized = {c.id for c, h in conns if takes_cdr(h.__name__)}
            for conn, _t, raw in reader.messages(connections=[c for c, _ in conns]):
                try:
                    if conn.id in serialized:
                        handlers[conn.id](raw)
                    else:
                        handlers[conn.id](reader.deserialize(raw, conn.msgtype))
                except ValueError as exc:
                    known = _route(conn.topic) or conn.topic  # the handlers' errors name it
                    view.warn(conn.topic, str(exc).removeprefix(f"{known}: "))
        view.report()
        view.send_series()
    finally:
        close_recording(rec)
    return Path(rrd_path) if rrd_path else None

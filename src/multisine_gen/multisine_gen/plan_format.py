"""The wire format of an ExperimentPlan: `/experiment/plan` and `/experiment/segment`.

The only place a plan is written or read as JSON. It imports the model (plan.py), never the
other way round. The messages are aero_rig_interfaces' ExperimentPlan (the plan's JSON in
`plan_json`, with the fields a user filters on beside it) and SegmentEvent; bags recorded
before those carried the same JSON in std_msgs/String and are still read.

`plan_to_dict` / `plan_to_json` write a plan with every excitation parameter (phases, lines,
amplitudes, seeds), its limits and its segment records; `plan_from_dict` / `plan_from_json`
rebuild it, so every sample comes out identical, and refuse a payload whose segments disagree
with the ones its excitations produce. `segment_event` is the `/experiment/segment` payload of a
segment's start or end: its record (`segment_to_dict`) and the stamps of its first and last
samples; `segment_event_fields` / `segment_event_from_message` carry any event payload through
a SegmentEvent message and back unchanged.
"""

import json
import math
from dataclasses import asdict, fields
from typing import Any, Literal

import numpy as np

from multisine_gen.multisine import Multisine
from multisine_gen.plan import (
    BaselineSweep,
    ExperimentPlan,
    MultisineLevel,
    PlanError,
    Segment,
    SineTest,
)
from multisine_gen.sine import Sine
from rig_runtime.interface import ActuatorLimits
from rig_runtime.json_payload import json_object

__all__ = [
    "PLAN_FORMAT",
    "PLAN_VERSION",
    "plan_from_dict",
    "plan_from_json",
    "plan_message",
    "plan_to_dict",
    "plan_to_json",
    "read_plan_message",
    "segment_event",
    "segment_event_fields",
    "segment_event_from_message",
    "segment_from_dict",
    "segment_to_dict",
]

PLAN_FORMAT = "multisine_gen/experiment_plan"
PLAN_VERSION = 1


def plan_to_dict(plan: ExperimentPlan) -> dict[str, Any]:
    """The `/experiment/plan` payload of a plan (JSON-safe; `plan_from_dict` inverts it)."""
    realizations = [ms for lv in plan.levels for ms in lv.realizations]
    shared = bool(realizations) and all(
        ms.N == realizations[0].N
        and np.array_equal(ms.excited_lines, realizations[0].excited_lines)
        and np.array_equal(ms.detection_lines, realizations[0].detection_lines)
        for ms in realizations
    )
    return {
        "format": PLAN_FORMAT,
        "version": PLAN_VERSION,
        "fs": plan.fs,
        "N": realizations[0].N if shared else None,
        "excited_lines": realizations[0].excited_lines.tolist() if shared else None,
        "detection_lines": realizations[0].detection_lines.tolist() if shared else None,
        "seed": plan.seed,
        "revision": plan.revision,
        "rest_deg": plan.rest_deg,
        "ramp_rate_deg_s": plan.ramp_rate_deg_s,
        # The ActuatorLimits fields only (a subclass's extra settings are not the plan's).
        "limits": {f.name: getattr(plan.limits, f.name) for f in fields(ActuatorLimits)},
        "baseline": asdict(plan.baseline) if plan.baseline is not None else None,
        "levels": [
            {
                "level": lv.level,
                "offset_deg": lv.offset_deg,
                "std_deg": lv.std_deg,
                "periods": lv.periods,
                "settle_periods": lv.settle_periods,
                "realization_periods": list(lv.realization_periods),
                "realizations": [_multisine_to_dict(ms) for ms in lv.realizations],
            }
            for lv in plan.levels
        ],
        "sines": [
            {
                "level": t.level,
                "frequency_hz": t.sine.frequency_hz,
                "requested_frequency_hz": t.sine.requested_frequency_hz,
                "samples_per_period": t.sine.samples_per_period,
                "amplitude_deg": t.sine.amplitude_deg,
                "offset_deg": t.sine.offset_deg,
                "periods": t.periods,
                "settle_periods": t.settle_periods,
            }
            for t in plan.sines
        ],
        "total_samples": plan.total_samples,
        "duration_s": plan.duration_s,
        "segments": [segment_to_dict(s) for s in plan.segments],
    }


def plan_to_json(plan: ExperimentPlan, indent: int | None = None) -> str:
    """The plan as JSON (floats written with round-trip precision)."""
    return json.dumps(plan_to_dict(plan), indent=indent, allow_nan=False)


def plan_from_dict(data: dict[str, Any]) -> ExperimentPlan:
    """Rebuild a plan from `plan_to_dict` output; PlanError if the payload is of another format
    or version, mistypes a field, or its segments disagree."""
    if data.get("format") != PLAN_FORMAT or data.get("version") != PLAN_VERSION:
        raise PlanError(
            f"not an experiment plan of format {PLAN_FORMAT!r} version {PLAN_VERSION}: got "
            f"format {data.get('format')!r} version {data.get('version')!r}"
        )
    try:
        fs = float(data["fs"])
        levels = tuple(
            MultisineLevel(
                level=int(lv["level"]),
                realizations=tuple(_multisine_from_dict(ms) for ms in lv["realizations"]),
                periods=int(lv["periods"]),
                settle_periods=int(lv["settle_periods"]),
                realization_periods=tuple(int(n) for n in lv.get("realization_periods", ())),
            )
            for lv in data["levels"]
        )
        sines = tuple(
            SineTest(
                level=int(t["level"]),
                sine=Sine(
                    fs=fs,
                    samples_per_period=int(t["samples_per_period"]),
                    amplitude_deg=float(t["amplitude_deg"]),
                    offset_deg=float(t["offset_deg"]),
                    requested_frequency_hz=t["requested_frequency_hz"],
                ),
                periods=int(t["periods"]),
                settle_periods=int(t["settle_periods"]),
            )
            for t in data["sines"]
        )
        baseline = BaselineSweep(**data["baseline"]) if data["baseline"] else None
        plan = ExperimentPlan(
            fs=fs,
            rest_deg=float(data["rest_deg"]),
            ramp_rate_deg_s=float(data["ramp_rate_deg_s"]),
            baseline=baseline,
            levels=levels,
            sines=sines,
            seed=data["seed"],
            limits=ActuatorLimits(**data["limits"]),
            revision=int(data.get("revision", 0)),
        )
    except PlanError:
        raise
    except (KeyError, TypeError, ValueError) as error:
        raise PlanError(f"experiment plan JSON is missing or mistypes a field: {error}") from error
    stored = [segment_from_dict(s) for s in data.get("segments", [])]
    if not _same_segments(stored, plan.segments):
        raise PlanError(
            "experiment plan JSON: its segments disagree with the segments its excitations "
            "produce (edited by hand, or written by another version); regenerate the plan"
        )
    return plan


def plan_from_json(text: str) -> ExperimentPlan:
    """Rebuild a plan from `plan_to_json` output; every sample comes out identical."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise PlanError(f"experiment plan is not valid JSON: {error}") from error
    if not isinstance(data, dict):
        raise PlanError("experiment plan JSON must be an object")
    return plan_from_dict(data)


def plan_message(
    plan: ExperimentPlan,
    t0_ns: int,
    adaptation: dict[str, int] | None = None,
    plan_id: str = "",
) -> dict[str, Any]:
    """The fields of the `/experiment/plan` message (aero_rig_interfaces/ExperimentPlan, but its
    header): the plan's JSON with ``t0_ns``, the stamp of sample 0 (docs/design.md §5), and the
    generator's bounds on an adaptive run's requests (multisine_gen.revision.Adaptation) when
    given; beside it the plan's id, revision, rate, size and levels."""
    payload = plan_to_dict(plan)
    payload["t0_ns"] = int(t0_ns)
    if adaptation is not None:
        payload["adaptation"] = dict(adaptation)
    return {
        "plan_id": plan_id,
        "revision": int(plan.revision),
        "t0_ns": int(t0_ns),
        "fs": float(plan.fs),
        "samples": int(plan.total_samples),
        "levels": len(plan.levels),
        "realizations": [len(lv.realizations) for lv in plan.levels],
        "offsets_deg": [float(lv.offset_deg) for lv in plan.levels],
        "adaptive": adaptation is not None,
        "plan_json": json.dumps(payload, allow_nan=False),
    }


def read_plan_message(msg: Any) -> tuple[ExperimentPlan, int]:
    """The plan and t0_ns of an `/experiment/plan` message (an ExperimentPlan; the std_msgs/String
    of a bag recorded before it; or its JSON text); PlanError when it is not one."""
    try:
        data = json_object(msg, "plan_json", "/experiment/plan")
    except ValueError as error:
        raise PlanError(str(error)) from None
    if not isinstance(data.get("t0_ns"), int):
        raise PlanError("/experiment/plan holds no plan with an integer t0_ns")
    return plan_from_dict(data), int(data["t0_ns"])


def segment_to_dict(segment: Segment) -> dict[str, Any]:
    """A segment's record, as the plan's `segments` and the segment events carry it."""
    return asdict(segment)


def segment_from_dict(values: dict[str, Any]) -> Segment:
    """The segment of a `segment_to_dict` record; PlanError naming any unknown field."""
    known = {f.name for f in fields(Segment)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise PlanError(f"segment has unknown field(s) {unknown}")
    return Segment(**values)


def segment_event(
    segment: Segment, edge: Literal["start", "end"], t0_s: float, fs: float
) -> dict[str, Any]:
    """The `/experiment/segment` payload for a segment's start or end: its record plus the
    stamps of its first and last samples (t0 + k/fs)."""
    payload: dict[str, Any] = {"event": edge}
    payload.update(segment_to_dict(segment))
    payload["start_stamp_s"] = t0_s + segment.start_k / fs
    payload["end_stamp_s"] = t0_s + (segment.stop_k - 1) / fs
    return payload


# SegmentEvent fields that an event payload may leave out, with the value that stands for
# "absent" on the wire (ROS messages have no optional fields): -1, NaN or "".
_ABSENT_INT = -1
_EVENT_INTS = (
    "index", "start_k", "length", "level", "realization", "period", "periods",
    "samples_per_period", "sine_test", "t0_ns", "samples", "planned_samples", "revision",
    "at_k", "after_k", "from_k",
)  # fmt: skip
_EVENT_FLOATS = (
    "offset_deg", "std_deg", "frequency_hz", "amplitude_deg", "start_deg", "end_deg",
    "rate_deg_s", "start_stamp_s", "end_stamp_s", "fs",
)  # fmt: skip
_EVENT_STRINGS = ("kind", "excitation", "direction", "request", "reason", "change", "why")
# The keys of each event's payload, in the order the generator writes them.
_SEGMENT_KEYS = ("event", *(f.name for f in fields(Segment)), "start_stamp_s", "end_stamp_s")
_EVENT_KEYS: dict[str, tuple[str, ...]] = {
    "start": (*_SEGMENT_KEYS, "t0_ns"),
    "end": (*_SEGMENT_KEYS, "t0_ns"),
    "plan_end": ("event", "samples", "fs", "planned_samples", "revision", "t0_ns"),
    "plan_aborted": ("event", "samples", "t0_ns"),
    "decision": (
        "t0_ns", "at_k", "request", "level", "after_k", "reason", "event", "change",
        "revision", "from_k", "samples",
    ),
    "refused": ("t0_ns", "at_k", "request", "level", "after_k", "reason", "event", "why"),
}  # fmt: skip
# Keys a payload of that event may lack (the rest it always has): Segment's optional fields
# (None), a decision's revision (a go_on changes nothing), a refusal's unparsed request.
_OPTIONAL = {f.name for f in fields(Segment) if f.default is None} | {
    "revision", "from_k", "samples", "level", "after_k", "reason", "change",
}  # fmt: skip


def segment_event_fields(payload: dict[str, Any]) -> dict[str, Any]:
    """The SegmentEvent fields (but its header) of an `/experiment/segment` payload: absent
    and None values as -1, NaN or "" (:func:`segment_event_from_message` reverses it)."""
    event = payload.get("event")
    if event not in _EVENT_KEYS:
        raise PlanError(f"/experiment/segment: unknown event {event!r}")
    unknown = sorted(set(payload) - set(_EVENT_KEYS[event]))
    if unknown:
        raise PlanError(f"/experiment/segment {event} event: unknown field(s) {unknown}")
    out: dict[str, Any] = {"event": event}
    for name in _EVENT_INTS:
        value = payload.get(name)
        out[name] = _ABSENT_INT if value is None else int(value)
    for name in _EVENT_FLOATS:
        value = payload.get(name)
        out[name] = math.nan if value is None else float(value)
    for name in _EVENT_STRINGS:
        value = payload.get(name)
        out[name] = "" if value is None else str(value)
    return out


def segment_event_from_message(msg: Any) -> dict[str, Any]:
    """The payload of an `/experiment/segment` message: a SegmentEvent's fields back as the
    generator's dict (the keys its event has, -1/NaN/"" as None), or the JSON of a
    std_msgs/String recorded before SegmentEvent existed. PlanError when it is neither."""
    if hasattr(msg, "data"):
        try:
            return json_object(msg, "data", "/experiment/segment")
        except ValueError as error:
            raise PlanError(str(error)) from None
    event = str(msg.event)
    keys = _EVENT_KEYS.get(event)
    if keys is None:
        raise PlanError(f"/experiment/segment: unknown event {event!r}")
    payload = {}
    for name in keys:
        value = getattr(msg, name)
        if name in _EVENT_INTS:
            value = None if value == _ABSENT_INT else int(value)
        elif name in _EVENT_FLOATS:
            value = None if math.isnan(value) else float(value)
        else:
            value = str(value)
            if name not in ("event", "request", "reason", "change", "why") and value == "":
                value = None
        if value is None and name in _OPTIONAL and event in ("decision", "refused", "plan_end"):
            continue  # a key that payload did not have
        payload[name] = value
    return payload


def _same_segments(a: list[Segment], b: tuple[Segment, ...]) -> bool:
    """Equal records; floats to 1e-9 relative, since another machine's FFT may round the last
    bit of a period sample (a ramp's end) differently."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        for f in fields(Segment):
            u, v = getattr(x, f.name), getattr(y, f.name)
            if isinstance(u, float) and isinstance(v, float):
                if not math.isclose(u, v, rel_tol=1e-9, abs_tol=1e-12):
                    return False
            elif u != v:
                return False
    return True


def _multisine_to_dict(ms: Multisine) -> dict[str, Any]:
    return {
        "fs": ms.fs,
        "N": ms.N,
        "kind": ms.kind,
        "excited_lines": ms.excited_lines.tolist(),
        "detection_lines": ms.detection_lines.tolist(),
        "amplitudes": ms.amplitudes.tolist(),
        "phases": ms.phases.tolist(),
        "offset_deg": ms.offset_deg,
        "std_deg": ms.std_deg,
        "seed": ms.seed,
    }


def _multisine_from_dict(d: dict[str, Any]) -> Multisine:
    return Multisine(
        fs=float(d["fs"]),
        N=int(d["N"]),
        excited_lines=np.array(d["excited_lines"], dtype=np.int64),
        detection_lines=np.array(d["detection_lines"], dtype=np.int64),
        amplitudes=np.array(d["amplitudes"], dtype=float),
        phases=np.array(d["phases"], dtype=float),
        offset_deg=float(d["offset_deg"]),
        std_deg=float(d["std_deg"]),
        seed=d["seed"],
        kind=d["kind"],
    )

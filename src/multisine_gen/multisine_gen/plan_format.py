"""The `/experiment/plan` JSON wire format of an ExperimentPlan.

`plan_to_dict` / `plan_to_json` write a plan with every excitation parameter (phases, lines,
amplitudes, seeds) and its segment records; `plan_from_dict` / `plan_from_json` rebuild it, so
every sample comes out identical, and refuse a payload whose segments disagree with the ones its
excitations produce. ExperimentPlan.to_dict / from_dict / to_json / from_json delegate here.
"""

import json
import math
from dataclasses import asdict, fields
from typing import Any

import numpy as np

from multisine_gen.multisine import Multisine
from multisine_gen.plan import (
    BaselineSweep,
    ExperimentPlan,
    MultisineLevel,
    PlanError,
    PlanLimits,
    Segment,
    SineTest,
)
from multisine_gen.sine import Sine

__all__ = [
    "PLAN_FORMAT",
    "PLAN_VERSION",
    "plan_from_dict",
    "plan_from_json",
    "plan_to_dict",
    "plan_to_json",
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
        "rest_deg": plan.rest_deg,
        "ramp_rate_deg_s": plan.ramp_rate_deg_s,
        "limits": asdict(plan.limits),
        "baseline": asdict(plan.baseline) if plan.baseline is not None else None,
        "levels": [
            {
                "level": lv.level,
                "offset_deg": lv.offset_deg,
                "std_deg": lv.std_deg,
                "periods": lv.periods,
                "settle_periods": lv.settle_periods,
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
        "segments": [s.to_dict() for s in plan.segments],
    }


def plan_to_json(plan: ExperimentPlan, indent: int | None = None) -> str:
    """The plan as JSON (floats written with round-trip precision)."""
    return json.dumps(plan.to_dict(), indent=indent, allow_nan=False)


def plan_from_dict(
    data: dict[str, Any], cls: type[ExperimentPlan] = ExperimentPlan
) -> ExperimentPlan:
    """Rebuild a plan (an instance of cls) from `plan_to_dict` output; PlanError if the payload
    is of another format or version, mistypes a field, or its segments disagree."""
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
        plan = cls(
            fs=fs,
            rest_deg=float(data["rest_deg"]),
            ramp_rate_deg_s=float(data["ramp_rate_deg_s"]),
            baseline=baseline,
            levels=levels,
            sines=sines,
            seed=data["seed"],
            limits=PlanLimits(**data["limits"]),
        )
    except PlanError:
        raise
    except (KeyError, TypeError, ValueError) as error:
        raise PlanError(f"experiment plan JSON is missing or mistypes a field: {error}") from error
    stored = [Segment.from_dict(s) for s in data.get("segments", [])]
    if not _same_segments(stored, plan.segments):
        raise PlanError(
            "experiment plan JSON: its segments disagree with the segments its excitations "
            "produce (edited by hand, or written by another version); regenerate the plan"
        )
    return plan


def plan_from_json(text: str, cls: type[ExperimentPlan] = ExperimentPlan) -> ExperimentPlan:
    """Rebuild a plan from `to_json()` output; every sample comes out identical."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise PlanError(f"experiment plan is not valid JSON: {error}") from error
    if not isinstance(data, dict):
        raise PlanError("experiment plan JSON must be an object")
    return cls.from_dict(data)


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

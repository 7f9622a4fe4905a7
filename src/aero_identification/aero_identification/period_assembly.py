"""Cutting a campaign's samples into periods and sine records, by the experiment plan.

The generator stamps command sample k at t0 + k/fs (docs/design.md §5) and publishes the plan with
``t0_ns``; measured pitch and C_l keep those stamps, so every sample maps back to its plan index
k = round((stamp − t0)·fs). :class:`CampaignAssembler` stores, in arrays sized by the plan (so
memory is bounded however long the run), the samples that fall in measured multisine periods
and measured sine periods. A period with a missing, duplicated or invalid (NaN) sample is
excluded and reported, never patched. So is every period and sine record that an anomaly
touches (rig_runtime.anomaly: the actuator ran on without commands, a command was not followed,
a scanner frame was lost, ...): :meth:`CampaignAssembler.add_anomaly`. Every plan sample is
accounted for on both channels (received once, missing, duplicated):
:meth:`CampaignAssembler.data_quality`. The same assembler serves the online identifier and the
offline fit from a bag, so both see identical data.
"""

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from multisine_gen.plan import ExperimentPlan


def _count_problems(count_u: np.ndarray, count_y: np.ndarray, u: np.ndarray, y: np.ndarray) -> str:
    problems = []
    for name, count, values in (("pitch", count_u, u), ("C_l", count_y, y)):
        missing = int(np.sum(count == 0))
        dup = int(np.sum(count > 1))
        bad = int(np.sum((count >= 1) & ~np.isfinite(values)))
        if missing:
            problems.append(f"{missing} {name} samples missing")
        if dup:
            problems.append(f"{dup} {name} samples duplicated")
        if bad:
            problems.append(f"{bad} invalid {name} samples")
    return ", ".join(problems)


@dataclass
class PeriodBlock:
    """Measured periods of one multisine realization of one level.

    u, y: (N, P) input [deg] and output (C_l) per sample and period, NaN where missing;
    count: (N, P) how many samples arrived for each slot (1 = good; 0 missing; >1 duplicated).
    """

    level: int
    realization: int
    offset_deg: float
    N: int
    P: int
    u: np.ndarray
    y: np.ndarray
    count_u: np.ndarray
    count_y: np.ndarray
    marks: list[str] = field(default_factory=list)  # per period: anomalies touching it ('' none)

    def __post_init__(self) -> None:
        if not self.marks:
            self.marks = [""] * self.P

    @classmethod
    def empty(
        cls, level: int, realization: int, offset_deg: float, N: int, P: int
    ) -> "PeriodBlock":
        nan = np.full((N, P), np.nan)
        zero = np.zeros((N, P), dtype=np.int32)
        return cls(level, realization, offset_deg, N, P, nan.copy(), nan.copy(), zero, zero.copy())

    def period_valid(self) -> np.ndarray:
        """(P,) True where every sample of the period arrived exactly once and is finite."""
        ok = (self.count_u == 1) & (self.count_y == 1) & np.isfinite(self.u) & np.isfinite(self.y)
        return ok.all(axis=0) & np.array([not m for m in self.marks], dtype=bool)

    def period_problem(self, p: int) -> str:
        """Why period p is excluded ('' if it is valid)."""
        text = _count_problems(self.count_u[:, p], self.count_y[:, p], self.u[:, p], self.y[:, p])
        return ", ".join(t for t in (text, self.marks[p]) if t)


@dataclass
class SineRecord:
    """The measured periods of one single-sine test (settling periods excluded)."""

    index: int
    level: int
    offset_deg: float
    frequency_hz: float
    amplitude_deg: float
    samples_per_period: int
    periods: int
    u: np.ndarray  # (n,) input [deg]
    y: np.ndarray  # (n,) C_l
    count_u: np.ndarray
    count_y: np.ndarray
    mark: str = ""  # anomalies touching the record ('' none)

    def valid(self) -> bool:
        return bool(
            not self.mark
            and np.all(self.count_u == 1)
            and np.all(self.count_y == 1)
            and np.all(np.isfinite(self.u))
            and np.all(np.isfinite(self.y))
        )

    def problem(self) -> str:
        """Why the record is not used ('' if it is valid)."""
        text = _count_problems(self.count_u, self.count_y, self.u, self.y)
        return ", ".join(t for t in (text, self.mark) if t)

    @property
    def name(self) -> str:
        return f"sine {self.frequency_hz:g} Hz at {self.offset_deg:g}°"


MAX_BEYOND = 100_000  # samples past the plan's end kept for a revision (CampaignAssembler)


@dataclass
class _Slot:
    """Where plan sample k goes: a period block column or a sine record offset."""

    kind: str  # "multisine" | "sine"
    key: Any
    start_k: int
    length: int
    column: int


@dataclass
class CampaignAssembler:
    """Collects measured samples into the plan's periods (see module docstring)."""

    plan: ExperimentPlan  # the typed plan (multisine_gen.plan_format.read_plan_message)
    t0_ns: int
    blocks: dict[tuple[int, int], PeriodBlock] = field(default_factory=dict)
    sines: dict[int, SineRecord] = field(default_factory=dict)
    outside: int = 0  # samples not in any measured period (ramps, settling, baseline)
    # id -> (first k, last k or None while open, description): rig_runtime.anomaly records
    anomalies: dict[str, tuple[int, int | None, str]] = field(default_factory=dict)
    # An adaptive run's decision and refused events (/experiment/segment), as they came.
    decisions: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.fs = float(self.plan.fs)
        self.period_ns = 1e9 / self.fs
        # The plan as first received (revision 0 in a run from the start): an adaptive run's
        # revisions (multisine_gen.revision) are measured against it.
        self.planned = self.plan
        # How often each plan sample arrived, per channel (saturating at 255), and how many
        # samples fell outside the plan (before t0 or after its last sample).
        self.total = int(self.plan.total_samples)
        self.coverage = {c: np.zeros(self.total, dtype=np.uint8) for c in ("u", "y")}
        self.outside_plan = {"u": 0, "y": 0}
        # The value each plan sample arrived with: the same sample delivered again (identical
        # value) is counted as redelivered and changes nothing; a different value for the same
        # stamp is a duplicate (a conflict: the period is excluded).
        self.values = {c: np.full(self.total, np.nan) for c in ("u", "y")}
        self.redelivered = {"u": 0, "y": 0}
        # Samples past the plan's end, kept until a revision that lengthens the plan claims
        # them (an adaptive run's plan message may come after its first new samples).
        self.beyond: dict[str, dict[int, float]] = {"u": {}, "y": {}}
        self._cut()

    def _cut(self) -> None:
        """Slots and empty period blocks / sine records of the plan's measured segments."""
        self.blocks.clear()
        self.sines.clear()
        self._slots: list[_Slot] = []
        for seg in self.plan.segments:
            if seg.kind == "multisine" and seg.period is not None:
                assert seg.level is not None and seg.realization is not None
                key = (seg.level, seg.realization)
                if key not in self.blocks:
                    level = next(lv for lv in self.plan.levels if lv.level == seg.level)
                    self.blocks[key] = PeriodBlock.empty(
                        key[0],
                        key[1],
                        float(seg.offset_deg or 0.0),
                        int(seg.samples_per_period or 0),
                        level.periods_of(seg.realization),
                    )
                self._slots.append(_Slot("multisine", key, seg.start_k, seg.length, seg.period))
            elif seg.kind == "sine":
                assert seg.sine_test is not None and seg.level is not None
                idx, n = seg.sine_test, seg.length
                self.sines[idx] = SineRecord(
                    idx,
                    seg.level,
                    float(seg.offset_deg or 0.0),
                    float(seg.frequency_hz or 0.0),
                    float(seg.amplitude_deg or 0.0),
                    int(seg.samples_per_period or 0),
                    seg.periods,
                    np.full(n, np.nan),
                    np.full(n, np.nan),
                    np.zeros(n, dtype=np.int32),
                    np.zeros(n, dtype=np.int32),
                )
                self._slots.append(_Slot("sine", idx, seg.start_k, n, 0))
        self._slots.sort(key=lambda s: s.start_k)
        self._starts = np.array([s.start_k for s in self._slots], dtype=np.int64)

    def revise(self, plan: ExperimentPlan) -> None:
        """Follow a revision of the plan (an adaptive run, multisine_gen.revision): cut the
        samples held so far into the revised plan's periods. The samples are kept per plan
        index, so nothing is lost and a conflict stays a conflict; samples past the held plan's end
        that the revision covers are claimed. ValueError when ``plan`` is not newer than the
        one held. (That every sample before the change is unchanged is the generator's check,
        multisine_gen.revision: samples of the revised plan may come before it.)"""
        if plan.revision <= self.plan.revision:
            raise ValueError(
                f"plan revision {plan.revision} is not newer than revision {self.plan.revision}"
            )
        marks = dict(self.anomalies)
        self.plan = plan
        self.total = int(plan.total_samples)
        for channel in ("u", "y"):
            n = min(self.total, len(self.coverage[channel]))
            coverage = np.zeros(self.total, dtype=np.uint8)
            values = np.full(self.total, np.nan)
            coverage[:n], values[:n] = self.coverage[channel][:n], self.values[channel][:n]
            self.coverage[channel], self.values[channel] = coverage, values
        self._cut()
        self.outside = 0
        for channel in ("u", "y"):
            for k in np.flatnonzero(self.coverage[channel]):
                for _ in range(int(self.coverage[channel][k])):
                    self._store(channel, int(k), float(self.values[channel][k]))
            waiting, self.beyond[channel] = self.beyond[channel], {}
            for k_beyond, value in sorted(waiting.items()):
                self.outside_plan[channel] -= 1  # counted again by add() if still outside
                self.add(channel, self.t0_ns + round(k_beyond * self.period_ns), value)
        self.anomalies = marks
        self._apply_marks()

    @property
    def multisine_end_k(self) -> int:
        """The plan's last multisine sample (-1: none): once both channels are past it, every
        multisine period of the plan is in."""
        ends = [s.start_k + s.length - 1 for s in self._slots if s.kind == "multisine"]
        return max(ends, default=-1)

    def index_of(self, stamp_ns: int) -> int:
        return round((stamp_ns - self.t0_ns) / self.period_ns)

    def _slot(self, k: int) -> _Slot | None:
        i = int(np.searchsorted(self._starts, k, side="right")) - 1
        if i < 0:
            return None
        slot = self._slots[i]
        return slot if k < slot.start_k + slot.length else None

    def add(self, channel: str, stamp_ns: int, value: float) -> None:
        """Store one sample of ``channel`` ("u": pitch [deg], "y": C_l) at its stamp."""
        k = self.index_of(stamp_ns)
        if 0 <= k < self.total:
            coverage = self.coverage[channel]
            seen = self.values[channel]
            if coverage[k] and (seen[k] == value or (math.isnan(seen[k]) and math.isnan(value))):
                self.redelivered[channel] += 1
                return
            seen[k] = value
            if coverage[k] < 255:
                coverage[k] += 1
        else:
            self.outside_plan[channel] += 1
            if k >= self.total and len(self.beyond[channel]) < MAX_BEYOND:
                self.beyond[channel][k] = value
        self._store(channel, k, value)

    def _store(self, channel: str, k: int, value: float) -> None:
        """Put sample k in its period or sine record (none: ramps, settling, baseline)."""
        slot = self._slot(k)
        if slot is None:
            self.outside += 1
            return
        offset = k - slot.start_k
        if slot.kind == "multisine":
            block = self.blocks[slot.key]
            values, counts = (
                (block.u, block.count_u) if channel == "u" else (block.y, block.count_y)
            )
            values[offset, slot.column] = value
            counts[offset, slot.column] += 1
        else:
            rec = self.sines[slot.key]
            values, counts = (rec.u, rec.count_u) if channel == "u" else (rec.y, rec.count_y)
            values[offset] = value
            counts[offset] += 1

    def add_anomaly(self, anomaly_id: str, first_ns: int, last_ns: int | None, text: str) -> None:
        """An anomaly (rig_runtime.anomaly.Anomaly fields): every period and sine record whose
        plan samples [first, last] touches is excluded, naming it. An open anomaly
        (``last_ns`` None) reaches to the end of the plan until it is published closed under
        the same id."""
        first = self.index_of(first_ns)
        last = None if last_ns is None else self.index_of(last_ns)
        self.anomalies[anomaly_id] = (first, last, text)
        self._apply_marks()

    def _apply_marks(self) -> None:
        for block in self.blocks.values():
            block.marks = [""] * block.P
        for rec in self.sines.values():
            rec.mark = ""
        for slot in self._slots:
            lo, hi = slot.start_k, slot.start_k + slot.length - 1
            texts = [
                text
                for first, last, text in self.anomalies.values()
                if first <= hi and (last is None or last >= lo)
            ]
            if not texts:
                continue
            text = "; ".join(texts)
            if slot.kind == "multisine":
                block = self.blocks[slot.key]
                current = block.marks[slot.column]
                block.marks[slot.column] = f"{current}; {text}" if current else text
            else:
                self.sines[slot.key].mark = text

    def baseline_sweep(self, final: bool) -> dict[str, Any] | None:
        """The plan's quasi-static baseline sweep as measured, once both channels are past its
        end (or ``final``): per branch ("up", "down") the plan samples that arrived exactly once,
        finite and untouched by an anomaly, as ``{branch: (u, y)}``, with ``rate_deg_s`` and
        ``left_out`` (how many of its samples were not usable). None without a baseline in the
        plan, before it has been measured, or with no usable sample."""
        segments = [s for s in self.plan.segments if s.kind == "baseline"]
        if not segments:
            return None
        end = max(s.start_k + s.length - 1 for s in segments)
        if not final:
            for coverage in self.coverage.values():
                received = np.flatnonzero(coverage[end:])
                if received.size == 0:
                    return None  # the streams have not passed the sweep's last sample yet
        out: dict[str, Any] = {"rate_deg_s": float(segments[0].rate_deg_s or 0.0), "left_out": 0}
        for seg in segments:
            k = np.arange(seg.start_k, seg.start_k + seg.length)
            u, y = self.values["u"][k], self.values["y"][k]
            ok = (self.coverage["u"][k] == 1) & (self.coverage["y"][k] == 1)
            ok &= np.isfinite(u) & np.isfinite(y)
            for first, last, _text in self.anomalies.values():
                ok &= ~((k >= first) & (k <= (last if last is not None else k[-1])))
            out["left_out"] += int(np.sum(~ok))
            out[str(seg.direction)] = (u[ok].copy(), y[ok].copy())
        if not any(len(out.get(b, ((),))[0]) for b in ("up", "down")):
            return None
        return out

    def plan_anomalies(self) -> list[str]:
        """The anomalies that touch the plan's samples (those after its end are harmless)."""
        out = []
        for first, last, text in self.anomalies.values():
            if first < self.total and (last is None or last >= 0):
                end = "open" if last is None else str(last)
                out.append(f"samples {first}..{end}: {text}")
        return out

    def sample_accounting(self, final: bool = False) -> dict[str, dict[str, int]]:
        """Per channel: plan samples expected, received exactly once, missing, duplicated (with
        conflicting values), redelivered (identical: harmless, not a problem), and samples
        outside the plan. Expected: the whole plan when ``final``; before, the samples
        up to the latest that both channels have reached (the rest may still be in flight)."""
        upto = self.total - 1
        if not final:
            for coverage in self.coverage.values():
                received = np.flatnonzero(coverage)
                upto = min(upto, int(received[-1]) if received.size else -1)
        out = {}
        for channel, name in (("u", "pitch"), ("y", "C_l")):
            seen = self.coverage[channel][: upto + 1]
            out[name] = {
                "expected": upto + 1,
                "received": int(np.sum(seen == 1)),
                "missing": int(np.sum(seen == 0)),
                "duplicated": int(np.sum(seen > 1)),
                "redelivered": self.redelivered[channel],
                "outside_plan": self.outside_plan[channel],
            }
        return out

    def add_many(self, channel: str, stamps_ns: Iterable[int], values: Iterable[float]) -> None:
        for stamp, value in zip(stamps_ns, values, strict=True):
            self.add(channel, int(stamp), float(value))

    def experiment_account(self, names: dict[int, str] | None = None) -> dict[str, Any]:
        """Multisine time per level (settling and measured periods), planned (the first plan
        held) against executed (the latest revision), with the realizations and their measured
        periods, and the adaptive run's decisions (``decisions``: the generator's ``decision``
        and ``refused`` events, as they came)."""

        def per_level(plan: ExperimentPlan) -> dict[int, dict[str, Any]]:
            out: dict[int, dict[str, Any]] = {}
            for lv in plan.levels:
                samples = sum(
                    s.length
                    for s in plan.segments
                    if s.excitation == "multisine"
                    and s.level == lv.level
                    and s.kind in ("settle", "multisine")
                )
                out[lv.level] = {
                    "seconds": samples / plan.fs,
                    "realizations": len(lv.realizations),
                    "periods": [lv.periods_of(m) for m in range(len(lv.realizations))],
                }
            return out

        planned, executed = per_level(self.planned), per_level(self.plan)
        levels = {}
        for level in sorted(set(planned) | set(executed)):
            name = (names or {}).get(level, f"level {level}")
            levels[name] = {
                "planned_s": planned.get(level, {}).get("seconds", 0.0),
                "executed_s": executed.get(level, {}).get("seconds", 0.0),
                "planned_periods": planned.get(level, {}).get("periods", []),
                "executed_periods": executed.get(level, {}).get("periods", []),
            }
        total_planned = sum(v["planned_s"] for v in levels.values())
        total_executed = sum(v["executed_s"] for v in levels.values())
        return {
            "revision": self.plan.revision,
            "levels": levels,
            "multisine_planned_s": total_planned,
            "multisine_executed_s": total_executed,
            "multisine_fraction": total_executed / total_planned if total_planned else 1.0,
            "plan_planned_s": self.planned.duration_s,
            "plan_executed_s": self.plan.duration_s,
            "decisions": list(self.decisions),
        }

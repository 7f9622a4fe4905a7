"""The experiment plan model and its validation: a campaign as one stream of pitch commands.

A plan is the single source of truth for an experiment (docs/design.md §4, `/experiment/plan`): the
generator renders it sample by sample (command k is stamped t0 + k/fs), the identifier cuts
periods with its segment records, and its JSON lets any subscriber rebuild every sample exactly.

Structure (paper §3.2):

1. optional quasi-static baseline sweep from the rest angle up to `peak_deg` and back at
   `rate_deg_s` (0.52 °/s, k ≈ 0.0001);
2. per level (offset): each multisine realization m = 0 … M−1 as one settling period (kind
   "settle", not for estimation) followed by P measured periods (kind "multisine", one segment
   per period, `period` = 0 … P−1); then the validation sines of that level: settling periods
   followed by the measured periods (one "sine" segment);
3. between blocks, ramps at `ramp_rate_deg_s`; the plan starts and ends at the rest angle.

A ramp into a periodic block ends at the last sample of that block's period, so the block's
first sample follows as it would in the periodic steady state (no step at the joint).

This module is the model only: the plan's JSON wire format (`/experiment/plan` and the
`/experiment/segment` events) is in plan_format.py, which imports this one and is the only place
a plan is written or read as JSON; the campaign presets (build_plan, default_plan, short_plan)
are in campaigns.py. The limits a plan is checked against are the actuator's
(rig_runtime.interface.ActuatorLimits, the one declaration of them).
"""

import bisect
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from multisine_gen.multisine import ExcitationError, Multisine
from multisine_gen.sine import Sine
from rig_runtime.interface import ActuatorLimits

__all__ = [
    "BaselineSweep",
    "ExperimentPlan",
    "MultisineLevel",
    "PlanError",
    "PlanSample",
    "Segment",
    "SegmentKind",
    "SineTest",
]

SegmentKind = Literal["ramp", "baseline", "settle", "multisine", "sine"]


class PlanError(ExcitationError):
    """A plan that must not run; `problems` lists every violation found (message: the first)."""

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        super().__init__(message)
        self.problems = problems if problems is not None else [message]


@dataclass(frozen=True)
class BaselineSweep:
    """Quasi-static sweep from the rest angle to peak_deg and back at rate_deg_s."""

    peak_deg: float = 30.0
    rate_deg_s: float = 0.52


@dataclass(frozen=True, eq=False)
class MultisineLevel:
    """One excitation level: M phase realizations on the same lines, amplitudes and offset."""

    level: int
    realizations: tuple[Multisine, ...]
    periods: int = 6  # P measured periods per realization
    settle_periods: int = 1  # transient periods before the measured ones
    # Measured periods of each realization when they differ (an adaptive run ended one early,
    # multisine_gen.revision); () = `periods` for every realization.
    realization_periods: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        where = f"multisine level {self.level}"
        if not self.realizations:
            raise PlanError(f"{where}: needs at least one realization")
        first = self.realizations[0]
        for m, ms in enumerate(self.realizations[1:], start=1):
            same = (
                ms.fs == first.fs
                and ms.N == first.N
                and np.array_equal(ms.excited_lines, first.excited_lines)
                and np.array_equal(ms.amplitudes, first.amplitudes)
                and ms.offset_deg == first.offset_deg
            )
            if not same:
                raise PlanError(
                    f"{where}, realization {m}: realizations of a level must differ only in "
                    f"their phases (same fs, N, lines, amplitudes, offset)"
                )
        if self.periods < 1 or self.settle_periods < 0:
            raise PlanError(f"{where}: needs periods >= 1 and settle_periods >= 0")
        object.__setattr__(self, "realization_periods", tuple(self.realization_periods))
        counts = self.realization_periods
        if counts and (len(counts) != len(self.realizations) or min(counts) < 1):
            raise PlanError(
                f"{where}: realization_periods {list(counts)} needs one count >= 1 per "
                f"realization ({len(self.realizations)})"
            )

    def periods_of(self, realization: int) -> int:
        """Measured periods of realization m."""
        return self.realization_periods[realization] if self.realization_periods else self.periods

    @property
    def offset_deg(self) -> float:
        return self.realizations[0].offset_deg

    @property
    def std_deg(self) -> float:
        return self.realizations[0].std_deg


@dataclass(frozen=True)
class SineTest:
    """A validation sine at a level: settle_periods, then `periods` measured periods."""

    level: int
    sine: Sine
    periods: int
    settle_periods: int = 1

    def __post_init__(self) -> None:
        if self.periods < 1 or self.settle_periods < 0:
            raise PlanError(
                f"sine level {self.level} at {self.sine.frequency_hz:g} Hz: needs periods >= 1 "
                f"and settle_periods >= 0"
            )


@dataclass(frozen=True)
class Segment:
    """A contiguous run of command samples [start_k, start_k + length).

    Every segment: index (position in the plan), kind, start_k, length.
    ramp / baseline: the command moves linearly from start_deg (the sample before, exclusive)
        to end_deg (its last sample) at rate_deg_s; baseline also has direction "up"/"down".
    settle / multisine / sine: level, offset_deg, excitation ("multisine" or "sine"),
        samples_per_period and periods (whole periods the segment holds);
        multisine: realization, period (0 … P−1 for measured periods; None when settling),
        std_deg; sine: sine_test (index into plan.sines), frequency_hz, amplitude_deg.
    """

    index: int
    kind: SegmentKind
    start_k: int
    length: int
    level: int | None = None
    offset_deg: float | None = None
    excitation: Literal["multisine", "sine"] | None = None
    realization: int | None = None
    period: int | None = None
    periods: int = 0
    samples_per_period: int | None = None
    std_deg: float | None = None
    sine_test: int | None = None
    frequency_hz: float | None = None
    amplitude_deg: float | None = None
    start_deg: float | None = None
    end_deg: float | None = None
    rate_deg_s: float | None = None
    direction: Literal["up", "down"] | None = None

    @property
    def stop_k(self) -> int:
        """One past the last sample."""
        return self.start_k + self.length

    def label(self) -> str:
        """Human-readable name used in errors and logs."""
        if self.kind in ("ramp", "baseline"):
            what = "ramp" if self.kind == "ramp" else f"baseline sweep {self.direction}"
            return (
                f"{what} (segment {self.index}) from {self.start_deg:.3f}° to {self.end_deg:.3f}°"
            )
        head = f"{self.excitation} level {self.level} (offset {self.offset_deg:g}°)"
        if self.excitation == "multisine":
            head += f", realization {self.realization}"
            if self.period is not None:
                head += f", period {self.period}"
        else:
            head += f", {self.frequency_hz:g} Hz, amplitude {self.amplitude_deg:g}°"
        return f"settle before {head}" if self.kind == "settle" else head


@dataclass(frozen=True, slots=True)
class PlanSample:
    """Sample k of the command stream, with the segment it belongs to and whether it is that
    segment's first / last sample (when a generator emits start / end events)."""

    k: int
    command_deg: float
    segment: Segment
    starts_segment: bool
    ends_segment: bool


def _linear(start: float, end: float, length: int) -> np.ndarray:
    """(length,) samples from start (exclusive) to end (inclusive) in equal steps."""
    return start + (end - start) * (np.arange(1, length + 1) / length)


@dataclass(frozen=True, eq=False)
class ExperimentPlan:
    """A validated campaign: excitations in order, rendered as `segments`.

    fs [Hz]; rest_deg: where the plan starts and ends; ramp_rate_deg_s: ramps between blocks;
    baseline: the quasi-static sweep or None; levels: multisine levels; sines: validation
    sines; seed: the seed the random parts were drawn from; limits: the actuator's limits
    (rig_runtime.interface.ActuatorLimits), checked at construction. Raises PlanError when the
    plan would leave the limits, exceed the rate or reach fs/2.
    """

    fs: float
    rest_deg: float = 0.0
    ramp_rate_deg_s: float = 5.0
    baseline: BaselineSweep | None = None
    levels: tuple[MultisineLevel, ...] = ()
    sines: tuple[SineTest, ...] = ()
    seed: int | None = None
    limits: ActuatorLimits = field(default_factory=ActuatorLimits)
    # 0 as designed; +1 at each change an adaptive run makes (multisine_gen.revision). A
    # revision keeps every sample before the change.
    revision: int = 0
    segments: tuple[Segment, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.fs) and self.fs > 0.0):
            raise PlanError(f"plan: fs must be > 0 Hz, got {self.fs!r}")
        if not (math.isfinite(self.ramp_rate_deg_s) and self.ramp_rate_deg_s > 0.0):
            raise PlanError(f"plan: ramp_rate_deg_s must be > 0, got {self.ramp_rate_deg_s!r}")
        if not math.isfinite(self.rest_deg):
            raise PlanError(f"plan: rest_deg must be finite, got {self.rest_deg!r}")
        object.__setattr__(self, "levels", tuple(self.levels))
        object.__setattr__(self, "sines", tuple(self.sines))
        for level in self.levels:
            if level.realizations[0].fs != self.fs:
                raise PlanError(
                    f"multisine level {level.level}: fs {level.realizations[0].fs} Hz differs "
                    f"from the plan's {self.fs} Hz"
                )
        for test in self.sines:
            if test.sine.fs != self.fs:
                raise PlanError(
                    f"sine level {test.level}: fs {test.sine.fs} Hz differs from the plan's "
                    f"{self.fs} Hz"
                )
        if len({lv.level for lv in self.levels}) != len(self.levels):
            raise PlanError("plan: two multisine levels share a level index")
        object.__setattr__(self, "_render_cache", {})
        object.__setattr__(self, "segments", tuple(self._build_segments()))
        if not self.segments:
            raise PlanError("plan has nothing to command: no baseline, multisine level or sine")
        object.__setattr__(self, "_starts", [s.start_k for s in self.segments])
        self.validate()

    # -- structure ------------------------------------------------------------------------------
    def _block_order(self) -> list[tuple[str, int]]:
        """[("multisine", level position) | ("sine", sine position)] in campaign order."""
        level_ids = sorted({lv.level for lv in self.levels} | {t.level for t in self.sines})
        order: list[tuple[str, int]] = []
        for level_id in level_ids:
            order += [("multisine", i) for i, lv in enumerate(self.levels) if lv.level == level_id]
            order += [("sine", i) for i, t in enumerate(self.sines) if t.level == level_id]
        return order

    def _build_segments(self) -> list[Segment]:
        segments: list[Segment] = []
        k = 0
        last = self.rest_deg  # value of the sample before k (the actuator rests there)

        def add(**kw: Any) -> None:
            nonlocal k
            segments.append(Segment(index=len(segments), start_k=k, **kw))
            k += kw["length"]

        def ramp_to(target: float) -> None:
            nonlocal last
            # Whole samples at no more than ramp_rate_deg_s (the last one lands on target).
            n = math.ceil(abs(target - last) * self.fs / self.ramp_rate_deg_s - 1e-9)
            if n > 0:
                add(
                    kind="ramp",
                    length=n,
                    start_deg=last,
                    end_deg=target,
                    rate_deg_s=self.ramp_rate_deg_s,
                )
            last = target

        if self.baseline is not None:
            sweep = self.baseline
            if not (sweep.rate_deg_s > 0.0 and sweep.peak_deg > self.rest_deg):
                raise PlanError(
                    f"baseline sweep: needs rate_deg_s > 0 and peak_deg ({sweep.peak_deg}°) above "
                    f"the rest angle ({self.rest_deg}°)"
                )
            ramp_to(self.rest_deg)
            n = max(1, round((sweep.peak_deg - self.rest_deg) * self.fs / sweep.rate_deg_s))
            actual_rate = (sweep.peak_deg - self.rest_deg) * self.fs / n
            for direction, a, b in (
                ("up", self.rest_deg, sweep.peak_deg),
                ("down", sweep.peak_deg, self.rest_deg),
            ):
                add(
                    kind="baseline",
                    length=n,
                    start_deg=a,
                    end_deg=b,
                    rate_deg_s=actual_rate,
                    direction=direction,
                )
            last = self.rest_deg

        for block, i in self._block_order():
            if block == "multisine":
                lv = self.levels[i]
                common = {
                    "level": lv.level,
                    "offset_deg": lv.offset_deg,
                    "excitation": "multisine",
                    "samples_per_period": lv.realizations[0].N,
                    "std_deg": lv.std_deg,
                }
                for m, ms in enumerate(lv.realizations):
                    period = self._period(("multisine", i, m))
                    ramp_to(float(period[-1]))
                    if lv.settle_periods:
                        add(
                            kind="settle",
                            length=lv.settle_periods * ms.N,
                            realization=m,
                            periods=lv.settle_periods,
                            **common,
                        )
                    for p in range(lv.periods_of(m)):
                        add(
                            kind="multisine",
                            length=ms.N,
                            realization=m,
                            period=p,
                            periods=1,
                            **common,
                        )
                    last = float(period[-1])
            else:
                test = self.sines[i]
                sine = test.sine
                common = {
                    "level": test.level,
                    "offset_deg": sine.offset_deg,
                    "excitation": "sine",
                    "samples_per_period": sine.samples_per_period,
                    "sine_test": i,
                    "frequency_hz": sine.frequency_hz,
                    "amplitude_deg": sine.amplitude_deg,
                }
                period = self._period(("sine", i, 0))
                ramp_to(float(period[-1]))
                if test.settle_periods:
                    add(
                        kind="settle",
                        length=test.settle_periods * sine.samples_per_period,
                        periods=test.settle_periods,
                        **common,
                    )
                add(
                    kind="sine",
                    length=test.periods * sine.samples_per_period,
                    periods=test.periods,
                    **common,
                )
                last = float(period[-1])
        ramp_to(self.rest_deg)
        return segments

    def _period(self, key: tuple[str, int, int]) -> np.ndarray:
        cache: dict[tuple[str, int, int], np.ndarray] = self._render_cache  # type: ignore[attr-defined]
        if key not in cache:
            kind, i, m = key
            if kind == "multisine":
                values = self.levels[i].realizations[m].period()
            else:
                values = self.sines[i].sine.period()
            values.setflags(write=False)
            cache[key] = values
        return cache[key]

    def _level_position(self, level_id: int) -> int:
        return next(i for i, lv in enumerate(self.levels) if lv.level == level_id)

    def segment_samples(self, segment: Segment) -> np.ndarray:
        """(segment.length,) commands of one segment in degrees."""
        if segment.kind in ("ramp", "baseline"):
            assert segment.start_deg is not None and segment.end_deg is not None
            return _linear(segment.start_deg, segment.end_deg, segment.length)
        if segment.excitation == "multisine":
            assert segment.level is not None and segment.realization is not None
            key = ("multisine", self._level_position(segment.level), segment.realization)
        else:
            assert segment.sine_test is not None
            key = ("sine", segment.sine_test, 0)
        return np.tile(self._period(key), segment.periods)

    # -- the sample stream ----------------------------------------------------------------------
    @property
    def total_samples(self) -> int:
        """K, the number of command samples."""
        return self.segments[-1].stop_k if self.segments else 0

    @property
    def duration_s(self) -> float:
        return self.total_samples / self.fs

    def command_deg(self) -> np.ndarray:
        """(K,) the whole command in degrees; sample k belongs at t0 + k/fs. Read-only."""
        cache: dict[Any, np.ndarray] = self._render_cache  # type: ignore[attr-defined]
        if "command" not in cache:
            parts = [self.segment_samples(s) for s in self.segments]
            command = np.concatenate(parts) if parts else np.empty(0)
            command.setflags(write=False)
            cache["command"] = command
        return cache["command"]

    def boundaries(self) -> list[tuple[int, Segment]]:
        """[(start_k, segment)] in order: where a generator emits segment start events."""
        return [(s.start_k, s) for s in self.segments]

    def segment_at(self, k: int) -> Segment:
        """The segment that holds sample k (0 <= k < K)."""
        if not 0 <= k < self.total_samples:
            raise IndexError(f"sample {k} outside the plan's 0 … {self.total_samples - 1}")
        return self.segments[bisect.bisect_right(self._starts, k) - 1]  # type: ignore[attr-defined]

    def samples(self, start_k: int = 0) -> Iterator[PlanSample]:
        """Iterate the command stream from sample start_k (a generator node's loop)."""
        command = self.command_deg()
        if start_k >= self.total_samples:
            return
        first = self.segment_at(start_k).index
        for segment in self.segments[first:]:
            last = segment.stop_k - 1
            for k in range(max(segment.start_k, start_k), segment.stop_k):
                yield PlanSample(k, float(command[k]), segment, k == segment.start_k, k == last)

    def _top_frequency_hz(self, segment: Segment) -> float | None:
        if segment.excitation == "multisine" and segment.level is not None:
            level = self.levels[self._level_position(segment.level)]
            return float(level.realizations[0].frequencies_hz[-1])
        return segment.frequency_hz

    # -- validation -----------------------------------------------------------------------------
    def validate(
        self,
        min_deg: float | ActuatorLimits | None = None,
        max_deg: float | None = None,
        max_rate_deg_s: float | None = None,
    ) -> None:
        """Refuse (PlanError) a plan that commands outside [min_deg, max_deg], changes faster
        than max_rate_deg_s between samples (including the first step from the rest angle),
        ramps faster than allowed, or excites at or above fs/2. Limits not given come from
        self.limits; an ActuatorLimits may be passed instead of the three numbers."""
        if isinstance(min_deg, ActuatorLimits):
            if max_deg is not None or max_rate_deg_s is not None:
                raise TypeError("validate: pass either an ActuatorLimits or the numbers, not both")
            given = min_deg
            min_deg, max_deg, max_rate_deg_s = (
                given.min_deg,
                given.max_deg,
                given.max_rate_deg_s,
            )
        lo = self.limits.min_deg if min_deg is None else min_deg
        hi = self.limits.max_deg if max_deg is None else max_deg
        rate = self.limits.max_rate_deg_s if max_rate_deg_s is None else max_rate_deg_s
        problems: list[str] = []
        if not lo <= self.rest_deg <= hi:
            problems.append(f"rest angle {self.rest_deg}° outside [{lo}, {hi}]°")
        if self.ramp_rate_deg_s > rate:
            problems.append(
                f"ramps: ramp_rate_deg_s {self.ramp_rate_deg_s}°/s exceeds the rate limit {rate}°/s"
            )
        nyquist = self.fs / 2.0
        previous = self.rest_deg
        for segment in self.segments:
            name = segment.label()
            f_top = self._top_frequency_hz(segment)
            if f_top is not None and f_top >= nyquist:
                problems.append(f"{name}: excites {f_top:g} Hz, at or above fs/2 = {nyquist:g} Hz")
            values = self.segment_samples(segment)
            v_max, v_min = float(values.max()), float(values.min())
            if v_max > hi:
                problems.append(f"{name}: command reaches {v_max:.3f}° above max_deg {hi}°")
            if v_min < lo:
                problems.append(f"{name}: command reaches {v_min:.3f}° below min_deg {lo}°")
            steps = np.abs(np.diff(values, prepend=previous))
            peak_rate = float(steps.max()) * self.fs
            if peak_rate > rate * (1.0 + 1e-9):
                problems.append(
                    f"{name}: command rate reaches {peak_rate:.2f}°/s above the limit {rate}°/s"
                )
            previous = float(values[-1])
        if problems:
            more = f" (and {len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
            raise PlanError(f"plan refused: {problems[0]}{more}", problems)

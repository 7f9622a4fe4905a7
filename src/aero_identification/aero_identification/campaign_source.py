"""The campaign-stream source: a `CampaignAssembler` (the identifier node's, or one rebuilt from
a bag by `aero_rig.offline`) as a `Dataset`, with its data-quality account.

Per level: the latest ``count`` valid periods of every realization, ``count`` the smallest
number of valid periods among them (the nonparametric methods need equal P); a period with a
missing, duplicated or non-finite sample, or touched by an anomaly, is excluded and named
(docs/design.md §1.2, step 1). Sine records: the complete, valid ones; a record that has
started (or that an anomaly touched) and is not valid is excluded and named, except while it is
still streaming before the final identification.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .dataset import Dataset, LevelRecord, QuasiStaticSweep, SineData
from .period_assembly import CampaignAssembler, PeriodBlock
from .periodic_data import PeriodicData

LEVEL_NAMES = {1: ["single"], 2: ["low", "high"], 3: ["low", "medium", "high"]}


def level_names(plan_levels: list[int], offsets: dict[int, float]) -> dict[int, str]:
    """Plan level number -> "low", "medium", "high" by offset (or "level k" beyond three)."""
    levels = sorted(plan_levels, key=lambda lv: offsets.get(lv, 0.0))
    names = LEVEL_NAMES.get(len(levels), [f"level {i + 1}" for i in range(len(levels))])
    return {lv: names[i] for i, lv in enumerate(levels)}


def _valid_periods(block: PeriodBlock) -> np.ndarray:
    return np.flatnonzero(block.period_valid())


def _excited_lines(assembler: CampaignAssembler, level: int, realization: int) -> np.ndarray:
    lv = next(x for x in assembler.plan.levels if x.level == level)
    return np.asarray(lv.realizations[realization].excited_lines, dtype=int)


def equal_periods(
    blocks: Sequence[PeriodBlock], columns: Sequence[np.ndarray], fs: float, lines: np.ndarray
) -> PeriodicData:
    """The realizations of one level as (N, P, M) periodic data: of each block the latest P of
    its given period columns, P the smallest count among them (the nonparametric estimators
    take equal P from every realization, Pintelon & Schoukens 2012 §4.3.1)."""
    count = min(len(c) for c in columns)
    cols = [np.asarray(c)[len(c) - count :] for c in columns]
    return PeriodicData(
        np.stack([b.u[:, c] for b, c in zip(blocks, cols, strict=True)], axis=2),
        np.stack([b.y[:, c] for b, c in zip(blocks, cols, strict=True)], axis=2),
        fs,
        lines,
        period_index=np.stack(cols, axis=1),
        realization_index=np.array([b.realization for b in blocks]),
    )


@dataclass(frozen=True)
class LevelSoFar:
    """A level's measured periods once period ``period`` of one of its realizations is in: what
    the adaptive rules judge (adaptive.judge_period)."""

    current: PeriodicData  # that realization's valid periods up to this one (M = 1)
    level_data: PeriodicData | None  # every realization so far, equal P (None: too few yet)
    earlier_periods: int  # the fewest valid periods among the earlier realizations (0: none)
    realization_periods: int  # periods the plan gives that realization
    planned_realizations: int  # realizations the plan has for the level now
    rank: tuple[int, int]  # the level's offset rank (0 = lowest) and the number of levels


def level_so_far(
    assembler: CampaignAssembler, level: int, realization: int, period: int
) -> LevelSoFar:
    """The level's valid periods after ``period`` (0-based) of ``realization`` was measured."""
    plan_level = next(lv for lv in assembler.plan.levels if lv.level == level)
    lines = np.asarray(plan_level.realizations[0].excited_lines)
    block = assembler.blocks[(level, realization)]
    valid = np.flatnonzero(block.period_valid()[: period + 1])
    current = PeriodicData(block.u[:, valid, None], block.y[:, valid, None], assembler.fs, lines)
    columns = [_valid_periods(assembler.blocks[(level, m)]) for m in range(realization)]
    columns.append(valid)
    level_data = None
    if min(len(c) for c in columns) >= 2 and len(columns) >= 2:
        blocks = [assembler.blocks[(level, m)] for m in range(realization + 1)]
        level_data = equal_periods(blocks, columns, assembler.fs, lines)
    offsets = sorted(lv.offset_deg for lv in assembler.plan.levels)
    return LevelSoFar(
        current,
        level_data,
        earlier_periods=min((len(c) for c in columns[:-1]), default=0),
        realization_periods=block.P,
        planned_realizations=len(plan_level.realizations),
        rank=(offsets.index(plan_level.offset_deg), len(offsets)),
    )


def campaign_dataset(
    assembler: CampaignAssembler, final: bool, min_periods: int = 2, source: str = ""
) -> Dataset:
    """What the assembler holds so far, as a Dataset (partial before the final call).

    A level's ``data`` is None until every realization has ``min_periods`` valid periods.
    """
    offsets: dict[int, float] = {}
    realizations: dict[int, list[int]] = {}
    for lv, m in sorted(assembler.blocks):
        offsets.setdefault(lv, assembler.blocks[(lv, m)].offset_deg)
        realizations.setdefault(lv, []).append(m)
    plan_levels = [lv.level for lv in assembler.plan.levels]
    names = level_names(plan_levels, offsets)
    levels: list[LevelRecord] = []
    for level in sorted(plan_levels, key=lambda lv: offsets.get(lv, 0.0)):
        blocks = [assembler.blocks[(level, m)] for m in realizations.get(level, [])]
        excluded = [
            f"realization {b.realization} period {p}: {problem}"
            for b in blocks
            for p in range(b.P)
            if (problem := b.period_problem(p)) and np.any(b.count_u[:, p] + b.count_y[:, p])
        ]
        columns = [_valid_periods(b) for b in blocks]
        data = None
        if len(blocks) >= 2 and min(len(c) for c in columns) >= min_periods:
            lines = _excited_lines(assembler, level, blocks[0].realization)
            data = equal_periods(blocks, columns, assembler.fs, lines)
        levels.append(
            LevelRecord(
                names[level],
                data,
                key=str(level),
                offset_deg=offsets.get(level, 0.0),
                periods_in_file=blocks[0].P if blocks else 0,
                excluded=tuple(excluded),
            )
        )
    dataset = Dataset(
        assembler.fs,
        levels,
        sines_planned=bool(assembler.sines),
        source=source or "campaign stream",
    )
    for rec in sorted(assembler.sines.values(), key=lambda r: r.index):
        if rec.valid():
            dataset.sines.append(
                SineData(
                    rec.name,
                    rec.frequency_hz,
                    rec.offset_deg,
                    rec.samples_per_period,
                    rec.u.copy(),
                    rec.y.copy(),
                )
            )
            continue
        # Still streaming (its last sample not in yet) is no fault until the final refit.
        in_progress = not (rec.count_u[-1] and rec.count_y[-1])
        started = np.any(rec.count_u) or np.any(rec.count_y)
        if (started or rec.mark) and (final or not in_progress):
            dataset.excluded_sines.append(f"{rec.name}: {rec.problem()}")
            dataset.warnings.append(f"{rec.name}: not used for validation ({rec.problem()})")
    sweep = assembler.baseline_sweep(final)
    if sweep is not None:
        empty = (np.empty(0), np.empty(0))
        (u_up, y_up), (u_down, y_down) = sweep.get("up", empty), sweep.get("down", empty)
        dataset.quasi_static = QuasiStaticSweep(
            u_up, y_up, u_down, y_down, sweep["rate_deg_s"], sweep["left_out"]
        )
        if sweep["left_out"]:
            dataset.warnings.append(
                f"quasi-static sweep: {sweep['left_out']} of its samples missing, duplicated or "
                "touched by an anomaly, left out"
            )
    dataset.quality = data_quality(assembler, dataset, final)
    dataset.experiment = assembler.experiment_account(names)
    return dataset


def data_quality(assembler: CampaignAssembler, dataset: Dataset, final: bool) -> dict[str, Any]:
    """What the identification could not use, and why: every plan sample accounted for on both
    channels, the anomalies that touch the plan, the excluded periods and sine records.

    ``clean`` is false as soon as any of these is not empty: such a run says so in its
    report, its status and the campaign's exit code.
    """
    samples = assembler.sample_accounting(final=final)
    anomalies = assembler.plan_anomalies()
    periods = [f"{lv.name}: {text}" for lv in dataset.levels for text in lv.excluded]
    lost = sum(c["missing"] + c["duplicated"] for c in samples.values())
    return {
        "clean": not (lost or anomalies or periods or dataset.excluded_sines),
        "samples": samples,
        "anomalies": anomalies,
        "excluded_periods": periods,
        "excluded_sines": list(dataset.excluded_sines),
    }

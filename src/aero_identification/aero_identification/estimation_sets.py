"""The estimation data every model class is fitted on ([PitchingWing] §4.1; docs/design.md §7.6a).

Per estimation level, one steady-state mean period per training realization, and held-out
periods of the same levels. The held-out periods choose each fit's iterate, score the structure
scans' candidates and choose the selected model; the validation sines and held-out levels are
never among them. `EstimationSets.of` builds them once per identification (and once per
bootstrap replicate); the PNLSS (pnlss_training.py), the B-spline LPV model (bspline_lpv.py)
and the Beddoes–Leishman baseline (beddoes_leishman.py) are each fitted on the same object.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .hyperparameters import IdentificationConfig
from .identification_result import IdentificationResult, LevelResult
from .level_identification import kept_periods
from .periodic_data import PeriodicData

__all__ = [
    "EstimationSets",
    "estimation_sets",
    "ready_levels",
    "scan_split_count",
    "validation_realization",
]


def validation_realization(data: PeriodicData, config: IdentificationConfig) -> int | None:
    """Which realization holds the held-out periods: ``config.validation_realization`` (the
    last one if there are fewer); None with M = 1."""
    if data.M < 2:
        return None
    return min(config.validation_realization, data.M - 1)


def estimation_sets(
    levels: Sequence[LevelResult], config: IdentificationConfig, fold: int = 0
) -> tuple[PeriodicData, PeriodicData | None, str]:
    """Training and held-out sets, one steady-state mean period per record, and what is held out.

    Training: per level, the mean of the kept periods of every realization except the held-out
    one (one record per level and realization). The input is periodic, so Σ_p ||ŷ − y_p||² =
    P ||ŷ − ȳ||² + const: the same least-squares problem as fitting every period, P times
    cheaper. Held out: the mean of the kept periods of realization `validation_realization`
    when M ≥ 2; with M = 1 the last period (independent noise, same excitation) and the
    training mean is over the others; with one period, none.

    ``fold`` k > 0: the structure scans' cross-fit split k (`scan_splits`): the realization k
    places after `validation_realization` (cyclically) is held out instead, or with M = 1 the
    period k places before the last.
    """
    us: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    uv: list[np.ndarray] = []
    yv: list[np.ndarray] = []
    how = ""
    for res in levels:
        d = res.record.data
        assert d is not None
        val = validation_realization(d, config)
        if val is not None:
            val = (val + fold) % d.M
            how = f"realization {int(d.realization_index[val])} of each level"
            for m in range(d.M):
                cols = kept_periods(res, m)
                target = (uv, yv) if m == val else (us, ys)
                target[0].append(d.u[:, cols, m].mean(axis=1))
                target[1].append(d.y[:, cols, m].mean(axis=1))
        elif d.P >= 2:
            cols = kept_periods(res, 0)
            last = len(cols) - 1 - fold % len(cols)  # the held-out period's position
            how = "the last period of each level" if fold == 0 else f"kept period {last}"
            rest = np.delete(cols, last)
            us.append(d.u[:, rest, 0].mean(axis=1))
            ys.append(d.y[:, rest, 0].mean(axis=1))
            uv.append(d.u[:, cols[last], 0])
            yv.append(d.y[:, cols[last], 0])
        else:
            us.append(d.u[:, 0, 0])
            ys.append(d.y[:, 0, 0])
    first = levels[0].record.data
    assert first is not None

    def stack(parts: list[np.ndarray]) -> np.ndarray:
        return np.stack(parts, axis=1)[:, None, :]  # (N, 1, records)

    train = PeriodicData(stack(us), stack(ys), first.fs, first.excited_lines)
    if len(uv) != len(levels):
        return train, None, "none (a level has one period and one realization)"
    held = PeriodicData(stack(uv), stack(yv), first.fs, first.excited_lines)
    return train, held, how


def scan_split_count(levels: Sequence[LevelResult]) -> int:
    """How many distinct held-out sets `estimation_sets` can make: the fewest realizations of
    any level, or of kept periods where a level has one realization."""
    counts = []
    for res in levels:
        d = res.record.data
        assert d is not None
        counts.append(d.M if d.M >= 2 else len(kept_periods(res, 0)))
    return min(counts, default=1)


def ready_levels(result: IdentificationResult) -> list[LevelResult]:
    """The estimation levels the models are fitted on: those with data, a BLA and a linear
    model, in the levels' order (lowest first)."""
    return [
        r
        for r in result.levels.values()
        if r.role == "estimation"
        and r.record.data is not None
        and r.bla is not None
        and r.linear is not None
    ]


@dataclass(frozen=True)
class EstimationSets:
    """The levels a model is fitted on, their training and held-out sets (`estimation_sets`,
    fold 0) and what is held out, built once and shared by every model class."""

    levels: tuple[LevelResult, ...]
    train: PeriodicData
    held: PeriodicData | None
    how: str

    @classmethod
    def of(cls, levels: Sequence[LevelResult], config: IdentificationConfig) -> "EstimationSets":
        if not levels:
            raise ValueError("no estimation level with data, a BLA and a linear model")
        train, held, how = estimation_sets(levels, config)
        return cls(tuple(levels), train, held, how)

    def folds(self, config: IdentificationConfig) -> list[tuple[PeriodicData, PeriodicData]]:
        """The structure scans' further cross-fit splits 1 … min(scan_splits, the distinct
        held-out sets there are) − 1; empty without held-out periods."""
        if self.held is None:
            return []
        out = []
        for fold in range(1, min(config.scan_splits, scan_split_count(self.levels))):
            train_k, held_k, _ = estimation_sets(self.levels, config, fold)
            assert held_k is not None  # every level has a held-out set in any fold
            out.append((train_k, held_k))
        return out

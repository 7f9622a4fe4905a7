"""The one input of the identification pipeline, whatever door the data came in by.

A source adapter turns its data into a `Dataset` (docs/design.md §7.1):

- a campaign stream (the identifier node's `CampaignAssembler`, or a bag read back into one):
  `campaign_source.campaign_dataset`;
- measured CSV/MAT records: `records.read_dataset`.

`pipeline.identify(dataset, config)` then runs every stage that the data allow, and
`report.write_report` writes one report for all of them.
"""

import fnmatch
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from aero_identification.periodic_data import PeriodicData


@dataclass(frozen=True, eq=False)
class LevelRecord:
    """One excitation level: its steady-state periods and where they came from.

    Attributes:
        name: the level's short name ("low", "medium", "high" in a campaign; "3" for a file
            named ``..._Level3.csv``).
        data: the usable periods (N, P, M), or None while a stream has too few of them.
        key: the level's key in ``models.json`` (the plan's level number in a campaign, the
            name for records).
        offset_deg: the operating point (plan offset) when the source knows it, else None.
        path: the file it was read from (records), else None.
        periods_in_file: P before any requested drop (records; P otherwise).
        dropped_periods: leading periods dropped on request (records).
        excluded: periods left out, each with its reason ("realization 1 period 3: ...").
        notes: what the adapter did (layout, fs source, excited lines), for the report.
    """

    name: str
    data: PeriodicData | None
    key: str = ""
    offset_deg: float | None = None
    path: Path | None = None
    periods_in_file: int = 0
    dropped_periods: int = 0
    excluded: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def periods(self) -> PeriodicData:
        """``data``, for a level known to have it (ValueError naming the level otherwise)."""
        if self.data is None:
            raise ValueError(f"level {self.name} has no usable periods yet")
        return self.data

    @property
    def input_rms(self) -> float:
        """RMS of the input around its mean, over the usable periods (nan without data)."""
        return float(np.std(self.data.u)) if self.data is not None else float("nan")

    def matches(self, token: str) -> bool:
        """Whether a user's level selector names this level: equal to its name, key, file stem
        or file name, or a glob matching one (e.g. "3", "F16Data_FullMSine_Level3", "*Level3*")."""
        names = [self.name, self.key]
        if self.path is not None:
            names += [self.path.stem, self.path.name]
        return any(token == n or fnmatch.fnmatchcase(n, token) for n in names if n)

    @property
    def label(self) -> str:
        """Key in models.json and the report's file names."""
        return self.key or self.name


@dataclass(frozen=True, eq=False)
class SineData:
    """The measured steady-state periods of one single-sine test (validation data)."""

    name: str
    frequency_hz: float
    offset_deg: float
    samples_per_period: int
    u: np.ndarray  # (n,) input [deg]
    y: np.ndarray  # (n,) output


@dataclass(frozen=True, eq=False)
class QuasiStaticSweep:
    """The measured quasi-static baseline sweep (the plan's baseline): α [deg] and C_l on the
    pitch-up and the pitch-down branch, the samples in time order ([PitchingWing] Fig. 5).

    Attributes:
        alpha_up, cl_up, alpha_down, cl_down: the usable samples of each branch.
        rate_deg_s: the sweep's pitch rate.
        left_out: sweep samples missing, duplicated, non-finite or touched by an anomaly (left
            out, never patched).
    """

    alpha_up: np.ndarray
    cl_up: np.ndarray
    alpha_down: np.ndarray
    cl_down: np.ndarray
    rate_deg_s: float
    left_out: int = 0

    def branch(self, direction: str, bin_deg: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
        """One branch as a curve: the mean C_l in α bins of ``bin_deg`` (bins with no sample
        dropped), as (bin centres [deg], mean C_l), α ascending."""
        if direction not in ("up", "down"):
            raise ValueError(f"direction must be 'up' or 'down'; got {direction!r}")
        alpha, cl = (
            (self.alpha_up, self.cl_up) if direction == "up" else (self.alpha_down, self.cl_down)
        )
        return binned_mean(alpha, cl, bin_deg)

    def static_curve(self, bin_deg: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
        """The static lift curve: per α bin the mean of the two branches' binned curves (where
        they differ, a hysteresis, their average; where only one reaches, that one)."""
        a_up, c_up = self.branch("up", bin_deg)
        a_down, c_down = self.branch("down", bin_deg)
        alpha = np.union1d(a_up, a_down)
        total, count = np.zeros(alpha.size), np.zeros(alpha.size)
        for a, c in ((a_up, c_up), (a_down, c_down)):
            at = np.searchsorted(alpha, a)
            total[at] += c
            count[at] += 1
        return alpha, total / count


def binned_mean(x: np.ndarray, y: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean of y in bins of ``width`` along x (bin edges at multiples of width), as (bin
    centres, means) for the bins that hold a sample."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.size == 0:
        return np.empty(0), np.empty(0)
    index = np.floor(x / width).astype(np.int64)
    bins, inverse, counts = np.unique(index, return_inverse=True, return_counts=True)
    sums = np.bincount(inverse, weights=y)
    return (bins + 0.5) * width, sums / counts


@dataclass
class Dataset:
    """Levels (lowest first), validation sines and the data-quality account of one source.

    Attributes:
        fs: sampling frequency [Hz].
        levels: every level, ordered from the lowest: by plan offset in a campaign, by input
            RMS for records (`lowest` is the level whose linear model starts the PNLSS fit).
        sines: valid single-sine records (empty for records).
        sines_planned: the source plans sine records (a campaign), so the level-1 models of
            Table 1's paper variant are fitted even before the first sine arrives.
        quality: the data-quality account (campaign_source.data_quality, or the records'
            reading account); ``clean`` false when anything was lost or excluded.
        excluded_sines: sine records left out, each with its reason.
        warnings: what the adapter noticed (a transient, a sine not used), for the report.
        source: one line naming the source (a bag, a directory of CSV files, a live stream).
        experiment: a campaign's executed plan against the planned one (multisine time per
            level, the adaptive run's decisions; CampaignAssembler.experiment_account); empty
            for records.
        quasi_static: the measured quasi-static sweep when the source has one (a campaign
            whose plan has a baseline, once it is measured); None for records.
    """

    fs: float
    levels: list[LevelRecord]
    sines: list[SineData] = field(default_factory=list)
    sines_planned: bool = False
    quality: dict[str, Any] = field(default_factory=dict)
    excluded_sines: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    source: str = ""
    experiment: dict[str, Any] = field(default_factory=dict)
    quasi_static: QuasiStaticSweep | None = None

    @property
    def clean(self) -> bool:
        return bool(self.quality.get("clean", True))

    def level(self, name: str) -> LevelRecord:
        for lv in self.levels:
            if lv.name == name:
                return lv
        raise KeyError(name)

    def select(self, tokens: Sequence[str]) -> list[str]:
        """Names of the levels a user's selectors name (`LevelRecord.matches`); ValueError
        naming the selector that matches nothing."""
        out: list[str] = []
        for token in tokens:
            hit = [lv.name for lv in self.levels if lv.matches(token)]
            if not hit:
                names = [lv.name for lv in self.levels]
                raise ValueError(f"level {token!r} matches no level; levels: {names}")
            out += [h for h in hit if h not in out]
        return out


def select_levels(
    dataset: Dataset,
    estimation: Sequence[str] | None,
    validation: Sequence[str] | None,
) -> tuple[Dataset, list[str]]:
    """The dataset restricted to the user's estimation and validation levels, and the names of
    the held-out (validation) levels.

    A selector is a level name, key, file stem or glob (`Dataset.select`). Without
    ``estimation`` every level not held out is estimated; without ``validation`` none is held
    out. A level in both, a selector matching nothing, or no estimation level left raises
    ValueError.
    """
    names = [lv.name for lv in dataset.levels]
    held = dataset.select(list(validation)) if validation else []
    est = dataset.select(list(estimation)) if estimation else [n for n in names if n not in held]
    both = sorted(set(est) & set(held))
    if both:
        raise ValueError(f"level(s) {both} are selected for estimation and for validation")
    if not est:
        raise ValueError(f"no estimation level left (levels: {names})")
    keep = set(est) | set(held)
    return replace(dataset, levels=[lv for lv in dataset.levels if lv.name in keep]), held

"""The result of `pipeline.identify`, whatever the source, and its JSON payload
(``/identification/model``, ``models.json``)."""

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import model_payload as msg
from .beddoes_leishman import BeddoesLeishman
from .bla import BLA
from .bspline_lpv import BSplineLPV, LpvScan
from .clustering import ClusterResult
from .dataset import LevelRecord, QuasiStaticSweep
from .hyperparameters import IdentificationConfig
from .quality import data_quality_note
from .report_tables import (
    LPV_ROW,
    SELECTED_ROW,
    SEMI_EMPIRICAL_ROW,
    TABLE1_MODELS,
    floor_ratio_table,
    held_out_table,
    table1,
)
from .scan import ScanResult
from .state_space_models import LinearStateSpace, PNLSSModel


@dataclass
class LevelResult:
    """One level's clustering, BLA and linear state-space model."""

    record: LevelRecord
    role: str = "estimation"  # or "held out": BLA only, used for validation errors
    clusters: ClusterResult | None = None
    bla: BLA | None = None
    linear: LinearStateSpace | None = None
    order_scanned: bool = False  # the linear order came from the subspace order scan
    periods_used: int = 0

    @property
    def name(self) -> str:
        return self.record.name

    @property
    def offset_deg(self) -> float:
        off = self.record.offset_deg
        return float(off) if off is not None else float("nan")

    @property
    def excluded(self) -> list[str]:
        return list(self.record.excluded)


Log = Callable[[str], None]  # an identification's progress messages

# EstimationSpread.off_mean: a cell whose error is farther than this many estimation spreads
# from the bootstrap refits' mean is named in the table's note (about 5 % of cells by chance
# if the replicates' errors were normal around the estimate's).
OFF_MEAN_SPREADS = 2.0


@dataclass
class EstimationSpread:
    """Table 1's estimation spread (bootstrap.py, ``config.bootstrap``): per cell, the std of
    the error over refits on bootstrap replicates of the estimation periods, the replicates'
    mean (minus the estimate's error: the bootstrap's bias estimate, bootstrap.py), and how
    many replicates failed or diverged there."""

    replicates: int
    spreads_all: dict[tuple[str, str, float], float] = field(default_factory=dict)
    spreads_level1: dict[tuple[str, str, float], float] = field(default_factory=dict)
    means_all: dict[tuple[str, str, float], float] = field(default_factory=dict)
    means_level1: dict[tuple[str, str, float], float] = field(default_factory=dict)
    failed_all: dict[tuple[str, str, float], int] = field(default_factory=dict)
    failed_level1: dict[tuple[str, str, float], int] = field(default_factory=dict)
    seconds: float = 0.0
    # config.bootstrap_scan: the structure the estimate's scan kept and the one each
    # replicate's scan kept ("" where it failed), by `structure_label`; empty: not rescanned.
    kept_structure: str = ""
    replicate_structures: list[str] = field(default_factory=list)

    @property
    def rescanned(self) -> bool:
        return bool(self.replicate_structures)

    @property
    def same_structure(self) -> int:
        """Replicates whose scan kept the estimate's structure."""
        return sum(s == self.kept_structure for s in self.replicate_structures)

    def off_mean(
        self, errors: Mapping[tuple[str, str, float], float], level1: bool = False
    ) -> dict[tuple[str, str, float], float]:
        """The cells of ``errors`` (all-levels table, or level 1's) whose estimate lies more
        than OFF_MEAN_SPREADS estimation spreads from the replicates' mean, with that distance
        in spreads (positive: the replicates' mean is worse than the estimate): there the
        estimate is not typical of its fitting procedure (docs/design.md §7.7)."""
        means = self.means_level1 if level1 else self.means_all
        spreads = self.spreads_level1 if level1 else self.spreads_all
        off: dict[tuple[str, str, float], float] = {}
        for cell, error in errors.items():
            mean, spread = means.get(cell, math.nan), spreads.get(cell, math.nan)
            if all(math.isfinite(v) for v in (error, mean, spread)) and spread > 0:
                units = (mean - error) / spread
                if abs(units) > OFF_MEAN_SPREADS:
                    off[cell] = units
        return off

    def note(self, errors: Mapping[tuple[str, str, float], float], level1: bool = False) -> str:
        """What the Markdown tables' second ± is (a line above each table), and the cells of
        ``errors`` whose estimate is off the replicates' mean (`off_mean`)."""
        scan = (
            f", each with its own structure scan (the estimate's structure, {self.kept_structure},"
            f" kept in {self.same_structure} of {self.replicates})"
            if self.rescanned
            else ""
        )
        off = self.off_mean(errors, level1)
        better = sum(u > 0 for u in off.values())
        far = (
            f" In {len(off)} of {len(errors)} cells the error lies more than "
            f"{OFF_MEAN_SPREADS:g} estimation spreads from the refits' mean ({better} below it, "
            f"{len(off) - better} above): there the estimate is not typical of what its "
            "fitting procedure gives on other draws of the periods; the CSV's `estimation "
            "mean` columns give the means."
            if off
            else ""
        )
        return (
            f"Each cell: error ± std over the sine's periods ± std over {self.replicates} "
            f"bootstrap refits on the estimation periods{scan} (docs/design.md §7.7).{far}\n\n"
        )


@dataclass
class IdentificationResult:
    config: IdentificationConfig
    fs: float
    levels: dict[str, LevelResult] = field(default_factory=dict)  # by name, lowest first
    pnlss_all: PNLSSModel | None = None
    pnlss_level1: PNLSSModel | None = None
    linear_level1: LinearStateSpace | None = None
    pnlss_start_level: str = ""  # the level whose linear model started the PNLSS fits
    pnlss_held_out: str = ""  # what chose the PNLSS iterate (estimation_sets.estimation_sets)
    errors_all: dict[tuple[str, str, float], float] = field(default_factory=dict)
    errors_level1: dict[tuple[str, str, float], float] = field(default_factory=dict)
    # Table 1's ± per cell, same keys: std over the sine's periods of the per-period error
    # (metrics.relative_rms_error_spread; NaN for a single period or a diverged model).
    spreads_all: dict[tuple[str, str, float], float] = field(default_factory=dict)
    spreads_level1: dict[tuple[str, str, float], float] = field(default_factory=dict)
    # Table 1's "noise floor" row, {(level, freq_hz): floor}: the sine's periods about their
    # own mean (metrics.noise_floor), the error no deterministic model of α goes below.
    noise_floor: dict[tuple[str, float], float] = field(default_factory=dict)
    held_out_errors: list[dict[str, Any]] = field(default_factory=list)
    predictions: list[dict[str, Any]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)
    complete: bool = False
    # Fitted with the final identification's stages (pipeline.identify's final_models): a
    # final call on the same multisine data may take the models over and only validate.
    final_models: bool = False
    level1_signature: bytes = b""  # which level-1 periods the level-1 PNLSS was trained on
    excluded_sines: list[str] = field(default_factory=list)
    data_quality: dict[str, Any] = field(default_factory=dict)  # the dataset's account
    experiment: dict[str, Any] = field(default_factory=dict)  # Dataset.experiment
    source: str = ""
    sines_planned: bool = False  # the source plans sine records: Table 1 is part of the result
    scan: ScanResult | None = None  # the structure scan of the all-levels PNLSS (config.scan)
    # The same pipeline without clustering (config.clustering_ablation, final only) and what
    # clustering changed (clustering_ablation.clustering_effect()).
    no_clustering: "IdentificationResult | None" = None
    clustering_effect: dict[str, Any] = field(default_factory=dict)
    # Table 1's estimation spread (config.bootstrap > 0, final identification only).
    bootstrap: EstimationSpread | None = None
    # The second nonlinear class (bspline_lpv.py; config.lpv), its scan (final models), and the
    # selected model (pipeline.select_model: the class, its structure, the held-out errors).
    lpv_all: BSplineLPV | None = None
    lpv_scan: LpvScan | None = None
    selection: dict[str, Any] = field(default_factory=dict)
    # The semi-empirical baseline (beddoes_leishman.py; config.semi_empirical, with a sweep).
    beddoes_leishman: BeddoesLeishman | None = None
    semi_empirical_signature: bytes = b""  # which sweep and sets it was fitted on
    # The measured quasi-static sweep (Dataset.quasi_static): Fig. 5, the semi-empirical model.
    quasi_static: QuasiStaticSweep | None = None

    @property
    def clean(self) -> bool:
        return bool(self.data_quality.get("clean", True))

    @property
    def level_names(self) -> list[str]:
        """Names of the levels with sines or models, lowest first (Table 1's columns)."""
        return [r.name for r in self.levels.values() if r.role == "estimation"]

    @property
    def sine_freqs(self) -> list[float]:
        cells = {round(k[2], 6) for k in (*self.errors_all, *self.errors_level1)}
        return sorted(cells | {round(f, 6) for _, f in self.noise_floor})

    def tables(self) -> dict[str, tuple[str, str]]:
        """Table 1 (both variants, and without clustering) when there were sines; the
        held-out levels' errors when there were held-out levels. A "Data not clean" note is on
        top of each when anything was lost or excluded."""
        levels, freqs = self.level_names, self.sine_freqs
        tables: dict[str, tuple[str, str]] = {}
        if self.sines_planned or freqs:
            boot = self.bootstrap
            models_all = table1_models(self.errors_all)
            tables["table1_all_levels"] = table1(
                self.errors_all, levels, freqs, models=models_all, spreads=self.spreads_all,
                floor=self.noise_floor,
                estimation_spreads=None if boot is None else boot.spreads_all,
                estimation_means=None if boot is None else boot.means_all,
            )  # fmt: skip
            tables["table1_level1"] = table1(
                self.errors_level1, levels, freqs, spreads=self.spreads_level1,
                floor=self.noise_floor,
                estimation_spreads=None if boot is None else boot.spreads_level1,
                estimation_means=None if boot is None else boot.means_level1,
            )  # fmt: skip
            if boot is not None:
                for key, errors, level1 in (
                    ("table1_all_levels", self.errors_all, False),
                    ("table1_level1", self.errors_level1, True),
                ):
                    md, csv_text = tables[key]
                    tables[key] = (boot.note(errors, level1) + md, csv_text)
            if self.selection and any(k[0] == SELECTED_ROW for k in self.errors_all):
                md, csv_text = tables["table1_all_levels"]
                tables["table1_all_levels"] = (selection_note(self.selection) + md, csv_text)
            if self.noise_floor:
                tables["table1_floor_ratios"] = floor_ratio_table(
                    [("all-levels table", self.errors_all), ("level-1 table", self.errors_level1)],
                    self.noise_floor, levels, freqs, models=models_all,
                )  # fmt: skip
            if self.no_clustering is not None:
                tables["table1_no_clustering"] = table1(
                    self.no_clustering.errors_all,
                    levels,
                    freqs,
                    models=table1_models(self.no_clustering.errors_all),
                    spreads=self.no_clustering.spreads_all,
                    floor=self.no_clustering.noise_floor,
                )
        if self.held_out_errors:
            tables["validation_errors"] = held_out_table(self.held_out_errors)
            if self.no_clustering is not None and self.no_clustering.held_out_errors:
                tables["validation_errors_no_clustering"] = held_out_table(
                    self.no_clustering.held_out_errors
                )
        if self.clean:
            return tables
        # Never a clean-looking table from data that lost or excluded samples.
        note = data_quality_note(self.data_quality)
        return {key: (note + md, csv) for key, (md, csv) in tables.items()}

    def _bootstrap_rows(self) -> dict[str, list[list[Any]] | None]:
        """models.json's per-cell rows of the estimation bootstrap: the std over the refits
        and their mean (minus the error: the bootstrap's bias), each table; null when the
        bootstrap did not run."""
        boot = self.bootstrap
        names = [f"{table}_bootstrap_{what}" for what in ("std", "mean")
                 for table in ("all_levels", "level1")]  # fmt: skip
        if boot is None:
            return dict.fromkeys(names)
        values = (boot.spreads_all, boot.spreads_level1, boot.means_all, boot.means_level1)
        return {name: _spread_rows(v) for name, v in zip(names, values, strict=True)}

    def to_json_dict(self) -> dict[str, Any]:
        """The /identification/model payload (also models.json in the run directory)."""
        tables = self.tables()

        def markdown(key: str) -> str | None:
            return tables[key][0] if key in tables else None

        return {
            "complete": self.complete,
            "source": self.source,
            "config": config_dict(self.config),
            msg.LEVELS: {lv.record.label: level_json(lv) for lv in self.levels.values()},
            "models": {
                "pnlss_all_levels": self.pnlss_all.to_dict() if self.pnlss_all else None,
                "pnlss_level1": self.pnlss_level1.to_dict() if self.pnlss_level1 else None,
                "bla_ss_level1": self.linear_level1.to_dict() if self.linear_level1 else None,
                "lpv_all_levels": self.lpv_all.to_dict() if self.lpv_all else None,
                "beddoes_leishman": None
                if self.beddoes_leishman is None
                else self.beddoes_leishman.to_dict(),
            },
            "pnlss": {
                "initial_linear_level": self.pnlss_start_level,
                "held_out": self.pnlss_held_out,
            },
            "errors": {
                "all_levels": [[m, lv, f, e] for (m, lv, f), e in self.errors_all.items()],
                "level1": [[m, lv, f, e] for (m, lv, f), e in self.errors_level1.items()],
                # Table 1's ± (same rows; null where undefined: one period, a diverged PNLSS).
                "all_levels_std": _spread_rows(self.spreads_all),
                "level1_std": _spread_rows(self.spreads_level1),
                # Table 1's noise floor per sine (metrics.noise_floor): [[level, freq_hz, floor]].
                "noise_floor": [[lv, f, v] for (lv, f), v in self.noise_floor.items()],
                # Table 1's estimation spread (config.bootstrap; null rows where not run).
                "bootstrap_replicates": None
                if self.bootstrap is None
                else self.bootstrap.replicates,
                **self._bootstrap_rows(),
                # config.bootstrap_scan: the structure each replicate's scan kept.
                "bootstrap_structures": None
                if self.bootstrap is None or not self.bootstrap.rescanned
                else {
                    "estimate": self.bootstrap.kept_structure,
                    "replicates": self.bootstrap.replicate_structures,
                },
                "held_out_levels": self.held_out_errors,
            },
            msg.TABLE1: {
                msg.TABLE1_ALL_LEVELS: markdown("table1_all_levels"),
                msg.TABLE1_LEVEL1: markdown("table1_level1"),
                msg.TABLE1_FLOOR_RATIOS: markdown("table1_floor_ratios"),
                msg.TABLE1_NO_CLUSTERING: markdown("table1_no_clustering"),
                msg.TABLE1_HELD_OUT: markdown("validation_errors"),
            },
            "clustering_effect": self.clustering_effect,
            "quasi_static": None
            if self.quasi_static is None
            else quasi_static_json(self.quasi_static),
            msg.PREDICTIONS: [_trim_prediction(p) for p in self.predictions],
            msg.WARNINGS: self.warnings,
            msg.DATA_QUALITY: self.data_quality,
            msg.EXPERIMENT: self.experiment,
            "timings_s": self.timings_s,
            "selection": self.selection or None,
            "lpv_scan": None
            if self.lpv_scan is None
            else {
                "table": self.lpv_scan.rows,
                "rule": self.lpv_scan.rule,
                "seconds": self.lpv_scan.seconds,
            },
            "pnlss_scan": None
            if self.scan is None
            else {
                "table": self.scan.table,
                "rule": self.scan.rule,
                "seconds": self.scan.seconds,
                "workers": self.scan.workers,
            },
        }


SELECTED_PNLSS = "PNLSS"  # pipeline.select_model's class names
SELECTED_LPV = "B-spline LPV"


def table1_models(errors: Mapping[tuple[str, str, float], float]) -> tuple[str, ...]:
    """Table 1's rows: TABLE1_MODELS, then those of the second class, the selected model and
    the semi-empirical baseline where they were scored."""
    scored = {model for model, _, _ in errors}
    extra = (LPV_ROW, SELECTED_ROW, SEMI_EMPIRICAL_ROW)
    return (*TABLE1_MODELS, *(row for row in extra if row in scored))


def pnlss_structure(model: PNLSSModel) -> str:
    """A PNLSS model's structure in one line."""
    return (
        f"nx {model.nx}, degrees {list(model.degrees)}, {model.structure}, "
        f"{model.parameters.size} parameters"
    )


def selection_note(selection: Mapping[str, Any]) -> str:
    """The line above the all-levels Table 1 naming the selected model and why."""
    if not selection:
        return ""
    errors = ", ".join(
        f"{name} {value:.4g}" for name, value in selection["validation_errors"].items()
    )
    return (
        f"selected: {selection['class']} ({selection['structure']}), the lower error on the "
        f"held-out periods ({selection['held_out']}): {errors}.\n\n"
    )


QUASI_STATIC_BIN_DEG = 0.25  # models.json's quasi-static curves: mean C_l per α bin


def quasi_static_json(sweep: QuasiStaticSweep) -> dict[str, Any]:
    """The sweep's two branches as curves (mean C_l per QUASI_STATIC_BIN_DEG bin of α)."""
    out: dict[str, Any] = {"rate_deg_s": sweep.rate_deg_s, "left_out": sweep.left_out}
    for direction in ("up", "down"):
        alpha, cl = sweep.branch(direction, QUASI_STATIC_BIN_DEG)
        out[direction] = {
            "alpha_deg": [round(float(a), 4) for a in alpha],
            "cl": [round(float(c), 5) for c in cl],
        }
    return out


def _spread_rows(spreads: dict[tuple[str, str, float], float]) -> list[list[Any]]:
    """[[model, level, freq_hz, value or None], ...]: NaN (undefined) as null in JSON."""
    return [[m, lv, f, s if math.isfinite(s) else None] for (m, lv, f), s in spreads.items()]


def config_dict(config: IdentificationConfig) -> dict[str, Any]:
    """The hyperparameters as JSON (tuples as lists): recorded so that a fit can be repeated
    with the parameters the run used."""
    to_dict = getattr(config, "to_dict", None)
    if callable(to_dict):
        return dict(to_dict())

    def plain(v: Any) -> Any:
        return [plain(x) for x in v] if isinstance(v, tuple | list) else v

    return {k: plain(v) for k, v in dataclasses.asdict(config).items()}


def bla_summary(bla: BLA) -> dict[str, float]:
    """Median levels over the excited lines [dB]: |G|, noise σ and (M ≥ 2) distortion σ."""

    def db_var(v: np.ndarray) -> float:
        m = float(np.median(v))
        return 10 * math.log10(m) if m > 0 else -math.inf

    out = {
        "G_db": float(20 * np.log10(np.median(np.abs(bla.G)))),
        "noise_db": db_var(bla.var_noise),
        "snr_db": float(10 * np.log10(np.median(bla.snr))),
    }
    if bla.M >= 2:
        out["nl_db"] = db_var(bla.var_nl)
        out["total_db"] = db_var(bla.var_total)
    return out


def modal_frequencies(model: LinearStateSpace) -> list[float]:
    """Natural frequencies [Hz] of the model's complex pole pairs, ascending."""
    p = model.poles()
    p = p[np.imag(p) > 0]
    return sorted(float(f) for f in np.abs(np.log(p)) * model.fs / (2 * math.pi))


def level_json(lv: LevelResult) -> dict[str, Any]:
    rec = lv.record
    entry: dict[str, Any] = {"name": lv.name, msg.OFFSET_DEG: rec.offset_deg, "role": lv.role}
    entry["periods_used"] = lv.periods_used
    entry["excluded_periods"] = lv.excluded
    if rec.data is not None:
        entry.update(N=rec.data.N, P=rec.data.P, M=rec.data.M, input_rms=rec.input_rms)
    entry["periods_in_file"] = rec.periods_in_file
    entry["dropped_periods"] = rec.dropped_periods
    if rec.path is not None:
        entry["file"] = str(rec.path)
    if rec.notes:
        entry["notes"] = list(rec.notes)
    if lv.bla is not None:
        entry[msg.BLA] = {
            "method": lv.bla.method,
            msg.FREQ_HZ: lv.bla.freq.tolist(),
            msg.G_RE: lv.bla.G.real.tolist(),
            msg.G_IM: lv.bla.G.imag.tolist(),
            msg.VAR_NOISE: lv.bla.var_noise.tolist(),
            msg.VAR_TOTAL: lv.bla.var_total.tolist(),
            msg.VAR_NL: lv.bla.var_nl.tolist(),
            "summary_db": bla_summary(lv.bla),
        }
    if lv.clusters is not None:
        entry[msg.CLUSTERS] = {
            msg.LABELS: lv.clusters.labels.tolist(),
            msg.K: int(lv.clusters.k),
            msg.DOMINANT: int(lv.clusters.dominant),
            msg.SIZES: [int(s) for s in lv.clusters.sizes],
            msg.SILHOUETTE: {str(k): v for k, v in lv.clusters.silhouette.items()},
        }
    if lv.linear is not None:
        entry["bla_ss"] = lv.linear.to_dict()
        entry["bla_ss"]["order_scanned"] = lv.order_scanned
        entry["bla_ss"]["modal_frequencies_hz"] = modal_frequencies(lv.linear)
    return entry


PAYLOAD_PERIODS = 2  # sine periods per prediction in the published model (C_l-alpha loops)


def _trim_prediction(pred: dict[str, Any]) -> dict[str, Any]:
    """The last PAYLOAD_PERIODS periods of a prediction, 5 decimals: the /identification/model
    payload stays small (the full records go to the report's figures)."""
    n = PAYLOAD_PERIODS * int(pred.get(msg.SAMPLES_PER_PERIOD, 0))
    out: dict[str, Any] = {}
    for key, value in pred.items():
        if isinstance(value, list) and n:
            out[key] = [round(float(v), 5) for v in value[-n:]]
        else:
            out[key] = value
    return out

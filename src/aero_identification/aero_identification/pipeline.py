"""The identification pipeline of a campaign (docs/design.md §1, §7), shared by the online
identifier node and the offline fit from a bag.

Per level: period clustering (k-means; the dominant cluster is kept), robust BLA over the two
realizations with noise and nonlinear-distortion levels. Models, as in the paper (§4.1):

- "all levels" (default): the PNLSS model is estimated on one realization of every level
  (realization ``estimation_realization``; one record per level, the mean of its kept periods),
  and the other realization is its validation set (model selection and the divergence guard).
  The linear models of this table are the BLA of each level (BLA FRF) and the state-space model
  fitted to it (BLA SS): a linear model is only valid around its own operating point.
- "level 1" (the paper's Table 1): BLA FRF, BLA SS and PNLSS all trained on the lowest level.

Every model is tested on the single-sine records (unseen data): relative RMS error
rms(y − ŷ)/rms(y − mean y). BLA FRF and BLA SS map deviations around the operating point, so
their prediction is centred on the sine record's measured mean; PNLSS predicts absolute C_l.
Models are simulated in periodic steady state (the record's last period is prepended and
dropped), like the measured data.
"""

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .bla import BLA, bla_levels_db, estimate_bla
from .campaign import CampaignAssembler, PeriodBlock, SineRecord
from .clustering import ClusterResult, period_clusters
from .config import IdentificationConfig
from .data import PeriodicData, random_phase_period
from .metrics import predict_bla_sine, relative_rms_error, steady_state_response
from .models import LinearStateSpace, PNLSSModel
from .pnlss import fit_pnlss, output_equation_start
from .quality import data_quality, data_quality_lines, data_quality_note
from .scan import ScanResult, scan_pnlss
from .subspace import fit_linear_ss

LEVEL_NAMES = {1: ["single"], 2: ["low", "high"], 3: ["low", "medium", "high"]}


@dataclass
class LevelResult:
    level: int
    name: str
    offset_deg: float
    clusters: ClusterResult | None = None
    bla: BLA | None = None
    linear: LinearStateSpace | None = None
    periods_used: int = 0
    excluded: list[str] = field(default_factory=list)


@dataclass
class IdentificationResult:
    config: IdentificationConfig
    fs: float
    levels: dict[int, LevelResult] = field(default_factory=dict)
    pnlss_all: PNLSSModel | None = None
    pnlss_level1: PNLSSModel | None = None
    linear_level1: LinearStateSpace | None = None
    errors_all: dict[tuple[str, str, float], float] = field(default_factory=dict)
    errors_level1: dict[tuple[str, str, float], float] = field(default_factory=dict)
    predictions: list[dict[str, Any]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)
    complete: bool = False
    level1_signature: bytes = b""  # which level-1 periods the level-1 PNLSS was trained on
    excluded_sines: list[str] = field(default_factory=list)
    data_quality: dict[str, Any] = field(default_factory=dict)  # see data_quality()
    scan: ScanResult | None = None  # the structure scan of the all-levels PNLSS (config.scan)
    # The same pipeline without clustering (config.clustering_ablation, final only) and what
    # clustering changed (clustering_effect()).
    no_clustering: "IdentificationResult | None" = None
    clustering_effect: dict[str, Any] = field(default_factory=dict)

    @property
    def clean(self) -> bool:
        return bool(self.data_quality.get("clean", True))

    @property
    def level_names(self) -> list[str]:
        return [r.name for r in sorted(self.levels.values(), key=lambda r: r.offset_deg)]

    @property
    def sine_freqs(self) -> list[float]:
        return sorted({round(k[2], 6) for k in (*self.errors_all, *self.errors_level1)})

    def tables(self) -> dict[str, tuple[str, str]]:
        from .report import table1

        levels, freqs = self.level_names, self.sine_freqs
        tables = {
            "all_levels": table1(self.errors_all, levels, freqs),
            "level1": table1(self.errors_level1, levels, freqs),
        }
        if self.no_clustering is not None:
            tables["no_clustering"] = table1(self.no_clustering.errors_all, levels, freqs)
        if self.clean:
            return tables
        # Never a clean-looking Table 1 from data that lost or excluded samples.
        note = data_quality_note(self.data_quality)
        return {key: (note + md, csv) for key, (md, csv) in tables.items()}

    def to_json_dict(self) -> dict[str, Any]:
        """The /identification/model payload (also models.json in the run directory)."""
        levels: dict[str, Any] = {}
        for lv in self.levels.values():
            entry: dict[str, Any] = {"name": lv.name, "offset_deg": lv.offset_deg}
            entry["periods_used"] = lv.periods_used
            entry["excluded_periods"] = lv.excluded
            if lv.bla is not None:
                entry["bla"] = {
                    "freq_hz": lv.bla.freq.tolist(),
                    "G_re": lv.bla.G.real.tolist(),
                    "G_im": lv.bla.G.imag.tolist(),
                    "var_noise": lv.bla.var_noise.tolist(),
                    "var_total": lv.bla.var_total.tolist(),
                    "var_nl": lv.bla.var_nl.tolist(),
                }
            if lv.clusters is not None:
                entry["clusters"] = {
                    "labels": lv.clusters.labels.tolist(),
                    "k": int(lv.clusters.k),
                    "dominant": int(lv.clusters.dominant),
                    "sizes": [int(s) for s in lv.clusters.sizes],
                    "silhouette": {str(k): v for k, v in lv.clusters.silhouette.items()},
                }
            if lv.linear is not None:
                entry["bla_ss"] = lv.linear.to_dict()
            levels[str(lv.level)] = entry
        tables = self.tables()
        return {
            "complete": self.complete,
            "config": {
                "nx": self.config.nx,
                "degrees": list(self.config.degrees),
                "structure": self.config.structure,
                "max_iter": self.config.max_iter,
            },
            "levels": levels,
            "models": {
                "pnlss_all_levels": self.pnlss_all.to_dict() if self.pnlss_all else None,
                "pnlss_level1": self.pnlss_level1.to_dict() if self.pnlss_level1 else None,
                "bla_ss_level1": self.linear_level1.to_dict() if self.linear_level1 else None,
            },
            "errors": {
                "all_levels": [[m, lv, f, e] for (m, lv, f), e in self.errors_all.items()],
                "level1": [[m, lv, f, e] for (m, lv, f), e in self.errors_level1.items()],
            },
            "table1": {
                "markdown": tables["all_levels"][0],
                "markdown_level1": tables["level1"][0],
                "markdown_no_clustering": tables["no_clustering"][0]
                if "no_clustering" in tables
                else None,
            },
            "clustering_effect": self.clustering_effect,
            "predictions": [_trim_prediction(p) for p in self.predictions],
            "warnings": self.warnings,
            "data_quality": self.data_quality,
            "timings_s": self.timings_s,
            "pnlss_scan": None
            if self.scan is None
            else {
                "table": self.scan.table,
                "rule": self.scan.rule,
                "seconds": self.scan.seconds,
                "workers": self.scan.workers,
            },
        }


PAYLOAD_PERIODS = 2  # sine periods per prediction in the published model (C_l-alpha loops)


def _trim_prediction(pred: dict[str, Any]) -> dict[str, Any]:
    """The last PAYLOAD_PERIODS periods of a prediction, 5 decimals: the /identification/model
    payload stays small (the full records go to the report's figures)."""
    n = PAYLOAD_PERIODS * int(pred.get("samples_per_period", 0))
    out: dict[str, Any] = {}
    for key, value in pred.items():
        if isinstance(value, list) and n:
            out[key] = [round(float(v), 5) for v in value[-n:]]
        else:
            out[key] = value
    return out


def _level_names(assembler: CampaignAssembler) -> dict[int, str]:
    levels = sorted(assembler.plan["levels"], key=lambda lv: _level_offset(assembler, lv["level"]))
    names = LEVEL_NAMES.get(len(levels), [f"level {i + 1}" for i in range(len(levels))])
    return {lv["level"]: names[i] for i, lv in enumerate(levels)}


def _level_offset(assembler: CampaignAssembler, level: int) -> float:
    for (lv, _), block in assembler.blocks.items():
        if lv == level:
            return block.offset_deg
    return 0.0


def _valid_periods(block: PeriodBlock) -> np.ndarray:
    return np.flatnonzero(block.period_valid())


def _periodic(blocks: list[PeriodBlock], fs: float, lines: np.ndarray, count: int) -> PeriodicData:
    """(N, count, M) data from the latest `count` valid periods of each block."""
    us, ys = [], []
    for block in blocks:
        cols = _valid_periods(block)[-count:]
        us.append(block.u[:, cols])
        ys.append(block.y[:, cols])
    return PeriodicData(np.stack(us, axis=2), np.stack(ys, axis=2), fs, lines)


def _excited_lines(assembler: CampaignAssembler, level: int, realization: int) -> np.ndarray:
    lv = next(x for x in assembler.plan["levels"] if x["level"] == level)
    return np.asarray(lv["realizations"][realization]["excited_lines"], dtype=int)


def identify(
    assembler: CampaignAssembler,
    config: IdentificationConfig | None = None,
    final: bool = False,
    models_from: IdentificationResult | None = None,
    previous: IdentificationResult | None = None,
    client: Any = None,
) -> IdentificationResult:
    """Run the pipeline on whatever the assembler holds so far (partial results early on).

    ``models_from``: reuse that result's clustering, BLAs and models and only validate on the
    sines (the online node does this when only sine records completed since its last refit:
    the multisine data, hence the models, are unchanged). ``previous``: the last refit, whose
    level-1 PNLSS is reused when the level-1 periods it was trained on did not change.
    ``client``: a ``dask.distributed.Client`` for the structure scan (``config.scan``, final
    identification only); None: local worker processes.
    """
    config = config or IdentificationConfig()
    if final and config.scan and models_from is not None and models_from.scan is None:
        # The final models come from the structure scan, which the online refits skip: the
        # multisine data did not change, but the all-levels PNLSS must still be chosen.
        models_from = None
    fs = assembler.fs
    result = IdentificationResult(config=config, fs=fs, complete=final)
    names = _level_names(assembler)
    level_ids = sorted(names, key=lambda lv: _level_offset(assembler, lv))
    est, val = config.estimation_realization, config.validation_realization
    t_start = time.perf_counter()
    if models_from is not None:
        result.levels = models_from.levels
        result.linear_level1 = models_from.linear_level1
        result.pnlss_all = models_from.pnlss_all
        result.scan = models_from.scan
        result.no_clustering = models_from.no_clustering
        result.pnlss_level1 = models_from.pnlss_level1
        result.level1_signature = models_from.level1_signature
        result.warnings = [w for w in models_from.warnings if not w.startswith("sine ")]
        result.timings_s = {"bla": 0.0, "pnlss": 0.0}
        _validate_on_sines(assembler, result, names)
        if result.no_clustering is not None:
            result.no_clustering = identify(
                assembler, result.no_clustering.config, final, models_from=result.no_clustering
            )
            result.clustering_effect = clustering_effect(assembler, result, result.no_clustering)
        result.data_quality = data_quality(assembler, result)
        result.timings_s["total"] = time.perf_counter() - t_start
        return result

    # 1. Per level: clustering of both realizations' periods and the robust BLA.
    for level in level_ids:
        res = LevelResult(level, names[level], _level_offset(assembler, level))
        result.levels[level] = res
        blocks = [assembler.blocks.get((level, m)) for m in (est, val)]
        if any(b is None for b in blocks):
            continue
        for b in blocks:
            assert b is not None
            for p in range(b.P):
                problem = b.period_problem(p)
                if problem and np.any(b.count_u[:, p] + b.count_y[:, p]):
                    res.excluded.append(f"realization {b.realization} period {p}: {problem}")
        counts = [len(_valid_periods(b)) for b in blocks if b is not None]
        if min(counts) < config.min_periods:
            continue
        data = _periodic(
            [b for b in blocks if b is not None],
            fs,
            _excited_lines(assembler, level, est),
            min(counts),
        )
        try:
            if config.clustering:
                res.clusters = period_clusters(data)
                kept = data.select(res.clusters.keep, min_periods=config.min_periods)
            else:
                kept = data
            if kept.M < 2:
                result.warnings.append(
                    f"level {res.name}: the dominant cluster leaves < 2 realizations; "
                    "BLA from all valid periods"
                )
                kept = data
            res.periods_used = kept.P * kept.M
            res.bla = estimate_bla(kept, method="robust")
            res.linear = fit_linear_ss(res.bla, nx=config.nx).with_operating_point(
                float(np.mean(kept.u)), float(np.mean(kept.y))
            )
        except ValueError as exc:
            result.warnings.append(f"level {res.name}: {exc}")
    result.timings_s["bla"] = time.perf_counter() - t_start

    low = result.levels.get(level_ids[0]) if level_ids else None
    result.linear_level1 = low.linear if low else None

    # 2. PNLSS on every level (estimation realization), validated on the other realization.
    t0 = time.perf_counter()
    ready = [
        lv
        for lv in level_ids
        if (lv, est) in assembler.blocks
        and (lv, val) in assembler.blocks
        and len(_valid_periods(assembler.blocks[(lv, est)])) >= config.min_periods
        and len(_valid_periods(assembler.blocks[(lv, val)])) >= 1
    ]
    if result.linear_level1 is not None and ready:
        if final and config.scan:
            result.scan = _scan_pnlss(assembler, ready, result, config, client)
            result.pnlss_all = result.scan.best if result.scan is not None else None
        else:
            result.pnlss_all = _fit_pnlss(assembler, ready, result, config, "all levels")
        if level_ids[0] in ready:
            # Level 1 is complete long before the campaign ends: refit its PNLSS only when its
            # kept periods changed (the fit is deterministic, so reuse gives the same model).
            signature = _level_signature(assembler, result, level_ids[0])
            if (
                previous is not None
                and previous.pnlss_level1 is not None
                and (previous.level1_signature == signature)
            ):
                result.pnlss_level1 = previous.pnlss_level1
            elif ready == [level_ids[0]]:
                result.pnlss_level1 = result.pnlss_all  # the same data: the same fit
            else:
                result.pnlss_level1 = _fit_pnlss(
                    assembler, [level_ids[0]], result, config, "level 1"
                )
            result.level1_signature = signature
    result.timings_s["pnlss"] = time.perf_counter() - t0

    # 3. Validation on the single sines.
    _validate_on_sines(assembler, result, names)

    # 4. The ablation: the same pipeline on every valid period (final identification only).
    if final and config.clustering and config.clustering_ablation:
        t0 = time.perf_counter()
        plain = dataclasses.replace(config, clustering=False, clustering_ablation=False)
        result.no_clustering = identify(assembler, plain, final=True, client=client)
        result.clustering_effect = clustering_effect(assembler, result, result.no_clustering)
        result.timings_s["no_clustering"] = time.perf_counter() - t0
    result.data_quality = data_quality(assembler, result)
    result.timings_s["total"] = time.perf_counter() - t_start
    return result


def clustering_effect(
    assembler: CampaignAssembler,
    clustered: IdentificationResult,
    plain: IdentificationResult,
) -> dict[str, Any]:
    """What clustering changed, per level: clusters, periods used, the BLA's levels
    (bla.bla_levels_db: SNR and SNLR near 1.02 Hz, distortion levels) and mean variances, and
    the all-levels PNLSS error on the validation realization's dominant-cluster periods (one
    steady-state mean period; both models scored on the same periods)."""
    cfg = clustered.config
    effect: dict[str, Any] = {}
    for level, lv in clustered.levels.items():
        other = plain.levels.get(level)
        entry: dict[str, Any] = {
            "k": None if lv.clusters is None else int(lv.clusters.k),
            "sizes": None if lv.clusters is None else [int(s) for s in lv.clusters.sizes],
            "periods_used": lv.periods_used,
            "periods_used_without": None if other is None else other.periods_used,
        }
        for tag, bla in (("with", lv.bla), ("without", other.bla if other else None)):
            if bla is None:
                continue
            try:
                entry[f"bla_{tag}"] = bla_levels_db(bla)
            except ValueError:
                entry[f"bla_{tag}"] = {}
            # Variances of one realization's and one period's FRF (bla.BLA: × M and × M·P),
            # relative to |G|², so that BLAs from different numbers of periods compare.
            g2 = np.abs(bla.G) ** 2
            nl = float(np.mean(bla.var_nl * bla.M / g2))
            entry[f"bla_{tag}"]["var_nl_db"] = float(10 * np.log10(nl)) if nl > 0 else None
            entry[f"bla_{tag}"]["var_noise_db"] = float(
                10 * np.log10(np.mean(bla.var_noise * bla.M * bla.P / g2))
            )
        # The PNLSS fit's own validation record of this level: its kept periods' mean.
        sets = _pnlss_sets(assembler, [level], clustered, cfg) if lv.bla is not None else None
        if sets is not None:
            u, y = sets[1].u[:, 0, 0], sets[1].y[:, 0, 0]
            for tag, model in (("with", clustered.pnlss_all), ("without", plain.pnlss_all)):
                if model is None:
                    continue
                y_hat = steady_state_response(model, u, u.size)
                entry[f"pnlss_validation_{tag}"] = (
                    relative_rms_error(y, y_hat) if np.all(np.isfinite(y_hat)) else None
                )
            val = cfg.validation_realization
            entry["validation_periods"] = len(_kept_columns(assembler, clustered, level, val))
        effect[lv.name] = entry
    return effect


def warm_up() -> float:
    """Run every stage once on a small synthetic record; returns the seconds it took.

    A fresh worker process pays its imports (scipy, scikit-learn) and the loading of the
    compiled numba kernels on its first call; the identifier node calls this when it starts so
    the first refit does not.
    """
    t0 = time.perf_counter()
    rng = np.random.default_rng(0)
    N, P, M = 128, 2, 2
    lines = np.arange(1, N // 2, 2)
    u = np.zeros((N, P, M))
    for m in range(M):
        u[:, :, m] = random_phase_period(rng, N, lines)[:, None] * 10.0
    y = 0.5 * u + 0.01 * np.roll(u, 1, axis=0) + 0.1 * u**2
    data = PeriodicData(u, y + 1e-3 * rng.standard_normal(y.shape), 1.0, lines)
    period_clusters(data)
    lin = fit_linear_ss(estimate_bla(data, method="robust"), nx=1)
    fit_pnlss(data, lin, degrees=(2, 3), max_iter=2, validation=data)
    return time.perf_counter() - t0


def _kept_columns(
    assembler: CampaignAssembler, result: IdentificationResult, level: int, m: int
) -> np.ndarray:
    """Valid periods of (level, m) that the level's clustering kept (all valid if no clusters)."""
    block = assembler.blocks[(level, m)]
    valid = _valid_periods(block)
    clusters = result.levels[level].clusters
    if clusters is None:
        return valid
    # Clustering ran on the latest `count` valid periods of each realization.
    count = clusters.labels.shape[0]
    order = [result.config.estimation_realization, result.config.validation_realization]
    column = order.index(m)
    cols = valid[-count:]
    keep = clusters.keep[:, column]
    return cols[keep] if keep.any() else cols


def _clustered_outputs(
    assembler: CampaignAssembler, result: IdentificationResult, level: int
) -> np.ndarray | None:
    """(N, P, M) outputs of the periods the level's clustering labelled (the `_periodic` data
    of step 1), or None without clusters."""
    clusters = result.levels[level].clusters
    if clusters is None:
        return None
    cfg = result.config
    blocks = [
        assembler.blocks[(level, m)]
        for m in (cfg.estimation_realization, cfg.validation_realization)
    ]
    lines = _excited_lines(assembler, level, cfg.estimation_realization)
    return _periodic(blocks, result.fs, lines, clusters.labels.shape[0]).y


def _level_signature(
    assembler: CampaignAssembler, result: IdentificationResult, level: int
) -> bytes:
    """The estimation and validation periods a level's PNLSS fit would use, as bytes."""
    cfg = result.config
    parts = []
    for m in (cfg.estimation_realization, cfg.validation_realization):
        cols = _kept_columns(assembler, result, level, m)
        block = assembler.blocks[(level, m)]
        parts.append(
            cols.astype(np.int64).tobytes()
            + block.u[:, cols].tobytes()
            + block.y[:, cols].tobytes()
        )
    return b"|".join(parts)


def _scan_pnlss(
    assembler: CampaignAssembler,
    levels: list[int],
    result: IdentificationResult,
    config: IdentificationConfig,
    client: Any,
) -> ScanResult | None:
    """The all-levels PNLSS by the cross-validated structure scan (scan.py): the training and
    validation sets of `_fit_pnlss`, every order's linear start from the level-1 BLA."""
    sets = _pnlss_sets(assembler, levels, result, config)
    low = result.levels[levels[0]] if levels else None
    if sets is None or low is None or low.bla is None or result.linear_level1 is None:
        return None
    data, validation = sets
    u0, y0 = result.linear_level1.u_mean, result.linear_level1.y_mean
    try:
        linear = {
            n: fit_linear_ss(low.bla, nx=n).with_operating_point(float(u0[0]), float(y0[0]))
            for n in sorted(set(config.scan_nx))
        }
        if client is None and config.scan_scheduler:
            from dask.distributed import Client

            with Client(config.scan_scheduler, timeout="30s") as remote:
                return _scan_pnlss(assembler, levels, result, config, remote)
        return scan_pnlss(
            data,
            validation,
            nx=config.scan_nx,
            degrees=config.scan_degrees,
            equations=config.scan_equations,
            structures=(config.structure,),
            max_iter=config.scan_max_iter,
            client=client,
            linear=linear,
            workers=config.scan_workers or None,
            record_weights=_level_weights(data, config.level_weighting),
            validation_weights=_level_weights(validation, config.level_weighting),
            starts=("linear", "output_ls"),  # the latter: the single-structure fit's start
        )
    except (ValueError, OSError) as exc:  # OSError: the Dask scheduler cannot be reached
        result.warnings.append(f"PNLSS structure scan failed: {exc}")
        return None


def _pnlss_sets(
    assembler: CampaignAssembler,
    levels: list[int],
    result: IdentificationResult,
    config: IdentificationConfig,
) -> tuple[PeriodicData, PeriodicData] | None:
    """Training and validation sets of the PNLSS fit: one steady-state mean period per level."""
    est, val = config.estimation_realization, config.validation_realization
    cols = {lv: _kept_columns(assembler, result, lv, est) for lv in levels}
    if min(len(c) for c in cols.values()) < 1:
        return None
    # One training record per level: the mean of all its kept periods. The input is periodic,
    # so Σ_p ||ŷ − y_p||² = P ||ŷ − ȳ||² + const: the same least-squares problem as fitting every
    # period, P times cheaper, and every kept period counts even when the levels keep different
    # numbers of periods.
    u = np.stack(
        [assembler.blocks[(lv, est)].u[:, cols[lv]].mean(axis=1, keepdims=True) for lv in levels],
        axis=2,
    )
    y = np.stack(
        [assembler.blocks[(lv, est)].y[:, cols[lv]].mean(axis=1, keepdims=True) for lv in levels],
        axis=2,
    )
    lines = _excited_lines(assembler, levels[0], est)
    data = PeriodicData(u, y, assembler.fs, lines)
    # Validation: the other realization, likewise one steady-state mean period per level
    # (its kept periods), so choosing the best iterate costs one period's simulation per
    # level instead of all of them.
    vcols = {lv: _kept_columns(assembler, result, lv, val) for lv in levels}
    if min(len(c) for c in vcols.values()) < 1:
        return None
    u_val, y_val = (
        np.stack(
            [
                getattr(assembler.blocks[(lv, val)], name)[:, vcols[lv]].mean(axis=1, keepdims=True)
                for lv in levels
            ],
            axis=2,
        )
        for name in ("u", "y")
    )
    return data, PeriodicData(u_val, y_val, assembler.fs, lines)


def _fit_pnlss(
    assembler: CampaignAssembler,
    levels: list[int],
    result: IdentificationResult,
    config: IdentificationConfig,
    label: str,
) -> PNLSSModel | None:
    sets = _pnlss_sets(assembler, levels, result, config)
    if sets is None:
        return None
    data, validation = sets
    weights = _level_weights(data, config.level_weighting)
    val_weights = _level_weights(validation, config.level_weighting)
    lin = result.linear_level1
    assert lin is not None
    try:
        start = output_equation_start(
            data, lin, degrees=config.degrees, structure=config.structure, validation=validation,
            record_weights=weights, validation_weights=val_weights,
        )  # fmt: skip
        return fit_pnlss(
            data,
            lin,
            degrees=config.degrees,
            structure=config.structure,
            max_iter=config.max_iter,
            validation=validation,
            initial_model=start,
            record_weights=weights,
            validation_weights=val_weights,
        )
    except (ValueError, np.linalg.LinAlgError) as exc:
        result.warnings.append(f"PNLSS ({label}) failed: {exc}")
        return None


def _level_weights(data: PeriodicData, weighting: str) -> np.ndarray | None:
    """Per-record weights of a one-record-per-level set (config.level_weighting)."""
    if weighting == "none":
        return None
    if weighting != "relative":
        raise ValueError(f"level_weighting must be 'relative' or 'none'; got {weighting!r}")
    var = np.var(data.y, axis=0).T.reshape(-1)  # record r = m·P + p
    if not np.all(var > 0):
        raise ValueError("a level's output is constant: relative weighting is undefined")
    return 1.0 / var


def _validate_on_sines(
    assembler: CampaignAssembler, result: IdentificationResult, names: dict[int, str]
) -> None:
    for rec in sorted(assembler.sines.values(), key=lambda r: r.index):
        if not rec.valid():
            # Still streaming (its last sample not in yet) is no fault until the final refit.
            in_progress = not (rec.count_u[-1] and rec.count_y[-1])
            started = np.any(rec.count_u) or np.any(rec.count_y)
            if (started or rec.mark) and (result.complete or not in_progress):
                result.excluded_sines.append(f"{rec.name}: {rec.problem()}")
                result.warnings.append(f"{rec.name}: not used for validation ({rec.problem()})")
            continue
        level = _nearest_level(result, rec)
        if level is None:
            continue
        name = result.levels[level].name
        f = round(rec.frequency_hz, 6)
        own = result.levels[level]
        y_mean, u_mean = float(np.mean(rec.y)), float(np.mean(rec.u))
        preds: dict[str, np.ndarray] = {}
        low = next(iter(sorted(result.levels.values(), key=lambda r: r.offset_deg)))
        # Linear models predict deviations: centred on the record's measured means.
        for lin_level, errors, key in (
            (own, result.errors_all, "BLA SS (own level)"),
            (low, result.errors_level1, "BLA SS (level 1)"),
        ):
            if lin_level.bla is None or lin_level.linear is None:
                continue
            y_frf = predict_bla_sine(lin_level.bla, rec.frequency_hz, rec.u, y_mean)
            errors[("BLA FRF", name, f)] = relative_rms_error(rec.y, y_frf)
            lin = lin_level.linear.with_operating_point(u_mean, y_mean)
            y_ss = steady_state_response(lin, rec.u, rec.samples_per_period)
            errors[("BLA SS", name, f)] = relative_rms_error(rec.y, y_ss)
            preds[key] = y_ss
        for model, errors, key in (
            (result.pnlss_all, result.errors_all, "PNLSS (all levels)"),
            (result.pnlss_level1, result.errors_level1, "PNLSS (level 1)"),
        ):
            if model is None:
                continue
            y_hat = steady_state_response(model, rec.u, rec.samples_per_period)
            errors[("PNLSS", name, f)] = (
                relative_rms_error(rec.y, y_hat) if np.all(np.isfinite(y_hat)) else float("inf")
            )
            preds[key] = y_hat
        result.predictions.append(
            {
                "name": f"sine {name} {rec.frequency_hz:g} Hz",
                "level": name,
                "frequency_hz": rec.frequency_hz,
                "samples_per_period": rec.samples_per_period,
                "alpha_deg": rec.u.tolist(),
                "cl_measured": rec.y.tolist(),
                **{f"cl_{k}": v.tolist() for k, v in preds.items()},
            }
        )


def _nearest_level(result: IdentificationResult, rec: SineRecord) -> int | None:
    if not result.levels:
        return None
    return min(result.levels.values(), key=lambda r: abs(r.offset_deg - rec.offset_deg)).level


def write_report(
    result: IdentificationResult,
    assembler: CampaignAssembler,
    out_dir: str | Path,
    quasi_static: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict[str, Path]:
    """Models (JSON), Table 1 (Markdown, CSV) and the figures of paper Figs. 5-9, as PNG."""
    from . import report

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    payload = result.to_json_dict()
    path = out / "models.json"
    path.write_text(json.dumps(payload, indent=1, allow_nan=True))
    written["models"] = path
    for key, (markdown, csv) in result.tables().items():
        (out / f"table1_{key}.md").write_text(markdown)
        (out / f"table1_{key}.csv").write_text(csv)
        written[f"table1_{key}"] = out / f"table1_{key}.md"
    lines = data_quality_lines(result.data_quality)
    samples = result.data_quality.get("samples", {})
    text = ["# Data quality", ""]
    text += [
        f"- {name}: {c['received']} of {c['expected']} plan samples received once, "
        f"{c['missing']} missing, {c['duplicated']} duplicated with another value, "
        f"{c.get('redelivered', 0)} delivered twice with the same value (harmless), "
        f"{c['outside_plan']} outside the plan"
        for name, c in samples.items()
    ]
    text += [
        "",
        "Clean: every plan sample arrived once; no anomaly; nothing excluded."
        if not lines
        else "**Not clean**:",
        *[f"- {line}" for line in lines],
    ]
    path = out / "data_quality.md"
    path.write_text("\n".join(text).rstrip() + "\n")
    written["data_quality"] = path
    if result.scan is not None:
        scan_md = (
            "# PNLSS structure scan (all levels)\n\n"
            "Validation error: relative RMS error on the validation realization's steady-state "
            "periods (docs/design.md §7.6).\n\n" + result.scan.to_markdown()
        )
        (out / "pnlss_scan.md").write_text(scan_md)
        (out / "pnlss_scan.csv").write_text(result.scan.to_csv())
        written["pnlss_scan"] = out / "pnlss_scan.md"
        written["pnlss_scan_plot"] = report.plot_scan(result.scan, out / "pnlss_scan.png")
    for lv in result.levels.values():
        tag = lv.name.replace(" ", "_")
        if lv.bla is not None:
            written[f"frf_{tag}"] = report.plot_frf(
                lv.bla, out / f"frf_{tag}.png", f"BLA, {lv.name} level ({lv.offset_deg:g}°)"
            )
            written[f"spectrum_{tag}"] = report.plot_output_spectrum(
                lv.bla, out / f"output_spectrum_{tag}.png", f"Output spectrum, {lv.name} level"
            )
        if lv.clusters is not None:
            written[f"clusters_{tag}"] = report.plot_clusters(
                lv.clusters.labels,
                out / f"clusters_{tag}.png",
                y=_clustered_outputs(assembler, result, lv.level),
                fs=result.fs,
                title=f"Clusters, {lv.name} level (k = {lv.clusters.k})",
            )
    if result.clustering_effect:
        path = out / "clustering.md"
        path.write_text(report.clustering_markdown(result.clustering_effect))
        written["clustering"] = path
    for pred in result.predictions:
        tag = pred["name"].replace(" ", "_").replace(".", "p")
        alpha = np.asarray(pred["alpha_deg"])
        measured = np.asarray(pred["cl_measured"])
        simulated = {
            k[3:]: np.asarray(v)
            for k, v in pred.items()
            if k.startswith("cl_") and k != "cl_measured"
        }
        written[f"cl_alpha_{tag}"] = report.plot_cl_alpha(
            alpha, measured, out / f"cl_alpha_{tag}.png", simulated, quasi_static, pred["name"]
        )
        t = np.arange(len(measured)) / result.fs
        written[f"time_{tag}"] = report.plot_time_series(
            t, measured, simulated, out / f"time_{tag}.png", title=pred["name"]
        )
    return written

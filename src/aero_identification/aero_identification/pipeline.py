"""The identification pipeline: one `identify(dataset, config)` for every source
(docs/design.md §1.2, §7): the identifier node's stream, a bag, CSV and MAT records.

Every stage runs that the data allow, each in its own module:

1. level_identification.py: per level, k-means clustering of the periods (the dominant cluster is
   kept; needs ≥ 3 periods) and the BLA over the kept periods: the robust method with noise
   and nonlinear distortion levels when the level has M ≥ 2 realizations, the Local Polynomial
   Method with M = 1 (the distortion level then cannot be separated);
2. level_identification.py: per level, a linear state-space model of its BLA, at ``config.nx`` or,
   with nx = 0, at the order the subspace order scan selects (1 … ``config.max_order``);
3. pnlss_training.py: one PNLSS model over every estimation level ("all levels";
   [PitchingWing] §4.1), started from the lowest level's linear model, trained on one mean
   period per level and training realization and choosing its iterate on held-out periods of
   the same levels (estimation_sets.py: built once, `EstimationSets`, and shared by every
   model class); with ``config.scan`` (the final models: the final
   identification, or ``final_models``) the cross-validated structure scan chooses its
   structure; and, when the source plans sines, the paper's "level 1" PNLSS trained on the
   lowest level alone;
4. validation.py: validation on the single sines (Table 1: relative RMS error
   rms(y − ŷ)/rms(y − mean y); BLA FRF and BLA SS centred on the record's measured means,
   PNLSS absolute; each cell's ± is the std over the sine's periods of the per-period error,
   `metrics.relative_rms_error_spread`) and on held-out levels (``held_out``: never used by
   any fit, so their errors are test errors); bootstrap.py: with ``config.bootstrap`` (final
   only) each cell's estimation spread, the std over refits on bootstrap replicates of the
   estimation periods;
5. clustering_ablation.py: with ``config.clustering_ablation`` (the final models only), the
   same pipeline without clustering, and what clustering changed.

The final models (the scan of stage 3, and stage 5) can be fitted before the final call, once the
estimation data are complete (``final_models``); the final call then takes them over with
``models_from`` and only validates (the identifier node does this while its last sines stream).

Models are simulated in periodic steady state (the record's last period is prepended and
dropped), like the measured data.
"""

import dataclasses
import hashlib
import math
import time
from collections.abc import Sequence
from concurrent.futures import Future, wait
from typing import Any

import numpy as np

from .beddoes_leishman import fit_beddoes_leishman
from .bootstrap import estimation_bootstrap
from .bspline_lpv import (
    LPV_MAX_PARAMETERS,
    LpvSettings,
    fit_bspline_lpv,
    lpv_parameters,
    scan_bspline_lpv,
)
from .clustering_ablation import (
    ablation_config,
    clustering_dropped,
    clustering_effect,
    run_ablation,
    start_ablation,
)
from .dataset import Dataset
from .estimation_sets import EstimationSets, ready_levels
from .hyperparameters import IdentificationConfig
from .identification_result import (
    SELECTED_LPV,
    SELECTED_PNLSS,
    IdentificationResult,
    LevelResult,
    Log,
    pnlss_structure,
)
from .level_identification import level_models
from .pnlss import one_blas_thread
from .pnlss_training import (
    MAX_JACOBIAN_BYTES,
    fit_client,
    fit_levels,
    jacobian_bytes,
    level_signature,
    scan_levels,
)
from .scan import periodic_error
from .validation import validate

# What a refit that only validates takes over from the previous result (identify's models_from).
REUSED = (
    "levels", "linear_level1", "pnlss_all", "scan", "no_clustering", "pnlss_level1",
    "level1_signature", "pnlss_start_level", "pnlss_held_out", "final_models",
    "beddoes_leishman", "semi_empirical_signature", "lpv_all", "lpv_scan", "selection",
)  # fmt: skip


def final_stages(config: IdentificationConfig) -> bool:
    """Whether the final models need stages the online refits skip: the structure scan of
    the all-levels PNLSS, the clustering ablation."""
    return (config.pnlss and config.scan) or (config.clustering and config.clustering_ablation)


def identify(
    dataset: Dataset,
    config: IdentificationConfig | None = None,
    final: bool = False,
    models_from: IdentificationResult | None = None,
    previous: IdentificationResult | None = None,
    client: Any = None,
    held_out: Sequence[str] = (),
    log: Log | None = None,
    final_models: bool = False,
) -> IdentificationResult:
    """Run every stage the dataset allows (partial results from a partial stream).

    Args:
        dataset: from a source adapter (campaign_source.campaign_dataset, records.read_dataset).
        config: hyperparameters (default: IdentificationConfig()).
        final: the final identification (the structure scan and the clustering ablation run
            only then; a sine record still streaming is no fault before it).
        models_from: reuse that result's clustering, BLAs and models and only validate (the
            online node does this when only sine records completed since its last refit).
        previous: the last refit, whose level-1 PNLSS is reused when the level-1 periods it was
            trained on did not change (the fit is deterministic, so reuse gives the same model).
        client: a ``dask.distributed.Client`` for the structure scan and the bootstrap refits;
            None: local processes.
        held_out: names of levels kept out of every fit, for validation errors.
        log: progress messages.
        final_models: the estimation data are complete (the identifier node: every multisine
            period of the plan is in, sines may still stream): fit the models as the final
            identification does (the structure scan, the clustering ablation), so that the
            final call can take them over with ``models_from`` and only validate. ``final``
            implies it.
    """
    with one_blas_thread():
        return _identify(dataset, config or IdentificationConfig(), final, final or final_models,
                         models_from, previous, client, tuple(held_out),
                         log or (lambda _m: None))  # fmt: skip


def _identify(
    dataset: Dataset,
    config: IdentificationConfig,
    final: bool,
    final_models: bool,
    models_from: IdentificationResult | None,
    previous: IdentificationResult | None,
    client: Any,
    held_out: tuple[str, ...],
    say: Log,
) -> IdentificationResult:
    if final_models and models_from is not None and not models_from.final_models:
        # The final models come from the structure scan and the ablation, which the online
        # refits skip: the multisine data did not change, but those stages must still run.
        models_from = None
    unknown = sorted(set(held_out) - {lv.name for lv in dataset.levels})
    if unknown:
        raise ValueError(f"held-out level(s) {unknown} not in the dataset")
    result = IdentificationResult(
        config=config,
        fs=dataset.fs,
        complete=final,
        source=dataset.source,
        sines_planned=dataset.sines_planned,
        # Without stages of its own (no scan, no ablation) every refit fits the final models.
        final_models=final_models or not final_stages(config),
    )
    t_start = time.perf_counter()
    ablation = None
    if models_from is not None:
        _reuse_models(dataset, result, models_from)
    else:
        # 1-2. Per level: clustering, BLA, linear model.
        _fit_level_models(dataset, result, config, held_out, say)
        # 5 (started here). The clustering ablation, the same pipeline on every valid period,
        # runs in a thread beside steps 3-4: its fits and this one's are independent, and the
        # PNLSS kernels release the GIL, so the final identification uses both cores.
        ablation = start_ablation(
            identify, dataset, result, config, final, final_models, client, held_out, say
        )
    try:
        if models_from is None:
            # 3. Every model class on the same estimation sets, built once here.
            estimation = [r for r in result.levels.values() if r.role == "estimation"]
            result.linear_level1 = estimation[0].linear if estimation else None
            ready = ready_levels(result)
            sets = EstimationSets.of(ready, config) if ready else None
            # 3a. PNLSS on every estimation level, its iterate chosen on their held-out periods.
            if sets is not None:
                _fit_pnlss_models(dataset, result, sets, config, final_models, previous, client,
                                  say)  # fmt: skip
            # 3b. The second model class on the same sets, and the selected model.
            if config.lpv and sets is not None:
                _fit_lpv_models(result, sets, config, final_models, client, say)
            result.selection = select_model(result, sets) if sets is not None else {}
            # 3c. The semi-empirical baseline, from the quasi-static sweep and the same sets.
            if config.semi_empirical:
                _fit_semi_empirical(dataset, result, sets, previous, say)
        # 4. Validation: single sines, held-out levels; Table 1's estimation spread.
        validate(dataset, result)
        if final and config.bootstrap > 0:
            estimation_bootstrap(dataset, result, config, client, say)
    except BaseException:
        if ablation is not None:  # not left running past this call (and its BLAS limit)
            wait([ablation])
        raise
    # 5. The ablation's result.
    _ablation_result(
        dataset, result, config, final, final_models, ablation, models_from, client, held_out, say
    )
    _finish(dataset, result, t_start)
    return result


def _reuse_models(
    dataset: Dataset, result: IdentificationResult, models_from: IdentificationResult
) -> None:
    """Take over a previous result's clustering, BLAs and models, to validate them only."""
    for key in REUSED:
        setattr(result, key, getattr(models_from, key))
    result.levels = dict(result.levels)  # this result's own (the records are replaced)
    # The level records carry this dataset's exclusions (the models are unchanged).
    for lv in dataset.levels:
        if lv.name in result.levels:
            result.levels[lv.name] = dataclasses.replace(result.levels[lv.name], record=lv)
    result.warnings = [w for w in models_from.warnings if not w.startswith("sine ")]
    result.timings_s = {"bla": 0.0, "pnlss": 0.0}


def _fit_level_models(
    dataset: Dataset,
    result: IdentificationResult,
    config: IdentificationConfig,
    held_out: tuple[str, ...],
    say: Log,
) -> None:
    t_start = time.perf_counter()
    for lv in dataset.levels:
        role = "held out" if lv.name in held_out else "estimation"
        res = LevelResult(lv, role)
        result.levels[lv.name] = res
        if lv.data is None:
            continue
        try:
            level_models(lv, res, config, result.warnings, say)
        except ValueError as exc:
            result.warnings.append(f"level {lv.name}: {exc}")
    result.timings_s["bla"] = time.perf_counter() - t_start


def _fit_pnlss_models(
    dataset: Dataset,
    result: IdentificationResult,
    sets: EstimationSets,
    config: IdentificationConfig,
    final_models: bool,
    previous: IdentificationResult | None,
    client: Any,
    say: Log,
) -> None:
    """The all-levels PNLSS (scanned for the final models) and the level-1 PNLSS."""
    low = next(r for r in result.levels.values() if r.role == "estimation")
    t0 = time.perf_counter()
    if config.pnlss and result.linear_level1 is not None:
        result.pnlss_start_level = low.name
        if final_models and config.scan:
            result.scan = scan_levels(sets, result, config, client, say)
            result.pnlss_all = result.scan.best if result.scan is not None else None
        else:
            result.pnlss_all = fit_levels(sets, result, config, "all levels", say)
        if dataset.sines_planned and sets.levels[0] is low:
            # Level 1 is complete long before the campaign ends: refit its PNLSS only when its
            # kept periods changed.
            signature = level_signature(low, config)
            if (
                previous is not None
                and previous.pnlss_level1 is not None
                and previous.level1_signature == signature
            ):
                result.pnlss_level1 = previous.pnlss_level1
            elif len(sets.levels) == 1:
                result.pnlss_level1 = result.pnlss_all  # the same data: the same fit
            else:
                level1 = EstimationSets.of([low], config)
                result.pnlss_level1 = fit_levels(level1, result, config, "level 1", say)
            result.level1_signature = signature
    result.timings_s["pnlss"] = time.perf_counter() - t0


def _fit_lpv_models(
    result: IdentificationResult,
    sets: EstimationSets,
    config: IdentificationConfig,
    final_models: bool,
    client: Any,
    say: Log,
) -> None:
    """The B-spline LPV model (bspline_lpv.py) on the estimation sets, from the PNLSS's linear
    model; scanned over its grid for the final models (``config.scan``), on the PNLSS scan's
    Dask client when there is one (``client``, ``config.scan_scheduler``)."""
    lin = result.linear_level1
    if lin is None:
        return
    t0 = time.perf_counter()
    train, held = sets.train, sets.held
    degrees = (config.lpv_scan_state_degrees if final_models and config.scan
               else (config.lpv_state_degree,))  # fmt: skip
    intervals = (config.lpv_scan_intervals if final_models and config.scan
                 else (config.lpv_intervals,))  # fmt: skip
    n_par = lpv_parameters(lin.nx, max(intervals), max(degrees))
    samples = train.N * train.P * train.M
    if n_par > LPV_MAX_PARAMETERS or jacobian_bytes(train, n_par) > MAX_JACOBIAN_BYTES:
        result.warnings.append(
            f"B-spline LPV (all levels) not fitted: at nx {lin.nx} (the linear model's order), "
            f"{max(intervals)} knot intervals and state degree {max(degrees)} it has {n_par} "
            f"parameters on {samples} samples (limits: {LPV_MAX_PARAMETERS} parameters, a "
            f"{MAX_JACOBIAN_BYTES / 1e9:g} GB Jacobian); set nx lower, or fewer intervals or "
            "degrees"
        )
        return
    settings = LpvSettings(
        intervals=config.lpv_intervals, state_degree=config.lpv_state_degree,
        max_iter=config.lpv_max_iter, weighting=config.lpv_weighting,
        stress=config.scan_stress,
    )  # fmt: skip
    try:
        if final_models and config.scan and held is not None:
            with fit_client(config, client) as executor:
                result.lpv_scan = scan_bspline_lpv(
                    train, held, lin, config.lpv_scan_intervals, config.lpv_scan_state_degrees,
                    settings, client=executor,
                )  # fmt: skip
            result.lpv_all = result.lpv_scan.best
        else:
            result.lpv_all = fit_bspline_lpv(train, lin, settings, held)
    except (ValueError, np.linalg.LinAlgError, OSError) as exc:  # OSError: no scheduler
        result.warnings.append(f"B-spline LPV (all levels) failed: {exc}")
        return
    result.timings_s["lpv"] = time.perf_counter() - t0
    say(f"B-spline LPV (all levels): {result.lpv_all.describe()}, "
        f"{result.timings_s['lpv']:.1f} s")  # fmt: skip


def select_model(result: IdentificationResult, sets: EstimationSets) -> dict[str, Any]:
    """The selected model: of the all-levels PNLSS and the B-spline LPV model, the one of
    lower error on the estimation sets' held-out periods (scan.periodic_error, the scans'
    score; the sines are not seen), with every candidate's error. Empty when neither is fitted
    or nothing is held out."""
    models: dict[str, Any] = {}
    structures: dict[str, str] = {}
    if result.pnlss_all is not None:
        models[SELECTED_PNLSS] = result.pnlss_all
        structures[SELECTED_PNLSS] = pnlss_structure(result.pnlss_all)
    if result.lpv_all is not None:
        models[SELECTED_LPV] = result.lpv_all
        structures[SELECTED_LPV] = result.lpv_all.describe()
    if not models or sets.held is None:
        return {}
    scores = {name: periodic_error(m, sets.held) for name, m in models.items()}
    finite = {n: s for n, s in scores.items() if math.isfinite(s[0])}
    if not finite:
        return {}
    chosen = min(finite, key=lambda n: finite[n][0])
    return {
        "class": chosen,
        "structure": structures[chosen],
        "held_out": sets.how,
        "validation_errors": {n: s[0] for n, s in scores.items()},
        "validation_se": {n: s[1] for n, s in scores.items()},
    }


def _fit_semi_empirical(
    dataset: Dataset,
    result: IdentificationResult,
    sets: EstimationSets | None,
    previous: IdentificationResult | None,
    say: Log,
) -> None:
    """The Beddoes–Leishman baseline (beddoes_leishman.py) on the estimation sets, its static
    curves from the quasi-static sweep; without a sweep, one warning says why its Table 1 row
    is absent. The previous refit's model is reused when its sweep and sets are the same (the
    fit is deterministic)."""
    t0 = time.perf_counter()
    if dataset.quasi_static is None:
        result.warnings.append(
            "Beddoes-Leishman baseline not fitted: the source has no quasi-static sweep (its "
            "static lift curve calibrates the model), so no table has a row for it"
        )
        return
    if sets is None:
        return
    train, held = sets.train, sets.held
    digest = hashlib.sha256()
    for part in (dataset.quasi_static.alpha_up, dataset.quasi_static.cl_up,
                 dataset.quasi_static.alpha_down, dataset.quasi_static.cl_down, train.u, train.y,
                 *((held.u, held.y) if held is not None else ())):  # fmt: skip
        digest.update(np.ascontiguousarray(part).tobytes())
    result.semi_empirical_signature = digest.digest()
    if (
        previous is not None
        and previous.beddoes_leishman is not None
        and previous.semi_empirical_signature == result.semi_empirical_signature
    ):
        result.beddoes_leishman = previous.beddoes_leishman
        return
    try:
        result.beddoes_leishman = fit_beddoes_leishman(dataset.quasi_static, train, held)
    except ValueError as exc:
        result.warnings.append(f"Beddoes-Leishman baseline not fitted: {exc}")
        return
    result.timings_s["semi_empirical"] = time.perf_counter() - t0
    say(f"Beddoes-Leishman baseline: {result.beddoes_leishman.describe()}, "
        f"{result.timings_s['semi_empirical']:.1f} s")  # fmt: skip


def _ablation_result(
    dataset: Dataset,
    result: IdentificationResult,
    config: IdentificationConfig,
    final: bool,
    final_models: bool,
    ablation: Future[tuple[IdentificationResult, float]] | None,
    models_from: IdentificationResult | None,
    client: Any,
    held_out: tuple[str, ...],
    say: Log,
) -> None:
    """The identification without clustering (final models only), and what clustering
    changed."""
    if models_from is not None:  # the reused ablation, validated on this dataset
        if result.no_clustering is not None:
            result.no_clustering = identify(
                dataset, result.no_clustering.config, final, models_from=result.no_clustering,
                held_out=held_out,
            )  # fmt: skip
            result.clustering_effect = clustering_effect(result, result.no_clustering)
        return
    if not (final_models and config.clustering and config.clustering_ablation):
        return
    plain = ablation_config(config)
    if ablation is not None:
        result.no_clustering, result.timings_s["no_clustering"] = ablation.result()
    elif clustering_dropped(result):  # it could not run beside (ablation_beside)
        result.no_clustering, result.timings_s["no_clustering"] = run_ablation(
            identify, dataset, plain, final, client, held_out, say
        )
    else:  # one cluster everywhere: every valid period was used, the same identification
        # (its config has no bootstrap, so neither has it)
        result.no_clustering = dataclasses.replace(result, config=plain, bootstrap=None)
        result.timings_s["no_clustering"] = 0.0
    result.clustering_effect = clustering_effect(result, result.no_clustering)


def _finish(dataset: Dataset, result: IdentificationResult, t_start: float) -> None:
    result.warnings[:0] = [w for w in dataset.warnings if w not in result.warnings]
    result.excluded_sines = list(dataset.excluded_sines)
    result.data_quality = dataset.quality
    result.experiment = dataset.experiment
    result.quasi_static = dataset.quasi_static
    result.timings_s["total"] = time.perf_counter() - t_start


__all__ = ["REUSED", "identify"]

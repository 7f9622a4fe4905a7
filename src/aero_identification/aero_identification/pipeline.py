"""The identification pipeline: one `identify(dataset, config)` for every source
(docs/design.md §1.2, §7): the identifier node's stream, a bag, CSV and MAT records.

Every stage runs that the data allow:

1. per level, k-means clustering of the periods (the dominant cluster is kept; needs ≥ 3
   periods) and the BLA over the kept periods: the robust method with noise and nonlinear
   distortion levels when the level has M ≥ 2 realizations, the Local Polynomial Method with
   M = 1 (the distortion level then cannot be separated);
2. per level, a linear state-space model of its BLA, at ``config.nx`` or, with nx = 0, at the
   order the subspace order scan selects (1 … ``config.max_order``);
3. one PNLSS model over every estimation level ("all levels"; [PitchingWing] §4.1), started from
   the lowest level's linear model, trained on one mean period per level and training
   realization and choosing its iterate on held-out periods of the same levels
   (`pnlss_sets`); with ``config.scan`` (final identification) the cross-validated structure
   scan chooses its structure; and, when the source plans sines, the paper's "level 1" PNLSS
   trained on the lowest level alone;
4. validation on the single sines (Table 1: relative RMS error rms(y − ŷ)/rms(y − mean y); BLA
   FRF and BLA SS centred on the record's measured means, PNLSS absolute; each cell's ± is the
   std over the sine's periods of the per-period error, `metrics.relative_rms_error_spread`)
   and on held-out levels
   (``held_out``: never used by any fit, so their errors are test errors); with
   ``config.bootstrap`` (final only) each cell's estimation spread, the std over refits on
   bootstrap replicates of the estimation periods (bootstrap.py, `_estimation_bootstrap`);
5. with ``config.clustering_ablation`` (final only), the same pipeline without clustering, and
   what clustering changed (`clustering_effect`).

Models are simulated in periodic steady state (the record's last period is prepended and
dropped), like the measured data.
"""

import dataclasses
import math
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor, wait
from contextlib import contextmanager
from typing import Any

import numpy as np

from . import model_message as msg
from .bla import bla_levels_db, estimate_bla
from .bootstrap import Cell, replicate_spreads, resample_periods
from .clustering import ClusterResult, period_clusters
from .config import IdentificationConfig
from .data import PeriodicData, random_phase_period
from .dataset import Dataset, LevelRecord, SineData
from .metrics import (
    predict_bla_sine,
    relative_rms_error,
    relative_rms_error_spread,
    steady_state_response,
)
from .models import LinearStateSpace, PNLSSModel
from .monomials import structure_exponents
from .pnlss import fit_pnlss, one_blas_thread, output_equation_start
from .results import EstimationSpread, IdentificationResult, LevelResult
from .scan import Candidate, ScanResult, run_fits, scan_pnlss
from .subspace import fit_linear_ss

# Largest Levenberg–Marquardt Jacobian a PNLSS fit may hold (bytes): one (samples × parameters)
# float64 buffer, each iteration about samples × parameters² flops: beyond 1 GB a fit takes hours
# on the 2-core target machine (full degrees 2–5 at nx = 6 on the four F-16 levels: 1.45 GB).
MAX_JACOBIAN_BYTES = 1_000_000_000

# The estimation bootstrap's random draws (bootstrap.py): fixed, so that a fit is reproducible.
BOOTSTRAP_SEED = 20_221_125

Log = Callable[[str], None]

# What a refit that only validates takes over from the previous result (identify's models_from).
REUSED = (
    "levels", "linear_level1", "pnlss_all", "scan", "no_clustering", "pnlss_level1",
    "level1_signature", "pnlss_start_level", "pnlss_held_out",
)  # fmt: skip


def identify(
    dataset: Dataset,
    config: IdentificationConfig | None = None,
    final: bool = False,
    models_from: IdentificationResult | None = None,
    previous: IdentificationResult | None = None,
    client: Any = None,
    held_out: Sequence[str] = (),
    log: Log | None = None,
) -> IdentificationResult:
    """Run every stage the dataset allows (partial results from a partial stream).

    Args:
        dataset: from a source adapter (campaign_dataset, records.read_dataset).
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
    """
    with one_blas_thread():
        return _identify(dataset, config or IdentificationConfig(), final, models_from,
                         previous, client, tuple(held_out), log or (lambda _m: None))  # fmt: skip


def _identify(
    dataset: Dataset,
    config: IdentificationConfig,
    final: bool,
    models_from: IdentificationResult | None,
    previous: IdentificationResult | None,
    client: Any,
    held_out: tuple[str, ...],
    say: Log,
) -> IdentificationResult:
    if final and config.scan and models_from is not None and models_from.scan is None:
        # The final models come from the structure scan, which the online refits skip: the
        # multisine data did not change, but the all-levels PNLSS must still be chosen.
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
    )
    t_start = time.perf_counter()
    if models_from is not None:
        for key in REUSED:
            setattr(result, key, getattr(models_from, key))
        result.levels = dict(result.levels)  # this result's own (the records are replaced)
        # The level records carry this dataset's exclusions (the models are unchanged).
        for lv in dataset.levels:
            if lv.name in result.levels:
                result.levels[lv.name] = dataclasses.replace(result.levels[lv.name], record=lv)
        result.warnings = [w for w in models_from.warnings if not w.startswith("sine ")]
        result.timings_s = {"bla": 0.0, "pnlss": 0.0}
        _validate(dataset, result)
        if final and config.bootstrap > 0:
            _estimation_bootstrap(dataset, result, config, client, say)
        if result.no_clustering is not None:
            result.no_clustering = identify(
                dataset, result.no_clustering.config, final, models_from=result.no_clustering,
                held_out=held_out,
            )  # fmt: skip
            result.clustering_effect = clustering_effect(result, result.no_clustering)
        _finish(dataset, result, t_start)
        return result

    # 1-2. Per level: clustering, BLA, linear model.
    for lv in dataset.levels:
        role = "held out" if lv.name in held_out else "estimation"
        res = LevelResult(lv, role)
        result.levels[lv.name] = res
        if lv.data is None:
            continue
        try:
            _level_models(lv, res, config, result.warnings, say)
        except ValueError as exc:
            result.warnings.append(f"level {lv.name}: {exc}")
    result.timings_s["bla"] = time.perf_counter() - t_start

    # 5 (started here). The clustering ablation, the same pipeline on every valid period, runs
    # in a thread beside steps 3-4: its fits and this one's are independent, and the PNLSS
    # kernels release the GIL, so the final identification uses both cores.
    ablation = _start_ablation(dataset, result, config, final, client, held_out, say)

    try:
        estimation = [r for r in result.levels.values() if r.role == "estimation"]
        low = estimation[0] if estimation else None
        result.linear_level1 = low.linear if low else None

        # 3. PNLSS on every estimation level, its iterate chosen on their held-out periods.
        t0 = time.perf_counter()
        ready = [
            r
            for r in estimation
            if r.record.data is not None and r.bla is not None and r.linear is not None
        ]
        if config.pnlss and low is not None and result.linear_level1 is not None and ready:
            result.pnlss_start_level = low.name
            if final and config.scan:
                result.scan = _scan(ready, result, config, client, say)
                result.pnlss_all = result.scan.best if result.scan is not None else None
            else:
                result.pnlss_all = _fit(ready, result, config, "all levels", say)
            if dataset.sines_planned and ready[0] is low:
                # Level 1 is complete long before the campaign ends: refit its PNLSS only when its
                # kept periods changed.
                signature = _signature(low, config)
                if (
                    previous is not None
                    and previous.pnlss_level1 is not None
                    and previous.level1_signature == signature
                ):
                    result.pnlss_level1 = previous.pnlss_level1
                elif len(ready) == 1:
                    result.pnlss_level1 = result.pnlss_all  # the same data: the same fit
                else:
                    result.pnlss_level1 = _fit([low], result, config, "level 1", say)
                result.level1_signature = signature
        result.timings_s["pnlss"] = time.perf_counter() - t0

        # 4. Validation: single sines, held-out levels; Table 1's estimation spread.
        _validate(dataset, result)
        if final and config.bootstrap > 0:
            _estimation_bootstrap(dataset, result, config, client, say)
    except BaseException:
        if ablation is not None:  # not left running past this call (and its BLAS limit)
            wait([ablation])
        raise

    # 5. The ablation's result (final identification only).
    if final and config.clustering and config.clustering_ablation:
        plain = _ablation_config(config)
        if ablation is not None:
            result.no_clustering, result.timings_s["no_clustering"] = ablation.result()
        elif _clustering_dropped(result):  # it could not run beside (_ablation_beside)
            result.no_clustering, result.timings_s["no_clustering"] = _ablation(
                dataset, plain, client, held_out, say
            )
        else:  # one cluster everywhere: every valid period was used, the same identification
            # (its config has no bootstrap, so neither has it)
            result.no_clustering = dataclasses.replace(result, config=plain, bootstrap=None)
            result.timings_s["no_clustering"] = 0.0
        result.clustering_effect = clustering_effect(result, result.no_clustering)
    _finish(dataset, result, t_start)
    return result


def _start_ablation(
    dataset: Dataset,
    result: IdentificationResult,
    config: IdentificationConfig,
    final: bool,
    client: Any,
    held_out: tuple[str, ...],
    say: Log,
) -> Future[tuple[IdentificationResult, float]] | None:
    """The identification without clustering, started in its own thread once the level models
    say whether clustering dropped any period (None: not asked for, nothing to ablate, or it
    cannot run beside: `_ablation_beside`). Its future gives (result, seconds). The caller
    holds one BLAS thread (`identify`) until it has the result, so both threads' fits run
    with the same BLAS as one after the other would, and give the same numbers."""
    if not (final and config.clustering and config.clustering_ablation):
        return None
    if not _clustering_dropped(result) or not _ablation_beside(config, client):
        return None
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="clustering_ablation")
    future = pool.submit(_ablation, dataset, _ablation_config(config), client, held_out, say)
    pool.shutdown(wait=False)  # the thread ends with its job; the caller waits on the future
    return future


def _ablation_config(config: IdentificationConfig) -> IdentificationConfig:
    """The ablation's configuration: the same pipeline on every valid period, no bootstrap."""
    return dataclasses.replace(config, clustering=False, clustering_ablation=False, bootstrap=0)


def _clustering_dropped(result: IdentificationResult) -> bool:
    return any(lv.clusters is not None and lv.clusters.k > 1 for lv in result.levels.values())


def _ablation(
    dataset: Dataset,
    plain: IdentificationConfig,
    client: Any,
    held_out: tuple[str, ...],
    say: Log,
) -> tuple[IdentificationResult, float]:
    """The same pipeline without clustering, and its seconds; its messages say so."""
    t0 = time.perf_counter()
    done = identify(dataset, plain, final=True, client=client, held_out=held_out,
                    log=lambda message: say(f"no clustering: {message}"))  # fmt: skip
    return done, time.perf_counter() - t0


def _ablation_beside(config: IdentificationConfig, client: Any) -> bool:
    """Whether the ablation may run in a thread beside the clustered fits: numba's threading
    layer must take parallel kernels from two threads at once (tbb or omp: the workqueue
    layer aborts the process), and the fits must not start local Dask clusters (two at once
    would race on ``__main__``, scan._workers_without_main_script, and oversubscribe the
    cores)."""
    local_cluster = client is None and not config.scan_scheduler and config.scan_workers != 1
    if local_cluster and (config.scan or config.bootstrap > 0):
        return False
    import numba

    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel kernel has run in this process yet: load them
        warm_up()
        layer = numba.threading_layer()
    return layer in ("tbb", "omp")


def _finish(dataset: Dataset, result: IdentificationResult, t_start: float) -> None:
    result.warnings[:0] = [w for w in dataset.warnings if w not in result.warnings]
    result.excluded_sines = list(dataset.excluded_sines)
    result.data_quality = dataset.quality
    result.experiment = dataset.experiment
    result.timings_s["total"] = time.perf_counter() - t_start


def _level_models(
    lv: LevelRecord,
    res: LevelResult,
    config: IdentificationConfig,
    warnings: list[str],
    say: Log,
    clusters: ClusterResult | None = None,
    order: int | None = None,
) -> None:
    """Clustering, BLA and (estimation levels) the linear model of one level. ``clusters``,
    ``order``: take these periods and this linear order instead of choosing them (the
    estimation bootstrap's replicates of an estimate)."""
    data = lv.data
    assert data is not None
    t0 = time.perf_counter()
    kept = data
    periods = None  # (P, M) mask of kept's periods where realizations keep different counts
    if config.clustering and data.P * data.M >= 3:
        res.clusters = clusters if clusters is not None else period_clusters(data)
        kept = data.select(res.clusters.keep, min_periods=config.min_periods)
        if kept.M < min(2, data.M):
            warnings.append(
                f"level {lv.name}: the dominant cluster leaves < 2 realizations; "
                "BLA from all valid periods"
            )
            kept = data
        elif kept.M >= 2 and kept.P >= 2:
            # The robust BLA takes every kept period of the retained realizations, P_m each
            # (bla.estimate_bla's periods), not the fewest of every realization.
            retained = np.flatnonzero(np.isin(data.realization_index, kept.realization_index))
            kept = data.select_realizations(retained)
            periods = res.clusters.keep[:, retained]
    res.periods_used = kept.P * kept.M if periods is None else int(periods.sum())
    res.bla = estimate_bla(kept, method="auto", periods=periods)  # robust with M >= 2, else LPM
    if kept.M < 2:
        warnings.append(
            f"level {lv.name}: one realization (M = 1): the nonlinear distortion level cannot "
            "be separated from the BLA (var_total = var_noise, LPM noise estimate)"
        )
    if res.role != "estimation":
        return  # its BLA is for the report only; no model is fitted to held-out data
    order = config.nx if order is None else order
    if order == 0:
        order = fit_linear_ss(res.bla, max_order=config.max_order, refine_fit=False).order
        res.order_scanned = True
    u_kept, y_kept = (
        (kept.u, kept.y) if periods is None else (kept.u[:, periods], kept.y[:, periods])
    )
    res.linear = fit_linear_ss(res.bla, nx=order).with_operating_point(
        float(np.mean(u_kept)), float(np.mean(y_kept))
    )
    say(
        f"level {lv.name}: BLA ({res.bla.method}, M={kept.M}, P={res.bla.periods_text}), "
        f"linear order "
        f"{res.linear.order}{' (scan)' if res.order_scanned else ''}, "
        f"{time.perf_counter() - t0:.1f} s"
    )


# --- PNLSS --------------------------------------------------------------------------------------


def _kept(res: LevelResult, m: int) -> np.ndarray:
    """Positions (within the level's data) of realization m's periods that clustering kept;
    every period without clusters, or when the cluster kept none of this realization."""
    data = res.record.data
    assert data is not None
    cols = np.arange(data.P)
    if res.clusters is None:
        return cols
    keep = res.clusters.keep[:, m]
    return cols[keep] if keep.any() else cols


def validation_realization(data: PeriodicData, config: IdentificationConfig) -> int | None:
    """Which realization holds the PNLSS fit's held-out periods: ``config.
    validation_realization`` (the last one if there are fewer); None with M = 1."""
    if data.M < 2:
        return None
    return min(config.validation_realization, data.M - 1)


def pnlss_sets(
    levels: Sequence[LevelResult], config: IdentificationConfig, fold: int = 0
) -> tuple[PeriodicData, PeriodicData | None, str]:
    """Training and held-out sets of the PNLSS fit, one steady-state mean period per record.

    Training: per level, the mean of the kept periods of every realization except the held-out
    one (one record per level and realization). The input is periodic, so Σ_p ||ŷ − y_p||² =
    P ||ŷ − ȳ||² + const: the same least-squares problem as fitting every period, P times
    cheaper. Held out (chooses the iterate): the mean of the kept periods of realization
    `validation_realization` when M ≥ 2; with M = 1 the last period (independent noise, same
    excitation) and the training mean is over the others; with one period, none.

    ``fold`` k > 0: the structure scan's cross-fit split k (`scan_splits`): the realization k
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
                cols = _kept(res, m)
                target = (uv, yv) if m == val else (us, ys)
                target[0].append(d.u[:, cols, m].mean(axis=1))
                target[1].append(d.y[:, cols, m].mean(axis=1))
        elif d.P >= 2:
            cols = _kept(res, 0)
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
    """How many distinct held-out sets `pnlss_sets` can make: the fewest realizations of any
    level, or of kept periods where a level has one realization."""
    counts = []
    for res in levels:
        d = res.record.data
        assert d is not None
        counts.append(d.M if d.M >= 2 else len(_kept(res, 0)))
    return min(counts, default=1)


def pnlss_parameters(nx: int, degrees: Sequence[int], structure: str, equations: str) -> int:
    """Parameters of a PNLSS model (A, B, E, C, D, F, offset; docs/design.md §7.5)."""
    K = structure_exponents(nx, 1, degrees, structure).shape[0]
    Ke = K if equations == "state+output" else 0
    return nx * nx + nx + nx * K + nx + 1 + Ke + 1


def _jacobian_bytes(data: PeriodicData, n_par: int) -> int:
    return data.N * data.P * data.M * (n_par + 1) * 8


def _fit(
    levels: Sequence[LevelResult],
    result: IdentificationResult,
    config: IdentificationConfig,
    label: str,
    say: Log,
) -> PNLSSModel | None:
    """One PNLSS structure (config.degrees, config.structure), started from the lowest level's
    linear model with its output equation solved by least squares (`output_equation_start`)."""
    data, validation, how = pnlss_sets(levels, config)
    result.pnlss_held_out = how
    lin = result.linear_level1
    assert lin is not None
    n_par = pnlss_parameters(lin.nx, config.degrees, config.structure, "state+output")
    size = _jacobian_bytes(data, n_par)
    if config.max_iter > 0 and size > MAX_JACOBIAN_BYTES:
        result.warnings.append(
            f"PNLSS ({label}) not fitted: nx={lin.nx}, degrees {list(config.degrees)}, structure "
            f"{config.structure!r} has {n_par} parameters; its Jacobian on "
            f"{data.N * data.P * data.M} samples would take {size / 1e9:.1f} GB (limit "
            f"{MAX_JACOBIAN_BYTES / 1e9:g} GB). Choose fewer degrees, structure 'inputsonly' or "
            "'statesonly', or a lower order"
        )
        return None
    t0 = time.perf_counter()
    try:
        weights, val_weights = _set_weights(levels, config, data, validation)
        start = output_equation_start(
            data, lin, degrees=config.degrees, structure=config.structure, validation=validation,
            record_weights=weights, validation_weights=val_weights,
        )  # fmt: skip
        model = fit_pnlss(
            data, lin, degrees=config.degrees, structure=config.structure,
            max_iter=config.max_iter, validation=validation, initial_model=start,
            record_weights=weights, validation_weights=val_weights,
        )  # fmt: skip
    except (ValueError, np.linalg.LinAlgError) as exc:
        result.warnings.append(f"PNLSS ({label}) failed: {exc}")
        return None
    say(f"PNLSS ({label}): {n_par} parameters, {time.perf_counter() - t0:.1f} s")
    return model


def _scan(
    levels: Sequence[LevelResult],
    result: IdentificationResult,
    config: IdentificationConfig,
    client: Any,
    say: Log,
) -> ScanResult | None:
    """The all-levels PNLSS by the cross-validated structure scan (scan.py) on `_fit`'s sets:
    every order of ``config.scan_nx`` (0: the lowest level's linear order) started from the
    lowest level's BLA; candidates whose Jacobian would exceed MAX_JACOBIAN_BYTES are left out
    and named."""
    data, validation, how = pnlss_sets(levels, config)
    result.pnlss_held_out = how
    low = levels[0]
    lin = result.linear_level1
    if validation is None:
        result.warnings.append("PNLSS structure scan: no held-out periods to score candidates")
        return None
    if low.bla is None or lin is None:
        return None
    splits = []
    for fold in range(1, min(config.scan_splits, scan_split_count(levels))):
        train_k, held_k, _ = pnlss_sets(levels, config, fold)
        assert held_k is not None  # every level has a held-out set (checked above) in any fold
        splits.append((train_k, held_k))
    orders = sorted({lin.nx if n == 0 else n for n in config.scan_nx})
    degree_sets = sorted({tuple(d) for d in config.scan_degrees}, key=lambda d: (len(d), d))
    equations = tuple(config.scan_equations)

    def over(n: int, d: tuple[int, ...], eq: str) -> bool:
        n_par = pnlss_parameters(n, d, config.structure, eq)
        return _jacobian_bytes(data, n_par) > MAX_JACOBIAN_BYTES

    # The scan fits the whole grid nx × degrees × equations: drop the largest degree sets,
    # then the highest orders, until no candidate is over the limit.
    while (
        degree_sets
        and orders
        and any(over(n, d, eq) for n in orders for d in degree_sets for eq in equations)
    ):
        dropped = degree_sets.pop() if len(degree_sets) > 1 else None
        if dropped is None:
            result.warnings.append(
                f"scan order nx {orders[-1]} left out: even degrees {list(degree_sets[0])} are "
                f"over the {MAX_JACOBIAN_BYTES / 1e9:g} GB Jacobian limit"
            )
            orders.pop()
        else:
            result.warnings.append(
                f"scan degrees {list(dropped)} left out: over the "
                f"{MAX_JACOBIAN_BYTES / 1e9:g} GB Jacobian limit at nx {orders[-1]}"
            )
    if not orders or not degree_sets:
        result.warnings.append("PNLSS structure scan: every candidate is over the Jacobian limit")
        return None
    degree_sets = [d for d in (tuple(x) for x in config.scan_degrees) if d in degree_sets]
    u0, y0 = float(lin.u_mean[0]), float(lin.y_mean[0])
    try:
        linear = {
            n: (lin if n == lin.nx and 0 in config.scan_nx else
                fit_linear_ss(low.bla, nx=n).with_operating_point(u0, y0))
            for n in orders
        }  # fmt: skip
        weights, val_weights = _set_weights(levels, config, data, validation)
        t0 = time.perf_counter()
        with fit_client(config, client) as executor:
            scan = scan_pnlss(
                data,
                validation,
                nx=tuple(orders),
                degrees=tuple(degree_sets),
                equations=equations,
                structures=(config.structure,),
                max_iter=config.scan_max_iter,
                client=executor,
                linear=linear,
                workers=config.scan_workers or None,
                record_weights=weights,
                validation_weights=val_weights,
                starts=("linear", "output_ls"),  # the latter: the single-structure fit's start
                stress=config.scan_stress or None,
                splits=splits,
            )
        say(
            f"PNLSS structure scan: {len(scan.rows)} candidates × {1 + len(splits)} split(s), "
            f"{time.perf_counter() - t0:.1f} s"
        )
        return scan
    except (ValueError, OSError) as exc:  # OSError: the Dask scheduler cannot be reached
        result.warnings.append(f"PNLSS structure scan failed: {exc}")
        return None


def _relative_weights(data: PeriodicData) -> np.ndarray:
    """1 / var(each record's output) (level_weighting "relative"); record r = m·P + p."""
    var = np.var(data.y, axis=0).T.reshape(-1)
    if not np.all(var > 0):
        raise ValueError("a level's output is constant: relative weighting is undefined")
    return 1.0 / var


def noise_variance(res: LevelResult) -> float:
    """Noise variance of the level's mean period: the sample variance over the kept periods
    of each realization (ddof 1), averaged over time and divided by the number of periods
    averaged (the mean of P periods has variance σ²/P), then averaged over the realizations.
    The stall's cycle-to-cycle scatter counts as noise here: no periodic model predicts it."""
    data = res.record.data
    assert data is not None
    per_realization = []
    for m in range(data.M):
        cols = _kept(res, m)
        if len(cols) >= 2:
            var = np.var(data.y[:, cols, m], axis=1, ddof=1).mean()
            per_realization.append(var / len(cols))
    if not per_realization:
        raise ValueError(
            f"level {res.record.name}: level_weighting 'noise' needs two kept periods of a "
            "realization to estimate the noise; use 'none' or 'relative'"
        )
    var = float(np.mean(per_realization))
    if not var > 0:
        raise ValueError(f"level {res.record.name}: the output repeats exactly, noise variance 0")
    return var


def _set_weights(
    levels: Sequence[LevelResult],
    config: IdentificationConfig,
    data: PeriodicData,
    validation: PeriodicData | None,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Record weights of `pnlss_sets`' training and held-out sets (config.level_weighting).

    "noise": each level's records by 1 / the noise variance of its mean period
    (`noise_variance`), the weighted least squares that is the maximum-likelihood output-error
    estimator under Gaussian noise of level-dependent variance [Pintelon2012]
    [Paduart2010: the PNLSS cost weighted by the inverse noise variance]. The records follow
    `pnlss_sets`' order: per level, its training realizations (or its one training mean)."""
    weighting = config.level_weighting
    if weighting == "none":
        return None, None
    if weighting == "relative":
        return _relative_weights(data), (_relative_weights(validation) if validation else None)
    if weighting != "noise":
        raise ValueError(
            f"level_weighting must be 'none', 'relative' or 'noise'; got {weighting!r}"
        )
    w = np.array([1.0 / noise_variance(res) for res in levels])
    counts = []
    for res in levels:
        d = res.record.data
        assert d is not None
        counts.append(d.M - 1 if validation_realization(d, config) is not None else 1)
    train = np.repeat(w, counts)
    if train.size != data.y.shape[2]:  # pnlss_sets' record order changed: fail loudly
        raise ValueError(f"noise weighting: {train.size} weights for {data.y.shape[2]} records")
    return train, (w if validation is not None else None)


def _signature(res: LevelResult, config: IdentificationConfig) -> bytes:
    """The periods a level's PNLSS fit would use, as bytes."""
    data = res.record.data
    assert data is not None
    parts = []
    for m in range(data.M):
        cols = _kept(res, m)
        parts.append(
            cols.astype(np.int64).tobytes()
            + data.period_index[cols, m].astype(np.int64).tobytes()
            + data.u[:, cols, m].tobytes()
            + data.y[:, cols, m].tobytes()
        )
    return b"|".join(parts)


# --- validation ---------------------------------------------------------------------------------


def _validate(dataset: Dataset, result: IdentificationResult) -> None:
    result.errors_all.clear()
    result.errors_level1.clear()
    result.spreads_all.clear()
    result.spreads_level1.clear()
    result.predictions.clear()
    for rec in dataset.sines:
        _validate_sine(rec, result)
    result.held_out_errors = _held_out_errors(result)


def _nearest(levels: Sequence[LevelResult], offset: float | None, rms: float) -> LevelResult:
    """The level nearest an operating point (by plan offset when known, else by input RMS)."""
    if offset is not None and all(lv.record.offset_deg is not None for lv in levels):
        return min(levels, key=lambda lv: abs(lv.offset_deg - offset))
    return min(levels, key=lambda lv: abs(lv.record.input_rms - rms))


def _validate_sine(rec: SineData, result: IdentificationResult) -> None:
    estimation = [lv for lv in result.levels.values() if lv.role == "estimation"]
    if not estimation:
        return
    own = _nearest(estimation, rec.offset_deg, float(np.std(rec.u)))
    low = estimation[0]
    name = own.name
    f = round(rec.frequency_hz, 6)
    y_mean, u_mean = float(np.mean(rec.y)), float(np.mean(rec.u))
    preds: dict[str, np.ndarray] = {}

    def score(
        errors: dict[tuple[str, str, float], float],
        spreads: dict[tuple[str, str, float], float],
        model_name: str,
        y_hat: np.ndarray,
        may_diverge: bool = False,
    ) -> None:
        """Table 1's cell (error over all periods) and its ± (std of the per-period errors)."""
        cell = (model_name, name, f)
        if may_diverge and not np.all(np.isfinite(y_hat)):  # a diverged PNLSS simulation
            errors[cell], spreads[cell] = float("inf"), float("nan")
            return
        errors[cell] = relative_rms_error(rec.y, y_hat)
        spreads[cell] = relative_rms_error_spread(rec.y, y_hat, rec.samples_per_period)

    # Linear models predict deviations: centred on the record's measured means.
    for lin_level, errors, spreads, key in (
        (own, result.errors_all, result.spreads_all, msg.BLA_SS_OWN),
        (low, result.errors_level1, result.spreads_level1, msg.BLA_SS_LEVEL1),
    ):
        if lin_level.bla is None or lin_level.linear is None:
            continue
        y_frf = predict_bla_sine(lin_level.bla, rec.frequency_hz, rec.u, y_mean)
        score(errors, spreads, "BLA FRF", y_frf)
        lin = lin_level.linear.with_operating_point(u_mean, y_mean)
        y_ss = steady_state_response(lin, rec.u, rec.samples_per_period)
        score(errors, spreads, "BLA SS", y_ss)
        preds[key] = y_ss
    for model, errors, spreads, key in (
        (result.pnlss_all, result.errors_all, result.spreads_all, msg.PNLSS_ALL),
        (result.pnlss_level1, result.errors_level1, result.spreads_level1, msg.PNLSS_LEVEL1),
    ):
        if model is None:
            continue
        y_hat = steady_state_response(model, rec.u, rec.samples_per_period)
        score(errors, spreads, "PNLSS", y_hat, may_diverge=True)
        preds[key] = y_hat
    result.predictions.append(
        {
            msg.NAME: f"sine {name} {rec.frequency_hz:g} Hz",
            msg.LEVEL: name,
            msg.FREQUENCY_HZ: rec.frequency_hz,
            msg.SAMPLES_PER_PERIOD: rec.samples_per_period,
            msg.ALPHA_DEG: rec.u.tolist(),
            msg.series_key(msg.MEASURED): rec.y.tolist(),
            **{msg.series_key(k): v.tolist() for k, v in preds.items()},
        }
    )


def record_error(model: Any, data: PeriodicData, centred: bool) -> float:
    """Relative RMS error over every realization's periods (steady-state simulation). Linear
    models map deviations: with ``centred`` they are put at the record's means."""
    num, den = 0.0, 0.0
    for m in range(data.M):
        u = data.u[:, :, m].T.reshape(-1)
        y = data.y[:, :, m].T.reshape(-1)
        mod = model.with_operating_point(u.mean(), y.mean()) if centred else model
        y_hat = steady_state_response(mod, u, data.N)
        if not np.all(np.isfinite(y_hat)):
            return math.inf
        e = relative_rms_error(y, y_hat)
        spread2 = float(np.mean((y - y.mean()) ** 2))
        num += e * e * spread2
        den += spread2
    return math.sqrt(num / den)


def _held_out_errors(result: IdentificationResult) -> list[dict[str, Any]]:
    """Errors of the linear models (nearest and lowest estimation level) and of the all-levels
    PNLSS on every held-out level's periods."""
    estimation = [
        lv for lv in result.levels.values() if lv.role == "estimation" and lv.linear is not None
    ]
    rows: list[dict[str, Any]] = []
    for lv in result.levels.values():
        data = lv.record.data
        if lv.role != "held out" or data is None or not estimation:
            continue
        nearest = _nearest(estimation, lv.record.offset_deg, lv.record.input_rms)
        rows.append(
            {
                "level": lv.name,
                "input_rms": lv.record.input_rms,
                "nearest_estimation_level": nearest.name,
                "linear_nearest": record_error(nearest.linear, data, centred=True),
                "linear_lowest": record_error(estimation[0].linear, data, centred=True),
                "pnlss": None
                if result.pnlss_all is None
                else record_error(result.pnlss_all, data, centred=False),
            }
        )
    return rows


# --- Table 1's estimation spread -----------------------------------------------------------------


def _refit_candidates(
    result: IdentificationResult, config: IdentificationConfig
) -> tuple[tuple[Candidate, int, float | None] | None, tuple[Candidate, int, float | None] | None]:
    """The structures (candidate, LM iterations, stress scale) the estimate's all-levels and
    level-1 PNLSS were fitted with: the scan's kept candidate, or `_fit`'s single structure."""
    lin = result.linear_level1
    if lin is None:
        return None, None
    single = (
        Candidate(lin.nx, tuple(config.degrees), "state+output", config.structure, "output_ls"),
        config.max_iter,
        None,
    )
    every: tuple[Candidate, int, float | None] | None = None
    if result.scan is not None and result.pnlss_all is not None:
        row = result.scan.best_row
        cand = Candidate(row.nx, tuple(row.degrees), row.equations, row.structure, row.start)
        every = (cand, config.scan_max_iter, config.scan_stress or None)
    elif result.pnlss_all is not None:
        every = single
    return every, (single if result.pnlss_level1 is not None else None)


def _refit_job(
    levels: Sequence[LevelResult],
    how: tuple[Candidate, int, float | None],
    config: IdentificationConfig,
) -> tuple[Candidate, LinearStateSpace, tuple[PeriodicData, PeriodicData], dict[str, Any]] | None:
    """One PNLSS fit of a given structure on `pnlss_sets(levels)`, from the lowest level's
    linear model (at the candidate's order, as the scan starts it), as a job for
    `scan.run_fits`: the candidate, its start, its (training, held-out) sets and options; None
    when there are no held-out periods (the scan could not have scored it)."""
    cand, max_iter, stress = how
    data, validation, _ = pnlss_sets(levels, config)
    if validation is None:
        return None
    low = levels[0]
    assert low.linear is not None and low.bla is not None
    lin = low.linear
    if cand.nx != lin.nx:
        u0, y0 = float(lin.u_mean[0]), float(lin.y_mean[0])
        lin = fit_linear_ss(low.bla, nx=cand.nx).with_operating_point(u0, y0)
    weights, val_weights = _set_weights(levels, config, data, validation)
    options = {
        "max_iter": max_iter,
        "record_weights": weights,
        "validation_weights": val_weights,
        "stress": stress,
    }
    return cand, lin, (data, validation), options


SCHEDULER_CONNECT_S = 30.0  # how long a scan or bootstrap tries to reach scan_scheduler


@contextmanager
def fit_client(config: IdentificationConfig, client: Any) -> Iterator[Any]:
    """The Dask client the scan's and the bootstrap's fits run on: identify's ``client``, else
    one of the scheduler at ``config.scan_scheduler`` for the duration (OSError if it cannot be
    reached within SCHEDULER_CONNECT_S), else None (scan.run_fits: ``scan_workers`` local
    processes or this one)."""
    if client is not None or not config.scan_scheduler:
        yield client
        return
    from dask.distributed import Client

    with Client(config.scan_scheduler, timeout=f"{SCHEDULER_CONNECT_S:g}s") as remote:
        yield remote


def _run_refits(
    wanted: list[tuple[Candidate, LinearStateSpace, tuple[PeriodicData, PeriodicData], Any]],
    config: IdentificationConfig,
    client: Any,
) -> tuple[list[PNLSSModel | None], str]:
    """The refits' models (None where a fit failed, diverged or failed the scan's check: the
    scan would not have kept it), on the scan's executor: ``client`` (identify's), the Dask
    scheduler at ``scan_scheduler``, local worker processes (``scan_workers``) or this
    process."""
    if not wanted:
        return [], "no refit"
    jobs = [(cand, lin, k, options) for k, (cand, lin, _, options) in enumerate(wanted)]
    sets = [pair for _, _, pair, _ in wanted]
    with fit_client(config, client) as executor:
        fits, where = run_fits(jobs, sets, executor, workers=config.scan_workers or None)
    return [model if row.status == "ok" else None for row, model in fits], where


def _estimation_bootstrap(
    dataset: Dataset,
    result: IdentificationResult,
    config: IdentificationConfig,
    client: Any,
    say: Log,
) -> None:
    """Table 1's estimation spread (bootstrap.py): ``config.bootstrap`` replicates, each with
    every estimation level's kept periods drawn with replacement within each realization, the
    level's BLA and linear model refitted at the estimate's order on the estimate's clusters,
    the all-levels and level-1 PNLSS refitted with the estimate's structures, and Table 1
    scored; each cell's spread is the std over the replicates (fixed seed: reproducible).
    The replicates are drawn and their linear models fitted here, in order; their PNLSS refits,
    the cost, are independent fits and run on the scan's executor (`_run_refits`). With
    ``config.bootstrap_scan`` and a scanned estimate, each replicate's all-levels PNLSS comes
    from its own structure scan instead (`_scan`, one after another, each on the executor), so
    that the spread includes the selection (Efron 2014, see config.py)."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    every, level1 = _refit_candidates(result, config)
    # bootstrap_scan: the estimate's kept structure, against which the replicates' are counted.
    kept = result.scan.best_row.structure_label if result.scan is not None else ""
    rescan = config.bootstrap_scan and bool(kept)
    structures: list[str] = []  # what each replicate's scan kept (rescan)
    if config.bootstrap_scan and not rescan:
        result.warnings.append(
            "bootstrap_scan: the all-levels PNLSS was not chosen by a structure scan (scan off "
            "or failed), so the replicates refit its one structure"
        )
    # One structure for both tables: the level-1 PNLSS is the all-levels one, not refitted.
    same = level1 is not None and result.pnlss_level1 is result.pnlss_all and every == level1
    quiet: Log = lambda _m: None  # noqa: E731
    replicates: list[IdentificationResult] = []
    wanted: list[Any] = []  # the refit jobs of every replicate
    slots: list[tuple[IdentificationResult, str]] = []  # where each job's model goes
    for _ in range(config.bootstrap):
        rep = IdentificationResult(config=config, fs=result.fs, sines_planned=result.sines_planned)
        replicates.append(rep)
        for name, res in result.levels.items():
            data = res.record.data
            if res.role != "estimation" or data is None or res.linear is None:
                rep.levels[name] = res
                continue
            keep = None if res.clusters is None else res.clusters.keep
            record = dataclasses.replace(res.record, data=resample_periods(data, keep, rng))
            res_b = LevelResult(record, res.role)
            rep.levels[name] = res_b
            try:
                _level_models(
                    record, res_b, config, [], quiet, clusters=res.clusters, order=res.linear.order
                )
            except (ValueError, np.linalg.LinAlgError):
                res_b.linear = None  # this replicate has no model of the level: its cells fail
        estimation = [r for r in rep.levels.values() if r.role == "estimation"]
        ready = [r for r in estimation if r.bla is not None and r.linear is not None]
        rep.linear_level1 = estimation[0].linear if estimation else None
        if not ready or ready[0] is not estimation[0]:
            if rescan:
                structures.append("")
            continue
        if rescan:
            scan = _scan(ready, rep, config, client, quiet)
            rep.pnlss_all = None if scan is None else scan.best
            structures.append("" if scan is None else scan.best_row.structure_label)
            result.warnings.extend(
                f"bootstrap replicate {len(replicates)}: {w}" for w in rep.warnings
            )
        for how, levels, slot in (
            (None if rescan else every, ready, "pnlss_all"),
            (None if same else level1, ready[:1], "pnlss_level1"),
        ):
            job = None if how is None else _refit_job(levels, how, config)
            if job is not None:
                wanted.append(job)
                slots.append((rep, slot))
    try:
        models, where = _run_refits(wanted, config, client)
    except OSError as exc:  # the Dask scheduler cannot be reached: Table 1 without spreads
        result.warnings.append(f"Table 1 estimation bootstrap failed: {exc}")
        return
    for (rep, slot), fitted in zip(slots, models, strict=True):
        setattr(rep, slot, fitted)
    replicates_all: list[dict[Cell, float]] = []
    replicates_level1: list[dict[Cell, float]] = []
    for rep in replicates:
        if same:
            rep.pnlss_level1 = rep.pnlss_all
        _validate(dataset, rep)
        replicates_all.append(dict(rep.errors_all))
        replicates_level1.append(dict(rep.errors_level1))
    spreads_all, means_all, failed_all = replicate_spreads(replicates_all, list(result.errors_all))
    spreads_level1, means_level1, failed_level1 = replicate_spreads(
        replicates_level1, list(result.errors_level1)
    )
    result.bootstrap = EstimationSpread(
        replicates=config.bootstrap,
        spreads_all=spreads_all,
        spreads_level1=spreads_level1,
        means_all=means_all,
        means_level1=means_level1,
        failed_all=failed_all,
        failed_level1=failed_level1,
        seconds=time.perf_counter() - t0,
        kept_structure=kept if rescan else "",
        replicate_structures=structures,
    )
    for table, failed in (("all levels", failed_all), ("level 1", failed_level1)):
        for (model, level, f), n in failed.items():
            if n:
                result.warnings.append(
                    f"bootstrap ({table}): {model} at {level} {f:g} Hz: the refit failed, "
                    f"diverged or was rejected by the scan's checks in {n} of "
                    f"{config.bootstrap} replicates (its estimation spread is over the rest)"
                )
    result.timings_s["bootstrap"] = result.bootstrap.seconds
    scans = (
        f", {len(structures)} structure scans (the estimate's structure kept in "
        f"{result.bootstrap.same_structure})"
        if rescan
        else ""
    )
    say(
        f"Table 1 estimation bootstrap: {config.bootstrap} replicates{scans}, {len(wanted)} "
        f"PNLSS refits ({where}), {result.bootstrap.seconds:.1f} s"
    )


# --- the ablation -------------------------------------------------------------------------------


def clustering_effect(
    clustered: IdentificationResult, plain: IdentificationResult
) -> dict[str, Any]:
    """What clustering changed, per level: clusters, periods used, the BLA's levels
    (bla.bla_levels_db: SNR and SNLR near 1.02 Hz, distortion levels) and mean variances, and
    the all-levels PNLSS error on the validation realization's dominant-cluster periods (one
    steady-state mean period; both models scored on the same periods)."""
    cfg = clustered.config
    effect: dict[str, Any] = {}
    for name, lv in clustered.levels.items():
        other = plain.levels.get(name)
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
        # The PNLSS fit's own held-out record of this level: its kept periods' mean.
        data = lv.record.data
        if lv.bla is not None and lv.role == "estimation" and data is not None:
            _, held, _ = pnlss_sets([lv], cfg)
            if held is not None:
                u, y = held.u[:, 0, 0], held.y[:, 0, 0]
                for tag, model in (("with", clustered.pnlss_all), ("without", plain.pnlss_all)):
                    if model is None:
                        continue
                    y_hat = steady_state_response(model, u, u.size)
                    entry[f"pnlss_validation_{tag}"] = (
                        relative_rms_error(y, y_hat) if np.all(np.isfinite(y_hat)) else None
                    )
                val = validation_realization(data, cfg)
                entry["validation_periods"] = len(_kept(lv, val)) if val is not None else 1
        effect[name] = entry
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


__all__ = [
    "MAX_JACOBIAN_BYTES",
    "IdentificationConfig",
    "IdentificationResult",
    "LevelResult",
    "LinearStateSpace",
    "clustering_effect",
    "identify",
    "pnlss_parameters",
    "pnlss_sets",
    "warm_up",
]

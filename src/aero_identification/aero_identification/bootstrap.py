"""Table 1's estimation spread: a bootstrap over the estimation periods (docs/design.md §7.7).

Table 1's ± (`metrics.relative_rms_error_spread`) is the scatter of a fixed model's error over
the sine's periods. It says nothing about the model: had the multisine periods come out
otherwise (measurement noise, dynamic stall's cycle-to-cycle variation), the fitted models
and so every cell would differ. The nonparametric bootstrap estimates that scatter by refitting
on resampled data (Efron & Tibshirani 1993, *An Introduction to the Bootstrap*, §6.2: the
bootstrap estimate of a standard error is the sample standard deviation over B replicates).

The resampling unit is the steady-state period. Under a periodic excitation the periods of one
realization share the input and differ by the noise and the plant's period-to-period variation,
which are independent from period to period (Pintelon & Schoukens 2012, §2.4 and §4.3.1, the
same assumption the robust BLA's noise estimate makes), so periods are drawn with replacement
within each realization and among the periods the clustering kept. The realizations (random
phases) stay as measured: with M = 2 per level, resampling them would repeat one realization
half of the time and leave the nonlinear distortion inseparable.

What is not resampled: which periods the clustering keeps, and by default which PNLSS
structure the scan keeps (each replicate refits the kept structure from its own start). With
``config.bootstrap_scan`` every replicate reruns the scan, at the scan's time B times, so that
the spread includes the selection (Efron 2014, "Estimation and accuracy after model selection",
JASA 109(507)). Either way the spread is a lower bound on the run-to-run scatter.

`resample_periods` and `replicate_spreads` are the numerical pieces; `estimation_bootstrap`
runs the replicates for `pipeline.identify` (``config.bootstrap``).
"""

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .beddoes_leishman import BeddoesLeishman, fit_beddoes_leishman
from .bspline_lpv import BSplineLPV, LpvSettings, fit_bspline_lpv
from .dataset import Dataset, QuasiStaticSweep
from .estimation_sets import EstimationSets, ready_levels
from .hyperparameters import IdentificationConfig
from .identification_result import EstimationSpread, IdentificationResult, LevelResult, Log
from .level_identification import level_models
from .periodic_data import PeriodicData
from .pnlss_training import fit_client, level_weights, scan_levels
from .scan import Candidate, run_fits
from .state_space_models import LinearStateSpace, PNLSSModel
from .subspace import fit_linear_ss
from .validation import validate

Cell = tuple[str, str, float]  # (model, level, frequency [Hz]), Table 1's keys

__all__ = [
    "BOOTSTRAP_SEED",
    "Cell",
    "estimation_bootstrap",
    "refit_candidates",
    "replicate_spreads",
    "resample_periods",
]


def resample_periods(
    data: PeriodicData, keep: np.ndarray | None, rng: np.random.Generator
) -> PeriodicData:
    """One bootstrap replicate of a level's periods: in each realization, its kept periods
    (``keep[:, m]``, every period without a mask or where the mask keeps none) are replaced by
    as many draws with replacement from them; the other periods stay as they are (no fit uses
    them). A draw that repeats one period in every place is drawn again, so that a realization
    with ≥ 2 periods keeps a noise estimate (the robust BLA's σ²_n would be 0)."""
    if keep is not None and keep.shape != (data.P, data.M):
        raise ValueError(
            f"keep mask {keep.shape} does not match the data's (P, M) {data.P, data.M}"
        )
    u, y = data.u.copy(), data.y.copy()
    for m in range(data.M):
        cols = np.arange(data.P)
        if keep is not None and keep[:, m].any():
            cols = cols[keep[:, m]]
        draw = rng.choice(cols, size=cols.size, replace=True)
        while cols.size >= 2 and np.all(draw == draw[0]):
            draw = rng.choice(cols, size=cols.size, replace=True)
        u[:, cols, m] = data.u[:, draw, m]
        y[:, cols, m] = data.y[:, draw, m]
    return PeriodicData(
        u=u,
        y=y,
        fs=data.fs,
        excited_lines=data.excited_lines,
        period_index=data.period_index,
        realization_index=data.realization_index,
    )


def replicate_spreads(
    replicates: Sequence[Mapping[Cell, float]], cells: Sequence[Cell]
) -> tuple[dict[Cell, float], dict[Cell, float], dict[Cell, int]]:
    """Per cell, over the replicates whose model gave a finite error: the bootstrap standard
    error (sample std, ddof 1) and the replicates' mean; and how many replicates did not give
    one (a model that failed to fit, or diverged on the sine). The mean minus the estimate's
    error is the bootstrap estimate of the estimate's bias (Efron & Tibshirani 1993, §10.2):
    it says whether the estimate's cell is typical of the procedure on other draws of the
    periods. Fewer than two finite values: NaN std (and NaN mean without one)."""
    spreads: dict[Cell, float] = {}
    means: dict[Cell, float] = {}
    failed: dict[Cell, int] = {}
    for cell in cells:
        values = [r.get(cell, math.nan) for r in replicates]
        finite = np.array([v for v in values if math.isfinite(v)])
        failed[cell] = len(values) - finite.size
        spreads[cell] = float(np.std(finite, ddof=1)) if finite.size >= 2 else math.nan
        means[cell] = float(np.mean(finite)) if finite.size else math.nan
    return spreads, means, failed


# The replicates' random draws: fixed, so that a fit is reproducible.
BOOTSTRAP_SEED = 20_221_125


def refit_candidates(
    result: IdentificationResult, config: IdentificationConfig
) -> tuple[tuple[Candidate, int, float | None] | None, tuple[Candidate, int, float | None] | None]:
    """The structures (candidate, LM iterations, stress scale) the estimate's all-levels and
    level-1 PNLSS were fitted with: the scan's kept candidate, or `fit_levels`' one structure."""
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


def refit_job(
    sets: EstimationSets,
    how: tuple[Candidate, int, float | None],
    config: IdentificationConfig,
) -> tuple[Candidate, LinearStateSpace, tuple[PeriodicData, PeriodicData], dict[str, Any]] | None:
    """One PNLSS fit of a given structure on the estimation sets, from the lowest level's
    linear model (at the candidate's order, as the scan starts it), as a job for
    `scan.run_fits`: the candidate, its start, its (training, held-out) sets and options; None
    when there are no held-out periods (the scan could not have scored it)."""
    cand, max_iter, stress = how
    data, validation = sets.train, sets.held
    if validation is None:
        return None
    low = sets.levels[0]
    assert low.linear is not None and low.bla is not None
    lin = low.linear
    if cand.nx != lin.nx:
        u0, y0 = float(lin.u_mean[0]), float(lin.y_mean[0])
        lin = fit_linear_ss(low.bla, nx=cand.nx).with_operating_point(u0, y0)
    weights, val_weights = level_weights(sets.levels, config, data, validation)
    options = {
        "max_iter": max_iter,
        "record_weights": weights,
        "validation_weights": val_weights,
        "stress": stress,
    }
    return cand, lin, (data, validation), options


def run_refits(
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


def estimation_bootstrap(
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
    the cost, are independent fits and run on the scan's executor (`run_refits`). With
    ``config.bootstrap_scan`` and a scanned estimate, each replicate's all-levels PNLSS comes
    from its own structure scan instead (`scan_levels`, one after another, each on the
    executor), so that the spread includes the selection (Efron 2014, see hyperparameters.py)."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    every, level1 = refit_candidates(result, config)
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
    replicates: list[IdentificationResult] = []
    replicate_sets: list[EstimationSets | None] = []  # each replicate's, built once
    wanted: list[Any] = []  # the refit jobs of every replicate
    slots: list[tuple[IdentificationResult, str]] = []  # where each job's model goes
    for _ in range(config.bootstrap):
        rep = _draw_replicate(result, config, rng)
        replicates.append(rep)
        estimation = [r for r in rep.levels.values() if r.role == "estimation"]
        ready = ready_levels(rep)
        if not ready or ready[0] is not estimation[0]:
            replicate_sets.append(None)
            if rescan:
                structures.append("")
            continue
        sets = EstimationSets.of(ready, config)
        replicate_sets.append(sets)
        if rescan:
            scan = scan_levels(sets, rep, config, client, lambda _m: None)
            rep.pnlss_all = None if scan is None else scan.best
            structures.append("" if scan is None else scan.best_row.structure_label)
            result.warnings.extend(
                f"bootstrap replicate {len(replicates)}: {w}" for w in rep.warnings
            )
        jobs = []
        if every is not None and not rescan:
            jobs.append((refit_job(sets, every, config), "pnlss_all"))
        if level1 is not None and not same:
            level1_sets = EstimationSets.of(ready[:1], config)
            jobs.append((refit_job(level1_sets, level1, config), "pnlss_level1"))
        for job, slot in jobs:
            if job is not None:
                wanted.append(job)
                slots.append((rep, slot))
    try:
        models, where = run_refits(wanted, config, client)
    except OSError as exc:  # the Dask scheduler cannot be reached: Table 1 without spreads
        result.warnings.append(f"Table 1 estimation bootstrap failed: {exc}")
        return
    for (rep, slot), fitted in zip(slots, models, strict=True):
        setattr(rep, slot, fitted)
    spread = _estimation_spread(dataset, result, replicates, replicate_sets, same)
    result.bootstrap = dataclasses.replace(
        spread,
        seconds=time.perf_counter() - t0,
        kept_structure=kept if rescan else "",
        replicate_structures=structures,
    )
    _warn_failed_refits(result, config.bootstrap)
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


def _draw_replicate(
    result: IdentificationResult, config: IdentificationConfig, rng: np.random.Generator
) -> IdentificationResult:
    """One bootstrap replicate of the estimate: every estimation level's kept periods drawn
    with replacement (`resample_periods`, in the levels' order), its BLA and linear model
    refitted at the estimate's order on the estimate's clusters; no PNLSS yet."""
    rep = IdentificationResult(config=config, fs=result.fs, sines_planned=result.sines_planned)
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
            level_models(
                record, res_b, config, [], lambda _m: None, clusters=res.clusters,
                order=res.linear.order,
            )  # fmt: skip
        except (ValueError, np.linalg.LinAlgError):
            res_b.linear = None  # this replicate has no model of the level: its cells fail
    estimation = [r for r in rep.levels.values() if r.role == "estimation"]
    rep.linear_level1 = estimation[0].linear if estimation else None
    return rep


def _estimation_spread(
    dataset: Dataset,
    result: IdentificationResult,
    replicates: Sequence[IdentificationResult],
    replicate_sets: Sequence[EstimationSets | None],
    same: bool,
) -> EstimationSpread:
    """Table 1 scored on every replicate (with its refitted PNLSS) and each cell's spread."""
    replicates_all: list[dict[Cell, float]] = []
    replicates_level1: list[dict[Cell, float]] = []
    for rep, sets in zip(replicates, replicate_sets, strict=True):
        if same:
            rep.pnlss_level1 = rep.pnlss_all
        if sets is not None and result.beddoes_leishman is not None and dataset.quasi_static:
            rep.beddoes_leishman = _refit_semi_empirical(dataset.quasi_static, sets)
        if sets is not None and result.lpv_all is not None:
            rep.lpv_all = _refit_lpv(result.lpv_all, rep, sets)
        rep.selection = result.selection  # the estimate's class, as its structure is kept
        validate(dataset, rep)
        replicates_all.append(dict(rep.errors_all))
        replicates_level1.append(dict(rep.errors_level1))
    spreads_all, means_all, failed_all = replicate_spreads(replicates_all, list(result.errors_all))
    spreads_level1, means_level1, failed_level1 = replicate_spreads(
        replicates_level1, list(result.errors_level1)
    )
    return EstimationSpread(
        replicates=len(replicates),
        spreads_all=spreads_all,
        spreads_level1=spreads_level1,
        means_all=means_all,
        means_level1=means_level1,
        failed_all=failed_all,
        failed_level1=failed_level1,
    )


def _refit_semi_empirical(sweep: QuasiStaticSweep, sets: EstimationSets) -> BeddoesLeishman | None:
    """The Beddoes–Leishman baseline refitted on a replicate's estimation sets (the sweep is
    not resampled: it calibrates the static curves); None where the fit fails (its cells then
    count as failed)."""
    try:
        return fit_beddoes_leishman(sweep, sets.train, sets.held)
    except ValueError:
        return None


def _refit_lpv(
    kept: BSplineLPV, rep: IdentificationResult, sets: EstimationSets
) -> BSplineLPV | None:
    """The B-spline LPV model refitted on a replicate's estimation sets with the estimate's
    structure (knot intervals, state degree); None where the fit fails (its cells then count
    as failed)."""
    config = rep.config
    settings = LpvSettings(
        intervals=kept.intervals, state_degree=kept.state_degree, max_iter=config.lpv_max_iter,
        weighting=config.lpv_weighting, stress=config.scan_stress,
    )  # fmt: skip
    if rep.linear_level1 is None:
        return None
    try:
        return fit_bspline_lpv(sets.train, rep.linear_level1, settings, sets.held)
    except (ValueError, np.linalg.LinAlgError):
        return None


def _warn_failed_refits(result: IdentificationResult, replicates: int) -> None:
    assert result.bootstrap is not None
    for table, failed in (
        ("all levels", result.bootstrap.failed_all),
        ("level 1", result.bootstrap.failed_level1),
    ):
        for (model, level, f), n in failed.items():
            if n:
                result.warnings.append(
                    f"bootstrap ({table}): {model} at {level} {f:g} Hz: the refit failed, "
                    f"diverged or was rejected by the scan's checks in {n} of "
                    f"{replicates} replicates (its estimation spread is over the rest)"
                )

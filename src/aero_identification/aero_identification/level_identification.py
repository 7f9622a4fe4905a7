"""One level's models: period clustering, the BLA and the linear state-space model (steps 1-2
of `pipeline.identify`)."""

import time

import numpy as np

from .bla import estimate_bla
from .clustering import ClusterResult, period_clusters
from .dataset import LevelRecord
from .hyperparameters import IdentificationConfig
from .identification_result import LevelResult, Log
from .subspace import fit_linear_ss

__all__ = ["kept_periods", "level_models"]


def level_models(
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


def kept_periods(res: LevelResult, m: int) -> np.ndarray:
    """Positions (within the level's data) of realization m's periods that clustering kept;
    every period without clusters, or when the cluster kept none of this realization."""
    data = res.record.data
    assert data is not None
    cols = np.arange(data.P)
    if res.clusters is None:
        return cols
    keep = res.clusters.keep[:, m]
    return cols[keep] if keep.any() else cols

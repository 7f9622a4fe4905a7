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

This module holds the numerical pieces; `pipeline.identify` runs the replicates
(``config.bootstrap``).
"""

import math
from collections.abc import Mapping, Sequence

import numpy as np

from .data import PeriodicData

Cell = tuple[str, str, float]  # (model, level, frequency [Hz]), Table 1's keys

__all__ = ["Cell", "replicate_spreads", "resample_periods"]


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

"""The clustering ablation: the same identification on every valid period, run beside the
clustered one, and what clustering changed (step 5 of `pipeline.identify`)."""

import dataclasses
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from .bla import bla_levels_db
from .dataset import Dataset
from .estimation_sets import estimation_sets, validation_realization
from .hyperparameters import IdentificationConfig
from .identification_result import IdentificationResult, Log
from .level_identification import kept_periods
from .metrics import relative_rms_error, steady_state_response
from .warm_up import warm_up

__all__ = [
    "ablation_beside",
    "ablation_config",
    "clustering_dropped",
    "clustering_effect",
    "run_ablation",
    "start_ablation",
]


# `pipeline.identify`, which runs this module's steps: handed in, not imported.
Identify = Callable[..., IdentificationResult]


def start_ablation(
    identify: Identify,
    dataset: Dataset,
    result: IdentificationResult,
    config: IdentificationConfig,
    final: bool,
    final_models: bool,
    client: Any,
    held_out: tuple[str, ...],
    say: Log,
) -> Future[tuple[IdentificationResult, float]] | None:
    """The identification without clustering, started in its own thread once the level models
    say whether clustering dropped any period (None: not asked for, nothing to ablate, or it
    cannot run beside: `ablation_beside`). Its future gives (result, seconds). The caller
    holds one BLAS thread (`identify`) until it has the result, so both threads' fits run
    with the same BLAS as one after the other would, and give the same numbers."""
    if not (final_models and config.clustering and config.clustering_ablation):
        return None
    if not clustering_dropped(result) or not ablation_beside(config, client):
        return None
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="clustering_ablation")
    future = pool.submit(
        run_ablation, identify, dataset, ablation_config(config), final, client, held_out, say
    )
    pool.shutdown(wait=False)  # the thread ends with its job; the caller waits on the future
    return future


def ablation_config(config: IdentificationConfig) -> IdentificationConfig:
    """The ablation's configuration: the same pipeline on every valid period, no bootstrap."""
    return dataclasses.replace(config, clustering=False, clustering_ablation=False, bootstrap=0)


def clustering_dropped(result: IdentificationResult) -> bool:
    return any(lv.clusters is not None and lv.clusters.k > 1 for lv in result.levels.values())


def run_ablation(
    identify: Identify,
    dataset: Dataset,
    plain: IdentificationConfig,
    final: bool,
    client: Any,
    held_out: tuple[str, ...],
    say: Log,
) -> tuple[IdentificationResult, float]:
    """The same pipeline without clustering, its final models (`identify`'s
    ``final_models``), and its seconds; its messages say so."""
    t0 = time.perf_counter()
    done = identify(
        dataset,
        plain,
        final=final,
        final_models=True,
        client=client,
        held_out=held_out,
        log=lambda message: say(f"no clustering: {message}"),
    )
    return done, time.perf_counter() - t0


def ablation_beside(config: IdentificationConfig, client: Any) -> bool:
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
            _, held, _ = estimation_sets([lv], cfg)
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
                entry["validation_periods"] = len(kept_periods(lv, val)) if val is not None else 1
        effect[name] = entry
    return effect

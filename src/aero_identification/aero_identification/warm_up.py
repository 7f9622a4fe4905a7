"""Warm-up of a fresh process: every stage of the identification once on a small record."""

import time

import numpy as np

from .bla import estimate_bla
from .clustering import period_clusters
from .periodic_data import PeriodicData, random_phase_period
from .pnlss import PnlssSettings, fit_pnlss
from .subspace import fit_linear_ss

__all__ = ["warm_up"]


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
    model = fit_pnlss(
        data, lin, PnlssSettings(degrees=(2, 3), max_iter=2, stress=1.5), validation=data
    )
    model.state_after(u[:, 0, 0])  # the scan's periodicity check's warm-up kernel
    return time.perf_counter() - t0

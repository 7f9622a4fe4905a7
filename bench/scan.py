"""Benchmark: the cross-validated PNLSS structure scan, serial, on local cores, on Dask.

    .venv/bin/python bench/scan.py [--periods P]

Data: the simulated Duffing system of bench/pnlss_fit.py (Silverbox-like, RK4, 0.5 % output
noise, odd multisine up to 200 Hz at fs = 610.35 Hz, N = 8192), with P training periods
(default 9, as pnlss_fit.py; `--periods 2` for a quick run, where the cluster's start-up
weighs more) and one validation realization of 2 periods.

Grid (18 candidates): nx ∈ {1, 2, 3} × degrees ∈ {(2,), (2, 3), (2, 3, 4, 5)} × equations ∈
{state, state+output}, "full" structure, 50 Levenberg–Marquardt iterations each.

Runs of `scan_pnlss` on the same data:
- serial: ``workers=1``, one fit after the other in this process, on one core (numba kernels
  limited to one thread: what one worker of the parallel runs has);
- serial, threaded: the same with the kernels' own parallelism over records (numba prange,
  every core), for comparison;
- parallel: the default, a local Dask cluster with one single-threaded worker process per core
  (its start-up is included: it is what a user waits for);
- dask: an explicit 2-worker ``LocalCluster`` + ``Client`` passed as ``client=`` (the way a
  remote cluster is used; the cluster's start-up is reported apart and not included).

Prints the scan table, the wall times, the speed-up serial (one core) / parallel and whether
every run selected the same candidate. Last line: JSON.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pnlss_fit as duffing  # the data generator of the PNLSS fit benchmark

NX = (1, 2, 3)
GRID: dict[str, Any] = {
    "nx": NX,
    "degrees": ((2,), (2, 3), (2, 3, 4, 5)),
    "equations": ("state", "state+output"),
    "structures": ("full",),
}
MAX_ITER = 50


def make_data(periods: int) -> tuple[Any, Any]:
    from aero_identification.periodic_data import PeriodicData

    rng = np.random.default_rng(2024)
    n = duffing.N
    lines = np.arange(1, int(200.0 / duffing.FS * n), 2)

    def record(p: int) -> tuple[np.ndarray, np.ndarray]:
        u = np.tile(duffing.odd_multisine(rng, lines), duffing.P_SETTLE + p)
        y = duffing.duffing_rk4(u, duffing.FS, duffing.F0, duffing.ZETA, duffing.A3)
        u, y = u[duffing.P_SETTLE * n :], y[duffing.P_SETTLE * n :]
        return u.reshape(p, n).T[:, :, None], y.reshape(p, n).T[:, :, None]

    u_tr, y_tr = record(periods)
    u_va, y_va = record(2)
    noise = duffing.NOISE_REL * np.std(y_tr)
    y_tr = y_tr + noise * rng.standard_normal(y_tr.shape)
    y_va = y_va + noise * rng.standard_normal(y_va.shape)
    train = PeriodicData(u_tr, y_tr, duffing.FS, lines)
    val = PeriodicData(u_va, y_va, duffing.FS, lines)
    return train, val


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--periods", type=int, default=9, help="training periods (default 9)")
    args = parser.parse_args()

    from dask.distributed import Client, LocalCluster

    from aero_identification.bla import estimate_bla
    from aero_identification.scan import scan_pnlss
    from aero_identification.subspace import fit_linear_ss

    train, val = make_data(args.periods)
    # Linear models of every order from the BLA of both records (two realizations).
    from aero_identification.periodic_data import PeriodicData

    both = PeriodicData(
        np.concatenate([train.u[:, :2], val.u[:, :2]], axis=2),
        np.concatenate([train.y[:, :2], val.y[:, :2]], axis=2),
        train.fs,
        train.excited_lines,
    )
    bla = estimate_bla(both)
    u0, y0 = float(train.u.mean()), float(train.y.mean())
    linear = {n: fit_linear_ss(bla, nx=n).with_operating_point(u0, y0) for n in NX}
    print(f"data: {train.N} × {train.P} training samples, validation {val.N} × {val.P}, "
          f"{train.excited_lines.size} excited lines; {os.cpu_count()} cores")  # fmt: skip

    # numba kernels: compiled (or loaded from the on-disk cache) here, not inside the timings.
    scan_pnlss(train, val, nx=(1,), degrees=((2,),), equations=("state",), max_iter=1,
               linear=linear, workers=1)  # fmt: skip

    import numba

    threads = numba.get_num_threads()
    numba.set_num_threads(1)  # "1 worker": one core, as each worker of the parallel runs
    t0 = time.perf_counter()
    serial = scan_pnlss(train, val, **GRID, max_iter=MAX_ITER, linear=linear, workers=1)
    serial_s = time.perf_counter() - t0
    numba.set_num_threads(threads)
    print(serial.to_markdown())
    print(f"serial, one core: {serial_s:.1f} s")
    # For comparison: serial with the kernels' own parallelism over records (numba prange).
    t0 = time.perf_counter()
    threaded = scan_pnlss(train, val, **GRID, max_iter=MAX_ITER, linear=linear, workers=1)
    threaded_s = time.perf_counter() - t0
    print(f"serial, numba threads over records ({threads}): {threaded_s:.1f} s")

    t0 = time.perf_counter()
    parallel = scan_pnlss(train, val, **GRID, max_iter=MAX_ITER, linear=linear)
    parallel_s = time.perf_counter() - t0
    print(f"parallel ({parallel.workers}, start-up included): {parallel_s:.1f} s")

    t0 = time.perf_counter()
    with (
        LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        startup_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        remote = scan_pnlss(train, val, **GRID, max_iter=MAX_ITER, linear=linear, client=client)
        dask_s = time.perf_counter() - t0
    print(f"dask (2-worker LocalCluster as client): {dask_s:.1f} s (+ {startup_s:.1f} s start)")

    same = serial.best_index == parallel.best_index == remote.best_index == threaded.best_index
    best = serial.best_row
    print(f"selected: nx={best.nx}, degrees {list(best.degrees)}, {best.equations}; "
          f"same in every run: {same}")  # fmt: skip
    print(json.dumps({
        "candidates": len(serial.rows),
        "training_samples": int(train.N * train.P),
        "serial_s": round(serial_s, 2),
        "serial_threaded_s": round(threaded_s, 2),
        "parallel_s": round(parallel_s, 2),
        "dask_s": round(dask_s, 2),
        "dask_startup_s": round(startup_s, 2),
        "speedup": round(serial_s / parallel_s, 2),
        "speedup_dask": round(serial_s / dask_s, 2),
        "same_selection": bool(same),
        "selected": {"nx": best.nx, "degrees": list(best.degrees), "equations": best.equations},
        "cores": os.cpu_count(),
    }))  # fmt: skip


if __name__ == "__main__":
    main()

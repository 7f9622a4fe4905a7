"""Peer benchmark: freq-statespace's NL-LFR (BLA → linear SS → inference & learning → optimisation).

Runs in a separate venv that has ``freq-statespace==0.1.2`` (jax) installed::

    /tmp/fss/bin/python bench/nllfr_peer.py --data IN.npz --out OUT.json
    /tmp/fss/bin/python bench/nllfr_peer.py --f16 /work/shared/data/f16-gvt --out OUT.json
        [--data F16.npz]   # with --f16: where the built .npz is written (optional)
        [--nx 10]          # overrides the .npz's nx (on F-16 nx 6 gives an unstable BLA)

Input .npz layout (all arrays; SISO):

- ``u_est``, ``y_est``: float, shape (N, P, R) — estimation input/output, N samples per
  period, P steady-state periods, R records (phase realizations or excitation levels);
- ``fs``: float scalar, sampling frequency [Hz];
- ``excited``: int, shape (F,) — excited DFT bin indices of one period (0 < k < N/2);
- ``nx``: int scalar, state order;
- ``val_names``: str, shape (K,) — names of the validation sets;
- ``u_val_<name>``, ``y_val_<name>``: float, shape (N, P_k) — one validation record per name,
  P_k steady-state periods of the same N-sample period.

The model (freq-statespace's documented pipeline, package defaults unless named here)::

    data  = fss.create_data_object(u (N,1,R,P), y (N,1,R,P), excited, fs)
    bla   = fss.lin.subspace_id(data, nx)                      # nq = nx + 1, BLA weighting
    bla   = fss.lin.optimize(bla, data)                        # LM, max_iter 1000
    phi   = fss.static.basis.Polynomial(nz, degree)            # full, cross terms, tanh clip
    model = fss.nonlin.inference_and_learning(bla, data, phi, nw)  # λ_w 1e-2, 10 FP iters
    model = fss.nonlin.optimize(model, data)                   # LM, max_iter 100

Validation: ``model.simulate(u, offset=settle·N)`` on the whole record (all P_k periods, one
period of the record's own input prepended by default and discarded), error
``rms(y − ŷ) / rms(y − mean(y))`` over all P_k periods. ``fit_s`` is the wall-clock time
(``time.perf_counter``) of everything from ``create_data_object`` through the last optimisation,
JIT compilation included; the import of jax/freq-statespace is timed separately. ``--budget S``
stops the fit after S seconds (checked between solver iterations): the JSON then has
``settings.timeout`` set and null errors. An error is also null if the simulation diverged
(an unstable model gives NaN). ``--threads 1`` (default) gives XLA's CPU backend a single
intra-op worker (see ``_import_fss``: it also avoids a jaxlib 0.10.2 deadlock on 2-core hosts);
jax's default float32 is kept unless ``--x64``.

Progress lines go to stdout; the last line is the JSON summary (also written to ``--out``).
"""

from __future__ import annotations

import argparse
import faulthandler
import importlib.metadata
import json
import os
import signal
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

F16_EST_LEVELS = (1, 3, 5, 7)
F16_VAL_LEVELS = (2, 4, 6)
F16_N = 8192
F16_PERIODS = 9


def _f16_file(directory: Path, level: int) -> Path:
    """Return the F-16 FullMSine CSV of ``level`` (estimation or ``_Validation`` name)."""
    hits = sorted(directory.glob(f"F16Data_FullMSine_Level{level}*.csv"))
    if len(hits) != 1:
        raise FileNotFoundError(f"expected one CSV for level {level} in {directory}: {hits}")
    return hits[0]


def build_f16_npz(directory: Path, out: Path, nx: int) -> Path:
    """Build the benchmark .npz from the F-16 GVT FullMSine CSVs.

    Input ``Force``, output ``Acceleration2``; 9 periods of 8192 samples per level, the first
    period dropped (transient). Estimation records: levels 1, 3, 5, 7 (R = 4, P = 8);
    validation sets ``L2``, ``L4``, ``L6`` (P_k = 8). Excited bins are read off the shaker's
    drive (``Voltage``) spectrum, which is exactly zero off the grid.
    """
    records: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    excited: set[int] = set()
    fs = float("nan")
    for level in (*F16_EST_LEVELS, *F16_VAL_LEVELS):
        path = _f16_file(directory, level)
        table = np.genfromtxt(path, delimiter=",", skip_header=1, usecols=(0, 1, 3, 5))
        if table.shape[0] != F16_N * F16_PERIODS:
            raise ValueError(f"{path}: {table.shape[0]} rows, expected {F16_N * F16_PERIODS}")
        fs = float(table[0, 3])
        per = table[:, :3].reshape(F16_PERIODS, F16_N, 3)[1:]  # (P, N, 3), first period dropped
        drive = np.abs(np.fft.rfft(per[:, :, 1].mean(axis=0)))
        excited |= set(np.nonzero(drive > 1e-2 * drive.max())[0].tolist())
        records[level] = (per[:, :, 0].T.copy(), per[:, :, 2].T.copy())  # (N, P) each
        print(f"[f16] level {level}: {path.name}, fs {fs:g} Hz", flush=True)
    bins = np.array(sorted(excited), dtype=int)
    print(f"[f16] excited bins {bins.min()}..{bins.max()} ({bins.size})", flush=True)
    arrays: dict[str, Any] = {
        "u_est": np.stack([records[k][0] for k in F16_EST_LEVELS], axis=2),
        "y_est": np.stack([records[k][1] for k in F16_EST_LEVELS], axis=2),
        "fs": np.float64(fs),
        "excited": bins,
        "nx": np.int64(nx),
        "val_names": np.array([f"L{k}" for k in F16_VAL_LEVELS]),
    }
    for k in F16_VAL_LEVELS:
        arrays[f"u_val_L{k}"], arrays[f"y_val_L{k}"] = records[k]
    np.savez(out, **arrays)
    return out


class FitTimeoutError(Exception):
    """The fit ran past its ``--budget``."""


def _radius(A: Any) -> float:
    """Return the spectral radius of a state matrix (> 1: unstable)."""
    return round(float(np.max(np.abs(np.linalg.eigvals(np.asarray(A, float))))), 6)


def _finite(x: Any) -> float | None:
    """Return ``x`` as a float, or None if it is NaN/inf (strict JSON has no NaN)."""
    v = float(x)
    return v if np.isfinite(v) else None


def relative_rms(y: np.ndarray, y_hat: np.ndarray) -> float:
    """Return rms(y − ŷ) / rms(y − mean(y)) over all samples."""
    return float(np.sqrt(np.mean((y - y_hat) ** 2) / np.mean((y - y.mean()) ** 2)))


def _import_fss(threads: int, x64: bool) -> Any:
    """Import freq_statespace (and jax) with the CPU backend set up; return the module.

    ``threads == 1``: the process is pinned to one CPU while jax creates its CPU client, so
    XLA's intra-op pool gets one worker, then the affinity is restored. jaxlib 0.10.2's
    batched LAPACK kernels (``jax::ParallelBatchMap``, used by the vmapped complex solves of
    inference and learning) block a pool worker while fanning out into the same pool: two of
    them at once on a 2-worker pool deadlock (seen on F-16 data; not on small problems).
    """
    os.environ["JAX_PLATFORMS"] = "cpu"
    if x64:
        os.environ["JAX_ENABLE_X64"] = "1"
    cpus = os.sched_getaffinity(0)
    if threads == 1:
        os.sched_setaffinity(0, {min(cpus)})
    try:
        import freq_statespace as fss  # type: ignore[import-not-found]  # imports jax

        importlib.import_module("jax").devices()  # creates the CPU client and its pool
    finally:
        os.sched_setaffinity(0, cpus)
    return fss


def main() -> None:
    """Parse arguments, fit the NL-LFR, validate, print and write the JSON summary."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, help="input .npz (with --f16: where to write it)")
    ap.add_argument("--out", type=Path, required=True, help="output JSON")
    ap.add_argument("--f16", type=Path, help="F-16 GVT CSV directory: build the .npz first")
    ap.add_argument("--f16-nx", type=int, default=6, help="state order stored by --f16")
    ap.add_argument("--nx", type=int, help="state order (default: the .npz's nx)")
    ap.add_argument("--nz", type=int, default=1, help="dimension of z (nonlinearity input)")
    ap.add_argument("--nw", type=int, default=1, help="dimension of w (nonlinearity output)")
    ap.add_argument("--degree", type=int, default=3, help="polynomial degree of phi(z)")
    ap.add_argument("--settle", type=int, default=1, help="periods prepended in validation")
    ap.add_argument(
        "--threads", type=int, default=1, help="1: one XLA intra-op worker, else default"
    )
    ap.add_argument("--x64", action="store_true", help="jax float64 (package default: float32)")
    ap.add_argument("--budget", type=float, default=0.0, help="stop the fit after S s (0: none)")
    ap.add_argument("--print-every", type=int, default=-1, help="fss solver logging (-1: off)")
    args = ap.parse_args()

    if args.f16 is not None:
        npz = args.data or Path(tempfile.mkdtemp(prefix="f16-npz-")) / "f16.npz"
        args.data = build_f16_npz(args.f16, npz, args.f16_nx)
        print(f"[data] wrote {args.data}", flush=True)
    if args.data is None:
        ap.error("--data is required unless --f16 is given")

    raw = np.load(args.data)
    u_est, y_est = np.asarray(raw["u_est"], float), np.asarray(raw["y_est"], float)
    N, P, R = u_est.shape
    fs, nx = float(raw["fs"]), int(raw["nx"]) if args.nx is None else args.nx
    excited = np.asarray(raw["excited"], dtype=int)
    val_names = [str(s) for s in raw["val_names"]]
    print(
        f"[data] {args.data}: N {N}, P {P}, R {R}, fs {fs:g}, {excited.size} excited "
        f"bins, nx {nx}, validation {val_names}",
        flush=True,
    )

    faulthandler.register(signal.SIGUSR1)  # `kill -USR1 PID` dumps the Python stacks
    t0 = time.perf_counter()
    fss = _import_fss(args.threads, args.x64)
    import_s = time.perf_counter() - t0
    print(
        f"[import] freq_statespace + jax {importlib.metadata.version('jax')} (cpu), "
        f"{import_s:.2f} s",
        flush=True,
    )

    # (N, P, R) → the package's (N, nu, R, P).
    u4 = np.transpose(u_est, (0, 2, 1))[:, None, :, :]
    y4 = np.transpose(y_est, (0, 2, 1))[:, None, :, :]
    pe = args.print_every
    stages: dict[str, dict[str, Any]] = {}

    def _log(name: str, t_start: float, result: Any | None, **extra: Any) -> None:
        entry: dict[str, Any] = {"s": round(time.perf_counter() - t_start, 3), **extra}
        if result is not None:
            entry |= {
                "iters": int(result.iter_count),
                "converged": bool(result.converged),
                "loss": _finite(result.loss_history[-1]) if result.iter_count else None,
                "solver_s": round(float(result.wall_time), 3),
            }
        stages[name] = entry
        print(f"[fit] {name}: {entry}", flush=True)

    def _fit() -> Any:
        data = fss.create_data_object(u4, y4, excited, fs)
        _log("create_data_object", t_fit, None)

        t = time.perf_counter()
        bla = fss.lin.subspace_id(data, nx, logging_enabled=pe != -1)
        _log("lin.subspace_id", t, None, spectral_radius=_radius(bla.A))

        t = time.perf_counter()
        bla, res = fss.lin.optimize(bla, data, print_every=pe, return_solve_details=True)
        _log("lin.optimize", t, res, spectral_radius=_radius(bla.A))

        phi = fss.static.basis.Polynomial(nz=args.nz, degree=args.degree)
        t = time.perf_counter()
        model, res = fss.nonlin.inference_and_learning(
            bla, data, phi, args.nw, print_every=pe, return_solve_details=True
        )
        _log("nonlin.inference_and_learning", t, res)

        t = time.perf_counter()
        model, res = fss.nonlin.optimize(model, data, print_every=pe, return_solve_details=True)
        _log("nonlin.optimize", t, res, spectral_radius=_radius(model.A))
        return model

    def _on_alarm(signum: int, frame: Any) -> None:
        raise FitTimeoutError

    errors: dict[str, float | None] = {name: None for name in val_names}
    timeout: dict[str, Any] | None = None
    if args.budget > 0:
        signal.signal(signal.SIGALRM, _on_alarm)
        signal.setitimer(signal.ITIMER_REAL, args.budget)
    t_fit = time.perf_counter()
    try:
        model = _fit()
    except FitTimeoutError:
        model = None
        done = list(stages)
        timeout = {"budget_s": args.budget, "stages_done": done}
        print(f"[fit] stopped after the {args.budget:g} s budget; done: {done}", flush=True)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    fit_s = time.perf_counter() - t_fit
    print(f"[fit] total {fit_s:.2f} s", flush=True)

    for name in val_names if model is not None else []:
        u_val = np.asarray(raw[f"u_val_{name}"], float)
        y_val = np.asarray(raw[f"y_val_{name}"], float)
        n_val = u_val.shape[0]
        # One continuous run over all P_k periods, `settle` periods of its input prepended.
        y_hat = model.simulate(u_val.T.reshape(-1), offset=args.settle * n_val)[0][:, 0]
        err = relative_rms(y_val.T.reshape(-1), y_hat)
        errors[name] = _finite(err)  # null: the simulation diverged
        print(f"[val] {name}: P {u_val.shape[1]}, relative RMS error {err:.4f}", flush=True)

    summary = {
        "method": "freq-statespace NL-LFR (BLA -> subspace -> inference & learning -> LM)",
        "settings": {
            "package": f"freq-statespace {importlib.metadata.version('freq-statespace')}",
            "nx": nx,
            "static_nl": f"BasisFunctionModel(Polynomial(nz={args.nz}, degree={args.degree},"
            " full, cross_terms, offset, linear, tanh_clip)), "
            f"nw={args.nw}",
            "subspace_id": "nq=nx+1, freq_weighting=True",
            "lin.optimize": "LevenbergMarquardt(rtol=1e-3, atol=1e-6), max_iter=1000",
            "inference_and_learning": "lambda_w=1e-2, fixed_point_iters=10, LM, "
            "max_iter=1000, seed=42",
            "nonlin.optimize": "LM, max_iter=100, offset=ceil(0.1 N), freq_weighting=True",
            "N": N,
            "P": P,
            "R": R,
            "excited_bins": int(excited.size),
            "validation_settle_periods": args.settle,
            "xla_intra_op_workers": args.threads if args.threads == 1 else "default",
            "x64": args.x64,
            "import_s": round(import_s, 3),
            "stages": stages,
            "timeout": timeout,
        },
        "fit_s": round(fit_s, 3),
        "errors": errors,
    }
    line = json.dumps(summary)
    args.out.write_text(line + "\n")
    print(line, flush=True)


if __name__ == "__main__":
    main()

"""Benchmark: does a PNLSS fit's quality depend on the BLAS kernel and the thread count?

    .venv/bin/python bench/reproducibility.py                  # duffing and f16
    .venv/bin/python bench/reproducibility.py --case duffing
    .venv/bin/python bench/reproducibility.py --case bag --bag runs/campaign/bag

Every case is fitted in fresh processes that differ only in their environment:

- ``machine``: the environment as it is (this machine sets OPENBLAS_CORETYPE=Haswell and
  OPENBLAS_L2_SIZE, and so do CI and the project's machines);
- ``generic``: OPENBLAS_CORETYPE and OPENBLAS_L2_SIZE unset (OpenBLAS picks its kernel itself);
- ``threads1``: as ``machine`` with NUMBA_NUM_THREADS=1 (the kernels' records in one thread
  instead of one per core).

Cases:

- ``duffing``: a Duffing oscillator (bench/pnlss_fit.py's system and multisine), the call of
  issue 22: ``fit_pnlss(data, lin, PnlssSettings(degrees=(2, 3), structure="full",
  max_iter=50), validation=...)`` at nx = 2; validation on another realization, test on a
  third realization at 1.4× the amplitude (extrapolation);
- ``f16``: the F-16 GVT benchmark (``$F16_GVT_DIR``, see docs/real_data.md): nx = 6, statesonly
  degree 3, 20 iterations, trained on levels 1, 3, 5, 7; errors on levels 2, 4, 6;
- ``bag``: ``aero-rig fit BAG`` on a campaign's bag (``--bag``); Table 1's PNLSS cells.

Prints each case's errors per environment and their relative spread ((max − min) / min, the
issue's target: ≤ 5 %). Last line: JSON.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ENVIRONMENTS: dict[str, dict[str, str | None]] = {
    "machine": {},
    "generic": {"OPENBLAS_CORETYPE": None, "OPENBLAS_L2_SIZE": None},
    "threads1": {"NUMBA_NUM_THREADS": "1"},
}


def duffing_case() -> dict[str, float]:
    sys.path.insert(0, str(HERE))
    from pnlss_fit import FS, P_SETTLE, P_TRAIN, N, duffing_rk4, odd_multisine

    from aero_identification.bla import estimate_bla
    from aero_identification.metrics import relative_rms_error
    from aero_identification.periodic_data import PeriodicData
    from aero_identification.pnlss import PnlssSettings, fit_pnlss
    from aero_identification.subspace import fit_linear_ss

    rng = np.random.default_rng(2024)
    lines = np.arange(1, int(200.0 / FS * N), 2)

    def record(scale: float, periods: int) -> tuple[np.ndarray, np.ndarray]:
        u = np.tile(odd_multisine(rng, lines) * scale, P_SETTLE + periods)
        y = duffing_rk4(u, FS, 60.0, 0.05, 0.05)[P_SETTLE * N :]
        return u[P_SETTLE * N :], y

    u, y = record(1.0, P_TRAIN)
    noise = 0.005 * np.std(y)
    y = y + noise * rng.standard_normal(y.size)
    data = PeriodicData(u.reshape(P_TRAIN, N).T[:, :, None], y.reshape(P_TRAIN, N).T[:, :, None],
                        FS, lines)  # fmt: skip
    u_val, y_val = record(1.0, 2)
    y_val = y_val + noise * rng.standard_normal(y_val.size)
    u_test, y_test = record(1.4, 2)
    y_test = y_test + noise * rng.standard_normal(y_test.size)
    lin = fit_linear_ss(estimate_bla(data), nx=2).with_operating_point(u.mean(), y.mean())
    t0 = time.perf_counter()
    settings = PnlssSettings(degrees=(2, 3), structure="full", max_iter=50)
    model = fit_pnlss(data, lin, settings, validation=(u_val, y_val))
    seconds = time.perf_counter() - t0
    return {
        "validation": relative_rms_error(y_val[N:], model.simulate(u_val)[N:]),
        "test_1.4x": relative_rms_error(y_test[N:], model.simulate(u_test)[N:]),
        "fit_s": seconds,
    }


def _cli_fit(args: list[str]) -> Path:
    out = Path(tempfile.mkdtemp(prefix="repro-"))
    cmd = [sys.executable, "-m", "aero_rig.cli", "fit", *args, "--out", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode not in (0, 3):
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{done.stderr[-2000:]}")
    return out


def f16_case() -> dict[str, float]:
    directory = os.environ.get("F16_GVT_DIR", str(HERE.parent.parent / "shared/data/f16-gvt"))
    t0 = time.perf_counter()
    out = _cli_fit([
        directory, "--format", "csv", "--input", "Force", "--output", "Acceleration2",
        "--period", "8192", "--estimation", "1", "3", "5", "7", "--validation", "2", "4", "6",
        "--drop-periods", "1", "--structure", "statesonly", "--degrees", "3", "--max-iter", "20",
    ])  # fmt: skip
    seconds = time.perf_counter() - t0
    import csv

    with (out / "validation_errors.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    return {f"level {r['level']}": float(r["pnlss"]) for r in rows} | {"fit_s": seconds}


def bag_case(bag: str) -> dict[str, float]:
    t0 = time.perf_counter()
    out = _cli_fit([bag])
    seconds = time.perf_counter() - t0
    models = json.loads((out / "models.json").read_text())
    cells = {}
    for model, level, freq, value in models["errors"]["all_levels"]:
        if model == "PNLSS":
            cells[f"{level} {freq:g} Hz"] = float(value)
    return cells | {"fit_s": seconds}


def run_worker(case: str, bag: str | None) -> None:
    if case == "duffing":
        result = duffing_case()
    elif case == "f16":
        result = f16_case()
    else:
        assert bag is not None
        result = bag_case(bag)
    print("RESULT " + json.dumps(result))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", action="append", choices=("duffing", "f16", "bag"))
    parser.add_argument("--bag", help="a campaign's bag directory (case 'bag')")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        run_worker(args.worker, args.bag)
        return
    cases = args.case or ["duffing", "f16"]
    summary: dict[str, dict] = {}
    for case in cases:
        per_env: dict[str, dict[str, float]] = {}
        for name, change in ENVIRONMENTS.items():
            env = dict(os.environ)
            for k, v in change.items():
                if v is None:
                    env.pop(k, None)
                else:
                    env[k] = v
            cmd = [sys.executable, __file__, "--worker", case]
            if args.bag:
                cmd += ["--bag", args.bag]
            done = subprocess.run(cmd, env=env, capture_output=True, text=True)
            line = [x for x in done.stdout.splitlines() if x.startswith("RESULT ")]
            if done.returncode != 0 or not line:
                raise SystemExit(f"{case} in {name}: failed\n{done.stderr[-3000:]}")
            per_env[name] = json.loads(line[0][7:])
            print(f"{case:8s} {name:9s} " + ", ".join(
                f"{k} {v:.4g}" for k, v in per_env[name].items()))  # fmt: skip
        keys = [k for k in per_env["machine"] if k != "fit_s"]
        spread = {}
        for k in keys:
            values = [per_env[e][k] for e in per_env]
            spread[k] = (max(values) - min(values)) / min(values)
        worst = max(spread.values())
        print(f"{case}: largest relative spread over the environments {100 * worst:.1f} % "
              f"({'within' if worst <= 0.05 else 'OVER'} the 5 % target)")  # fmt: skip
        summary[case] = {"errors": per_env, "spread": spread, "worst_spread": worst}
    print(json.dumps({"cases": summary}))


if __name__ == "__main__":
    main()

"""Benchmark: PNLSS fit (nx = 2, degrees (2, 3), full) on a simulated Silverbox-like Duffing system.

    .venv/bin/python bench/pnlss_fit.py          # numba cache as usual (warm after a first run)
    .venv/bin/python bench/pnlss_fit.py --cold   # empty numba cache: measures a cold compile

System: y'' + 2ζω0 y' + ω0² (y + a y³) = ω0² u (a Duffing oscillator, the Silverbox's model),
integrated by RK4 with 8 sub-steps per sample and the input held (ZOH). Excitation: odd
random-phase multisine generated here with numpy, lines up to 200 Hz at fs = 610.35 Hz.
Training: 9 steady-state periods × 8192 samples = 73,728 samples (one realization);
validation: another realization, 2 periods. 0.5 % output noise.

Prints the time of one training simulation, one Jacobian, the whole 100-iteration fit (numba
already compiled: the compile/cache-load time is reported separately and NOT included in fit_s),
peak memory of the fit, and the relative RMS errors on validation. Last line: JSON.
"""

import json
import os
import resource
import sys
import tempfile
import time
import tracemalloc

if "--cold" in sys.argv:  # must precede the first numba import
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="numba-cold-")

import numpy as np
from numba import njit

FS = 610.35
N = 8192
P_TRAIN = 9
P_SETTLE = 2
F0, ZETA, A3 = 60.0, 0.05, 0.05  # resonance [Hz], damping ratio, cubic stiffness [1/unit²]
U_RMS = 0.5
NOISE_REL = 0.005
MAX_ITER = 100


@njit(cache=True)
def duffing_rk4(u: np.ndarray, fs: float, f0: float, zeta: float, a3: float) -> np.ndarray:
    w0 = 2 * np.pi * f0
    h = 1.0 / (fs * 8)
    y = np.empty(u.size)
    x1 = 0.0
    x2 = 0.0
    for t in range(u.size):
        y[t] = x1
        for _ in range(8):
            # f(x) = [x2, w0²(u − x1 − a3 x1³) − 2ζw0 x2]
            k11 = x2
            k12 = w0 * w0 * (u[t] - x1 - a3 * x1**3) - 2 * zeta * w0 * x2
            p1, p2 = x1 + 0.5 * h * k11, x2 + 0.5 * h * k12
            k21 = p2
            k22 = w0 * w0 * (u[t] - p1 - a3 * p1**3) - 2 * zeta * w0 * p2
            p1, p2 = x1 + 0.5 * h * k21, x2 + 0.5 * h * k22
            k31 = p2
            k32 = w0 * w0 * (u[t] - p1 - a3 * p1**3) - 2 * zeta * w0 * p2
            p1, p2 = x1 + h * k31, x2 + h * k32
            k41 = p2
            k42 = w0 * w0 * (u[t] - p1 - a3 * p1**3) - 2 * zeta * w0 * p2
            x1 += h / 6 * (k11 + 2 * k21 + 2 * k31 + k41)
            x2 += h / 6 * (k12 + 2 * k22 + 2 * k32 + k42)
    return y


def odd_multisine(rng: np.random.Generator, lines: np.ndarray) -> np.ndarray:
    U = np.zeros(N // 2 + 1, complex)
    U[lines] = np.exp(2j * np.pi * rng.random(lines.size))
    u = np.fft.irfft(U, n=N)
    return u / np.std(u) * U_RMS


def main() -> None:
    from aero_identification.bla import estimate_bla
    from aero_identification.metrics import relative_rms_error
    from aero_identification.periodic_data import PeriodicData
    from aero_identification.pnlss import PnlssSettings, _Layout, fit_pnlss
    from aero_identification.pnlss_kernels import jacobian_records, simulate_records
    from aero_identification.state_space_models import STATE_BOUND
    from aero_identification.subspace import fit_linear_ss

    rng = np.random.default_rng(2024)
    lines = np.arange(1, int(200.0 / FS * N), 2)
    t0 = time.perf_counter()
    u_period = odd_multisine(rng, lines)
    u_all = np.tile(u_period, P_SETTLE + P_TRAIN)
    y_all = duffing_rk4(u_all, FS, F0, ZETA, A3)[P_SETTLE * N :]
    noise_std = NOISE_REL * np.std(y_all)
    y_all = y_all + noise_std * rng.standard_normal(y_all.size)
    u_tr = u_all[P_SETTLE * N :].reshape(P_TRAIN, N).T[:, :, None]
    y_tr = y_all.reshape(P_TRAIN, N).T[:, :, None]
    data = PeriodicData(u=u_tr, y=y_tr, fs=FS, excited_lines=lines)
    u_val = np.tile(odd_multisine(rng, lines), P_SETTLE + 2)
    y_val_true = duffing_rk4(u_val, FS, F0, ZETA, A3)[P_SETTLE * N :]
    u_val = u_val[P_SETTLE * N :]
    y_val = y_val_true + noise_std * rng.standard_normal(y_val_true.size)
    print(f"data: {data.N} × {data.P} = {data.N * data.P} training samples, "
          f"{lines.size} excited lines, simulated in {time.perf_counter() - t0:.2f} s")  # fmt: skip

    t0 = time.perf_counter()
    bla = estimate_bla(data)
    lin = fit_linear_ss(bla, nx=2).with_operating_point(data.u.mean(), data.y.mean())
    print(f"BLA ({bla.method}) + linear state space (nx=2): {time.perf_counter() - t0:.2f} s, "
          f"poles {np.round(lin.poles(), 4)}")  # fmt: skip

    # numba: first calls compile (or load from the on-disk cache); timed apart from the fit.
    t0 = time.perf_counter()
    tiny = data.select_realizations([0]).drop_leading(P_TRAIN - 1)
    fit_pnlss(tiny, lin, PnlssSettings(degrees=(2, 3), max_iter=1))
    compile_s = time.perf_counter() - t0
    cold = "--cold" in sys.argv
    print(f"numba {'cold compile' if cold else 'compile or cache load'} + tiny fit: "
          f"{compile_s:.2f} s")  # fmt: skip

    t0 = time.perf_counter()
    settings = PnlssSettings(degrees=(2, 3), structure="full", max_iter=MAX_ITER)
    model = fit_pnlss(data, lin, settings, validation=(u_val, y_val))
    fit_s = time.perf_counter() - t0
    accepted = sum(r.accepted for r in model.history_[1:])
    trials = len(model.history_) - 1
    print(f"fit: {trials} LM iterations ({accepted} accepted) in {fit_s:.2f} s "
          f"(excludes numba compile); n_transient = {model.n_transient}")  # fmt: skip

    # One simulation and one Jacobian of the training set, as inside the fit.
    nt = model.n_transient
    R = data.P * data.M
    u_n = ((data.u - model.u_mean[0]) / model.u_scale[0]).transpose(2, 1, 0).reshape(R, N)
    tail = np.arange(-nt, 0) % N
    u_rec = np.ascontiguousarray(np.concatenate([u_n[:, tail], u_n], axis=1)[:, :, None])
    y_rec = np.ascontiguousarray(((data.y - model.y_mean[0]) / model.y_scale[0])
                                 .transpose(2, 1, 0).reshape(R, N)[:, :, None])  # fmt: skip
    Kz = model.exponents_state.shape[0]
    layout = _Layout(model.nx, 1, 1, Kz, Kz, True)
    J = np.empty((R * N, layout.n_par + 1), order="F")
    m = model
    sim_times, jac_times = [], []
    for _ in range(5):
        t0 = time.perf_counter()
        simulate_records(m.A, m.B, m.C, m.D, m.E, m.F, m.exponents_state, m.exponents_output,
                         u_rec, np.zeros((R, m.nx)), STATE_BOUND)  # fmt: skip
        sim_times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        jacobian_records(m.A, m.B, m.C, m.D, m.E, m.F, m.exponents_state, m.exponents_output,
                         u_rec, y_rec, nt, np.zeros(1), True, STATE_BOUND, J)  # fmt: skip
        jac_times.append(time.perf_counter() - t0)
    simulate_s = float(np.median(sim_times))
    jacobian_s = float(np.median(jac_times))
    print(
        f"one simulation ({R} records × {nt + N} samples): {simulate_s * 1e3:.1f} ms; "
        f"one Jacobian ({R * N} × {layout.n_par} + residual): {jacobian_s * 1e3:.1f} ms"
    )
    del J

    # Peak memory: numpy/Python allocations of a short fit (the peak is reached at the first
    # Jacobian + QR), and the process's peak resident size.
    tracemalloc.start()
    fit_pnlss(data, lin, PnlssSettings(degrees=(2, 3), max_iter=3), validation=(u_val, y_val))
    peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    j_mb = R * N * (layout.n_par + 1) * 8 / 2**20
    print(f"peak traced memory of a fit: {peak_mb:.1f} MB (Jacobian buffer {j_mb:.1f} MB); "
          f"process peak RSS {rss_mb:.0f} MB")  # fmt: skip

    skip = N  # second validation period: free of the start-up transient of the simulation
    e_floor = relative_rms_error(y_val[skip:], y_val_true[skip:])
    e_lin = relative_rms_error(y_val[skip:], lin.simulate(u_val)[skip:])
    e_pnlss = relative_rms_error(y_val[skip:], model.simulate(u_val)[skip:])
    print(f"validation relative RMS error: linear {e_lin:.4f}, PNLSS {e_pnlss:.4f}, "
          f"noise floor {e_floor:.4f}")  # fmt: skip
    print(json.dumps({
        "simulate_s": round(simulate_s, 5),
        "jacobian_s": round(jacobian_s, 5),
        "fit_s": round(fit_s, 3),
        "fit_includes_compile": False,
        "compile_s": round(compile_s, 3),
        "compile_cold": cold,
        "peak_mb": round(peak_mb, 1),
        "rss_mb": round(rss_mb, 1),
        "n_samples": int(R * N),
        "n_params": int(layout.n_par),
        "iterations": trials,
        "accepted": int(accepted),
        "rel_err_linear": round(e_lin, 5),
        "rel_err_pnlss": round(e_pnlss, 5),
        "rel_err_noise_floor": round(e_floor, 5),
    }))  # fmt: skip


if __name__ == "__main__":
    main()

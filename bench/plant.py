"""Throughput of the simulated wing (aero + 49-tap synthesis) and of the lift integration.

Run: .venv/bin/python bench/plant.py [--samples N]
Prints human-readable figures; the last line is one JSON object:
  plant_batch_samples_s, plant_step_samples_s, integration_samples_s,
  integration_step_samples_s, realtime_factor_batch (batch rate / 200 Hz), plus details.
Single-threaded (numba kernels are serial; BLAS threads pinned to 1).
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from pressure_scanner.integration import PressureIntegrator  # noqa: E402
from wing_sim.aero import UnsteadyAerodynamics  # noqa: E402
from wing_sim.plant import WingPlant  # noqa: E402


def multisine_deg(n: int, offset_deg: float, seed: int = 0) -> np.ndarray:
    """Odd random-phase multisine, 0.02–1.98 Hz, 2.4° rms, 200 Hz, repeated to n samples."""
    rng = np.random.default_rng(seed)
    period = 10_000
    spectrum = np.zeros(period // 2 + 1, complex)
    odd = np.arange(1, 100, 2)
    spectrum[odd] = np.exp(2j * math.pi * rng.random(odd.size))
    u = np.fft.irfft(spectrum, period)
    u *= 2.4 / u.std()
    return offset_deg + np.resize(u, n)


def best_rate(fn, samples: int, repeats: int = 3) -> float:
    """Best samples/s over a few repeats (the machine is shared)."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return samples / best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=200_000, help="batch length")
    parser.add_argument("--step-samples", type=int, default=20_000, help="step() calls")
    args = parser.parse_args()
    n = args.samples

    t0 = time.perf_counter()
    plant = WingPlant(seed=0)
    construct_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    plant.simulate(np.zeros(4))
    first_call_s = time.perf_counter() - t0

    results: dict[str, float] = {}
    for offset in (6.6, 19.9):
        alpha = np.deg2rad(multisine_deg(n, offset))
        rate = best_rate(lambda a=alpha: WingPlant(seed=0).simulate(a), n)
        aero_rate = best_rate(lambda a=alpha: UnsteadyAerodynamics(seed=0).simulate(a), n)
        results[f"plant_batch_{offset}"] = rate
        results[f"aero_only_{offset}"] = aero_rate
        print(
            f"plant batch, multisine at {offset:4.1f}°: {rate:10,.0f} samples/s "
            f"(aero alone {aero_rate:11,.0f} samples/s)"
        )
    plant_batch = min(results["plant_batch_6.6"], results["plant_batch_19.9"])

    alpha = np.deg2rad(multisine_deg(args.step_samples, 19.9))
    stepper = WingPlant(seed=0)
    step = stepper.step

    def run_steps() -> None:
        for a in alpha:
            step(a)

    step_rate = best_rate(run_steps, alpha.size, repeats=2)
    print(
        f"plant step(), one sample per call:     {step_rate:10,.0f} samples/s "
        f"({1e6 / step_rate:.1f} µs per call)"
    )

    pressure, _ = WingPlant(seed=0).simulate(np.deg2rad(multisine_deg(n, 19.9)))
    alpha_batch = np.deg2rad(multisine_deg(n, 19.9))
    integrator = PressureIntegrator()
    q = plant.dynamic_pressure_pa
    integ_rate = best_rate(lambda: integrator.integrate(pressure, alpha_batch, q), n)
    print(f"lift integration, batch of {n}:    {integ_rate:10,.0f} samples/s")
    m = min(args.step_samples, n)

    def run_integration_steps() -> None:
        for k in range(m):
            integrator.integrate(pressure[k], alpha_batch[k], q)

    integ_step_rate = best_rate(run_integration_steps, m, repeats=2)
    print(
        f"lift integration, one sample per call: {integ_step_rate:10,.0f} samples/s "
        f"({1e6 / integ_step_rate:.1f} µs per call)"
    )
    print(
        f"plant construction {construct_s * 1e3:.0f} ms (panel solve + tables, cached per "
        f"process); first call {first_call_s * 1e3:.0f} ms (numba cache load or compile)"
    )
    realtime = plant_batch / plant.sample_rate_hz
    print(f"real-time factor of the batch plant: {realtime:,.0f}× (200 Hz)")
    print(
        json.dumps(
            {
                "plant_batch_samples_s": round(plant_batch),
                "plant_step_samples_s": round(step_rate),
                "integration_samples_s": round(integ_rate),
                "integration_step_samples_s": round(integ_step_rate),
                "realtime_factor_batch": round(realtime, 1),
                "plant_batch_samples_s_6_6deg": round(results["plant_batch_6.6"]),
                "plant_batch_samples_s_19_9deg": round(results["plant_batch_19.9"]),
                "aero_only_samples_s": round(
                    min(results["aero_only_6.6"], results["aero_only_19.9"])
                ),
                "plant_construct_s": round(construct_s, 3),
            }
        )
    )


if __name__ == "__main__":
    main()

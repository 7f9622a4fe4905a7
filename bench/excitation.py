"""Excitation benchmark: design and render the paper's campaign plan, crest factors of its
multisine realizations and sines (with and without crest-factor reduction), and the simulated
actuator's step rate (it must run far faster than 200 samples/s real time).

Run: .venv/bin/python bench/excitation.py
The last line is one JSON object: design_s, design_crest_reduced_s, render_s, json_s,
total_samples, duration_s, crest_factors, actuator_samples_per_s.
"""

import json
import math
import statistics
import time

import numpy as np

from multisine_gen import default_plan, plan_from_json, plan_to_json
from pitch_actuator import ActuatorModel


def _best_of(repeats: int, work: object) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        work()  # type: ignore[operator]
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    design_s = _best_of(5, lambda: default_plan(seed=0))
    design_crest_s = _best_of(3, lambda: default_plan(seed=0, crest_factor_reduction=True))
    plan = default_plan(seed=0)
    reduced = default_plan(seed=0, crest_factor_reduction=True)
    # command_deg() caches; time a fresh render of every segment instead.
    render_s = _best_of(5, lambda: np.concatenate([plan.segment_samples(s) for s in plan.segments]))
    text = plan_to_json(plan)
    json_s = _best_of(5, lambda: plan_from_json(text))

    crest: dict[str, float] = {}
    for lv, lv_reduced in zip(plan.levels, reduced.levels, strict=True):
        for m, (ms, ms_reduced) in enumerate(
            zip(lv.realizations, lv_reduced.realizations, strict=True)
        ):
            name = f"multisine_level{lv.level}_offset{lv.offset_deg:g}_r{m}"
            crest[name] = round(ms.crest_factor(), 4)
            crest[name + "_reduced"] = round(ms_reduced.crest_factor(), 4)
    for test in plan.sines:
        name = f"sine_level{test.level}_{test.sine.frequency_hz:g}Hz"
        crest[name] = round(test.sine.crest_factor(), 4)

    model = ActuatorModel(seed=0)
    n = 40_000
    k = np.arange(n)
    commands = np.radians(10.0 + 2.4 * np.sin(2 * np.pi * 1.0 * k / 200.0)).tolist()
    t = time.perf_counter()
    for c in commands:
        model.step(c)
    actuator_rate = n / (time.perf_counter() - t)

    print(
        f"default plan: {plan.total_samples} samples, {plan.duration_s / 60:.1f} min, "
        f"{len(plan.segments)} segments, JSON {len(text) / 1024:.0f} KiB"
    )
    print(f"design            {design_s * 1e3:8.1f} ms")
    print(f"design (crest-reduced multisines) {design_crest_s * 1e3:8.1f} ms")
    print(f"render all samples {render_s * 1e3:7.1f} ms")
    print(f"rebuild from JSON {json_s * 1e3:8.1f} ms")
    ms_cf = [v for key, v in crest.items() if key.startswith("multisine") and "reduced" not in key]
    ms_cf_red = [v for key, v in crest.items() if key.endswith("_reduced")]
    print(
        f"multisine crest factor: random phases {min(ms_cf):.2f}…{max(ms_cf):.2f} "
        f"(median {statistics.median(ms_cf):.2f}); reduced {min(ms_cf_red):.2f}…"
        f"{max(ms_cf_red):.2f}; sines {math.sqrt(2):.3f} (√2)"
    )
    for key, value in crest.items():
        print(f"  {key:42s} {value:.3f}")
    print(
        f"simulated actuator: {actuator_rate:,.0f} samples/s "
        f"({actuator_rate / 200:.0f}× real time at 200 Hz)"
    )
    print(
        json.dumps(
            {
                "design_s": round(design_s, 5),
                "design_crest_reduced_s": round(design_crest_s, 5),
                "render_s": round(render_s, 5),
                "json_s": round(json_s, 5),
                "total_samples": plan.total_samples,
                "duration_s": plan.duration_s,
                "crest_factors": crest,
                "actuator_samples_per_s": round(actuator_rate),
            }
        )
    )


if __name__ == "__main__":
    main()

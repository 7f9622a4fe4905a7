"""Identifier memory across realizations: the refit jobs of a whole campaign in one process.

The plan is simulated in process (aero_rig.simulation), then the identifier's refit worker job
(aero_identification.refit_worker.refit) runs as the node runs it: after each completed
multisine realization on the data received so far (a full refit), after each sine test on the
same data (validation only), and the final one; then ``--repeat`` more full refits of the
complete data, to show where the resident size settles. Each job's input is unpickled first,
as in the worker. Printed per job: resident size at its start (input included) and its peak
[MB] (/proc/self/status VmRSS, VmHWM reset per job), and its CPU time.

    .venv/bin/python bench/identifier_memory.py [--plan default] [--repeat 6]

Last line: JSON with start_mb and peak_mb per job, and the spread of both over the campaign's
full refits and over the repeats.
"""

import argparse
import json
import pickle
import time

import numpy as np

from aero_identification import refit_worker
from aero_identification.hyperparameters import IdentificationConfig
from aero_identification.period_assembly import CampaignAssembler
from aero_rig.simulation import simulate_plan
from multisine_gen.campaigns import default_plan, short_plan
from multisine_gen.plan import ExperimentPlan


def refit_points(assembler: CampaignAssembler, plan: ExperimentPlan) -> list[tuple[int, bool, str]]:
    """(end sample index, models change, label) of each refit the node starts, in order."""
    points = []
    for seg in plan.segments:
        end = seg.stop_k
        if seg.kind == "multisine" and seg.level is not None and seg.realization is not None:
            block = assembler.blocks[(seg.level, seg.realization)]
            if seg.period == block.P - 1:
                label = f"level {seg.level} realization {seg.realization}"
                points.append((end, True, label))
        elif seg.kind == "sine":
            points.append((end, False, f"sine {seg.frequency_hz:g} Hz"))
    return points


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plan", choices=("default", "short"), default="default")
    parser.add_argument("--repeat", type=int, default=6, help="full refits after the campaign")
    args = parser.parse_args()
    t0 = time.perf_counter()
    run = simulate_plan(default_plan(seed=0) if args.plan == "default" else short_plan(seed=0))
    print(f"simulated {len(run.cl)} samples in {time.perf_counter() - t0:.1f} s")
    refit_worker.warm_up()
    refit_worker.release_memory()
    baseline = refit_worker.status_mb("VmRSS")
    print(f"worker after warm-up: {baseline:.0f} MB")
    assembler = CampaignAssembler(run.plan, int(run.stamps_ns[0]))
    points = refit_points(assembler, run.plan)
    done = 0
    rows = []
    labels = [(end, not change, False, label) for end, change, label in points]
    labels.append((done, True, True, "final"))
    labels += [(done, False, False, "repeat")] * args.repeat
    for end, reuse, final, label in labels:
        if end > done:
            for channel, values in (("u", run.pitch_deg), ("y", run.cl)):
                assembler.add_many(channel, run.stamps_ns[done:end], values[done:end])
            done = end
        job_input = pickle.loads(pickle.dumps(assembler))  # as the worker receives it
        _, summary = refit_worker.refit(
            job_input, IdentificationConfig(), final, "", reuse_models=reuse
        )
        del job_input
        worker = summary["worker"]
        rows.append((label, reuse, worker["start_mb"], worker["peak_mb"], worker["cpu_s"]))
        print(
            f"{label:<28} {'validation' if reuse else 'refit':<10} start "
            f"{worker['start_mb']:6.0f} MB  peak {worker['peak_mb']:6.0f} MB  "
            f"cpu {worker['cpu_s']:5.2f} s"
        )
    full = [r for r in rows[: len(points) + 1] if not r[1]]
    repeats = rows[len(points) + 1 :]

    def spread(values: list[float]) -> list[float]:
        return [round(float(np.min(values)), 1), round(float(np.max(values)), 1)] if values else []

    figures = {
        "plan": args.plan,
        "baseline_mb": round(baseline, 1),
        "start_mb": [round(r[2], 1) for r in rows],
        "peak_mb": [round(r[3], 1) for r in rows],
        "campaign_full_refit_start_mb": spread([r[2] for r in full]),
        "campaign_full_refit_peak_mb": spread([r[3] for r in full]),
        "repeat_start_mb": spread([r[2] for r in repeats]),
        "repeat_peak_mb": spread([r[3] for r in repeats]),
    }
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The plan's quasi-static sweep as measured: the assembler keeps its samples per branch (left
out, never patched, where one is missing or an anomaly touches it), the dataset and the result
carry it, and the report draws the paper's Fig. 5 from it."""

import json
from pathlib import Path

import numpy as np
import pytest

from aero_identification.campaign_source import campaign_dataset
from aero_identification.dataset import QuasiStaticSweep
from aero_identification.identification_result import IdentificationResult, quasi_static_json
from aero_identification.period_assembly import CampaignAssembler
from aero_identification.report import plot_quasi_static
from multisine_gen.campaigns import build_plan
from multisine_gen.plan import BaselineSweep, ExperimentPlan

T0 = 5_000_000_000


def small_plan() -> ExperimentPlan:
    return build_plan(
        N=800, f_min_hz=0.25, f_max_hz=2.0, offsets_deg=(6.6,), realizations=2, periods=2,
        sine_frequencies_hz=(1.0,), sine_offsets_deg=(5.9,), sine_min_periods=2,
        sine_min_duration_s=0.0, sine_settle_s=0.0,
        baseline=BaselineSweep(peak_deg=12.0, rate_deg_s=4.0), seed=1,
    )  # fmt: skip


def lift(alpha: float, up: bool) -> float:
    """A static curve with a hysteresis: the pitch-down branch 0.2 lower above 10°."""
    return 0.1 * alpha - (0.2 if (not up and alpha > 10.0) else 0.0)


def stamp(plan: ExperimentPlan, k: int) -> int:
    return T0 + round(k * 1e9 / plan.fs)


def test_the_sweep_is_kept_per_branch_and_gaps_are_left_out(tmp_path: Path) -> None:
    plan = small_plan()
    sweep = [s for s in plan.segments if s.kind == "baseline"]
    assert [s.direction for s in sweep] == ["up", "down"]
    up, down = sweep
    command = plan.command_deg()
    asm = CampaignAssembler(plan, T0)
    missing = up.start_k + 7  # one pitch sample of the up branch never arrives
    end = down.start_k + down.length - 1
    for k in range(end):
        if k != missing:
            asm.add("u", stamp(plan, k), float(command[k]))
        asm.add("y", stamp(plan, k), lift(float(command[k]), k < down.start_k))
    assert asm.baseline_sweep(final=False) is None  # its last sample is not in yet
    asm.add("u", stamp(plan, end), float(command[end]))
    asm.add("y", stamp(plan, end), lift(float(command[end]), False))
    assert asm.baseline_sweep(final=False) is not None
    for k in range(end + 1, plan.total_samples):
        asm.add("u", stamp(plan, k), float(command[k]))
        asm.add("y", stamp(plan, k), 0.1 * float(command[k]))
    # An anomaly over 10 samples of the pitch-down branch.
    asm.add_anomaly("a1", stamp(plan, down.start_k + 20), stamp(plan, down.start_k + 29), "lost")
    dataset = campaign_dataset(asm, final=True)
    qs = dataset.quasi_static
    assert qs is not None
    assert qs.left_out == 11
    assert qs.alpha_up.size == up.length - 1 and qs.alpha_down.size == down.length - 10
    assert qs.rate_deg_s == pytest.approx(4.0, rel=0.01)
    assert np.allclose(qs.cl_up, 0.1 * qs.alpha_up)  # the up branch: no hysteresis term
    hysteresis = qs.alpha_down > 10.0
    assert np.allclose(qs.cl_down[hysteresis], 0.1 * qs.alpha_down[hysteresis] - 0.2)
    assert any("quasi-static sweep: 11 of its samples" in w for w in dataset.warnings)
    # Binned branches and the static curve (the branches' mean where they differ).
    alpha, _ = qs.branch("down", 0.5)
    assert np.all(np.diff(alpha) > 0) and alpha[-1] == pytest.approx(11.75)
    a_st, cl_st = qs.static_curve(0.5)
    high = (a_st > 10.5) & (a_st < 12.0)  # both branches; the 12.25° bin holds the peak only
    assert np.allclose(cl_st[high], 0.1 * a_st[high] - 0.1, atol=0.03)
    # models.json carries both branches as curves.
    payload = quasi_static_json(qs)
    assert payload["left_out"] == 11 and len(payload["up"]["alpha_deg"]) > 40
    json.dumps(payload, allow_nan=False)


def test_no_sweep_without_a_baseline_and_fig5_is_drawn(tmp_path: Path) -> None:
    plan = build_plan(
        N=800, f_min_hz=0.25, f_max_hz=2.0, offsets_deg=(6.6,), realizations=2, periods=2,
        sine_frequencies_hz=(1.0,), sine_offsets_deg=(5.9,), sine_min_periods=2,
        sine_min_duration_s=0.0, sine_settle_s=0.0, baseline=None, seed=1,
    )  # fmt: skip
    asm = CampaignAssembler(plan, T0)
    assert asm.baseline_sweep(final=True) is None
    assert campaign_dataset(asm, final=True).quasi_static is None

    alpha = np.linspace(0.0, 20.0, 400)
    sweep = QuasiStaticSweep(alpha, 0.1 * alpha, alpha[::-1], 0.09 * alpha[::-1], 0.5)
    path = plot_quasi_static(
        sweep, tmp_path / "fig5.png", [("low", 6.6, 2.4)], [("sine low 1 Hz", 1.2, 10.6)]
    )
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 20_000
    # The report draws it when the result carries a sweep.
    from aero_identification.hyperparameters import IdentificationConfig
    from aero_identification.report import write_report

    result = IdentificationResult(config=IdentificationConfig(), fs=200.0, quasi_static=sweep)
    written = write_report(result, tmp_path / "report")
    assert written["quasi_static"].name == "quasi_static_lift.png"
    models = json.loads((tmp_path / "report" / "models.json").read_text())
    assert models["quasi_static"]["rate_deg_s"] == 0.5

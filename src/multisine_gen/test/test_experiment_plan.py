"""Experiment plan: the paper's campaign as a sample stream, JSON that rebuilds every sample,
seeded, and refused with a message naming the segment when it would harm the rig."""

import json

import numpy as np
import pytest

from multisine_gen.campaigns import build_plan, default_plan, short_plan
from multisine_gen.plan import ExperimentPlan, PlanError
from multisine_gen.plan_format import plan_from_json, plan_to_json, segment_event
from rig_runtime.interface import ActuatorLimits


@pytest.fixture(scope="module")
def campaign() -> ExperimentPlan:
    return default_plan(seed=1)


@pytest.fixture(scope="module")
def short() -> ExperimentPlan:
    return short_plan(seed=1)


def test_default_plan_is_the_papers_campaign(campaign: ExperimentPlan) -> None:
    assert campaign.fs == 200.0
    assert [lv.offset_deg for lv in campaign.levels] == [6.6, 15.7, 19.9]
    for lv in campaign.levels:
        assert lv.std_deg == pytest.approx(2.4)
        assert len(lv.realizations) == 2 and lv.periods == 6 and lv.settle_periods == 1
        ms = lv.realizations[0]
        assert ms.N == 10_000
        lines = np.union1d(ms.excited_lines, ms.detection_lines)  # bin 1 may be a detection line
        np.testing.assert_array_equal(lines, np.arange(1, 100, 2))  # odd lines 0.02 … 1.98 Hz
    sines = {(t.level, t.sine.frequency_hz): t for t in campaign.sines}
    offsets = {0: 5.9, 1: 15.1, 2: 19.3}
    assert set(sines) == {(lv, f) for lv in range(3) for f in (0.4, 1.0, 1.6)}
    for (level, f), test in sines.items():
        assert test.sine.amplitude_deg == 4.7 and test.sine.offset_deg == offsets[level]
        assert test.periods >= 10 and test.periods / f >= 20.0
        assert test.settle_periods >= 1
    up, down = (s for s in campaign.segments if s.kind == "baseline")
    assert up.direction == "up" and up.end_deg == 30.0 and down.end_deg == campaign.rest_deg
    assert up.rate_deg_s == pytest.approx(0.52, rel=1e-3)
    assert 35 * 60 < campaign.duration_s < 45 * 60


def test_segments_tile_the_command_and_carry_what_cuts_periods(campaign: ExperimentPlan) -> None:
    u = campaign.command_deg()
    assert u.shape == (campaign.total_samples,)
    k = 0
    for segment in campaign.segments:
        assert segment.start_k == k and segment.length > 0
        k = segment.stop_k
    assert k == u.size
    measured = [s for s in campaign.segments if s.kind == "multisine"]
    assert len(measured) == 3 * 2 * 6
    for s in measured:
        assert s.level is not None and s.realization is not None
        level = campaign.levels[s.level]
        period = level.realizations[s.realization].period()
        assert s.samples_per_period == s.length == 10_000 and s.period in range(6)
        np.testing.assert_array_equal(u[s.start_k : s.stop_k], period)
    settles = [s for s in campaign.segments if s.kind == "settle" and s.excitation == "multisine"]
    assert len(settles) == 6
    for s in [x for x in campaign.segments if x.kind == "sine"]:
        assert s.sine_test is not None and s.samples_per_period is not None
        test = campaign.sines[s.sine_test]
        assert s.frequency_hz == test.sine.frequency_hz and s.amplitude_deg == 4.7
        assert s.length == s.periods * s.samples_per_period
        np.testing.assert_array_equal(u[s.start_k : s.stop_k], test.sine.samples(s.periods))


def test_plan_starts_and_ends_at_rest_with_limited_ramps(campaign: ExperimentPlan) -> None:
    u = campaign.command_deg()
    assert abs(u[0] - campaign.rest_deg) <= 0.53 / campaign.fs
    assert u[-1] == campaign.rest_deg
    for s in (x for x in campaign.segments if x.kind == "ramp"):
        before = u[s.start_k - 1] if s.start_k else campaign.rest_deg
        steps = np.abs(np.diff(np.concatenate([[before], u[s.start_k : s.stop_k]])))
        assert steps.max() * campaign.fs <= 5.0 + 1e-9
    assert np.abs(np.diff(u)).max() * campaign.fs < campaign.limits.max_rate_deg_s
    assert default_plan(seed=1, include_baseline=False).segments[0].kind == "ramp"
    assert all(s.kind != "baseline" for s in default_plan(1, include_baseline=False).segments)


def test_json_round_trip_rebuilds_every_sample(short: ExperimentPlan) -> None:
    text = plan_to_json(short)
    payload = json.loads(text)
    for key in ("fs", "N", "excited_lines", "detection_lines", "seed", "segments", "levels"):
        assert key in payload
    realization = payload["levels"][0]["realizations"][1]
    for key in ("amplitudes", "phases", "seed", "excited_lines"):
        assert key in realization
    rebuilt = plan_from_json(text)
    np.testing.assert_array_equal(rebuilt.command_deg(), short.command_deg())
    assert rebuilt.segments == short.segments
    assert plan_to_json(rebuilt) == text


def test_tampered_or_foreign_json_is_refused(short: ExperimentPlan) -> None:
    payload = json.loads(plan_to_json(short))
    payload["levels"][0]["realizations"][0]["phases"][0] += 1.0
    with pytest.raises(PlanError, match="segments disagree"):
        plan_from_json(json.dumps(payload))
    with pytest.raises(PlanError, match="not an experiment plan"):
        plan_from_json('{"format": "something else"}')
    with pytest.raises(PlanError, match="not valid JSON"):
        plan_from_json("{")


def test_plan_is_checked_against_the_contracts_actuator_limits(short: ExperimentPlan) -> None:
    assert short.limits == ActuatorLimits()  # rig_runtime.interface: the one declaration
    payload = json.loads(plan_to_json(short))
    assert payload["limits"] == ActuatorLimits().as_dict()
    payload["limits"]["max_deg"] = payload["limits"]["min_deg"]
    with pytest.raises(PlanError, match=r"min_deg .* must be below max_deg"):
        plan_from_json(json.dumps(payload))


def test_same_seed_same_plan_other_seed_other_phases() -> None:
    a, b, c = short_plan(seed=3), short_plan(seed=3), short_plan(seed=4)
    assert plan_to_json(a) == plan_to_json(b)
    pa = a.levels[0].realizations[0].phases
    pc = c.levels[0].realizations[0].phases
    assert not np.array_equal(pa, pc)
    assert [s.kind for s in a.segments][:5] == [s.kind for s in c.segments][:5]
    r0, r1 = a.levels[1].realizations
    np.testing.assert_array_equal(r0.excited_lines, r1.excited_lines)
    np.testing.assert_array_equal(r0.amplitudes, r1.amplitudes)
    assert not np.array_equal(r0.phases, r1.phases)


def test_short_plan_has_the_same_structure_and_is_short(short: ExperimentPlan) -> None:
    assert short.duration_s < 240.0
    assert [lv.offset_deg for lv in short.levels] == [6.6, 19.9]
    assert all(len(lv.realizations) == 2 and lv.periods == 4 for lv in short.levels)
    ms = short.levels[0].realizations[0]
    assert ms.N == 2000
    np.testing.assert_array_equal(
        np.union1d(ms.excited_lines, ms.detection_lines), np.arange(1, 20, 2)
    )  # odd lines 0.1 … 1.9 Hz
    assert short.baseline is None
    assert {t.sine.frequency_hz for t in short.sines} == {1.0, 1.6}
    kinds = [s.kind for s in short.segments]
    assert kinds[:6] == ["ramp", "settle", "multisine", "multisine", "multisine", "multisine"]


def test_sample_stream_marks_segment_starts_and_ends(short: ExperimentPlan) -> None:
    u = short.command_deg()
    starts, ends, values = [], [], []
    for sample in short.samples():
        values.append(sample.command_deg)
        if sample.starts_segment:
            starts.append((sample.k, sample.segment.index))
        if sample.ends_segment:
            ends.append(sample.k)
    np.testing.assert_array_equal(values, u)
    assert starts == [(s.start_k, s.index) for s in short.segments]
    assert starts == [(k, s.index) for k, s in short.boundaries()]
    assert ends == [s.stop_k - 1 for s in short.segments]
    middle = short.segments[3]
    resumed = list(short.samples(start_k=middle.start_k + 5))
    assert resumed[0].k == middle.start_k + 5 and not resumed[0].starts_segment
    assert len(resumed) == u.size - middle.start_k - 5
    assert short.segment_at(middle.start_k + 5) is middle
    event = segment_event(middle, "start", t0_s=100.0, fs=short.fs)
    assert event["kind"] == "multisine" and event["realization"] == 0 and event["period"] == 1
    assert event["start_stamp_s"] == pytest.approx(100.0 + middle.start_k / short.fs)


def test_plan_beyond_the_actuator_limits_is_refused_naming_the_segment() -> None:
    with pytest.raises(PlanError, match=r"multisine level 1 \(offset 33°\).*above max_deg 35"):
        build_plan(N=2000, f_min_hz=0.1, offsets_deg=(6.6, 33.0), sine_offsets_deg=())
    with pytest.raises(PlanError) as refused:
        short_plan().validate(min_deg=5.0)
    assert any(
        p.startswith("sine level 0 (offset 5.9°), 1.6 Hz") and "below min_deg 5.0°" in p
        for p in refused.value.problems
    )


def test_empty_plan_is_refused() -> None:
    with pytest.raises(PlanError, match="nothing to command"):
        ExperimentPlan(fs=200.0)


def test_plan_above_nyquist_is_refused_naming_the_part() -> None:
    with pytest.raises(PlanError, match=r"multisine levels: .*at or above fs/2 = 100"):
        build_plan(N=2000, f_min_hz=0.1, f_max_hz=100.0)
    with pytest.raises(PlanError, match=r"sine level 0 \(offset 5\.9°\), 150 Hz: .*fs/2"):
        build_plan(N=2000, f_min_hz=0.1, sine_frequencies_hz=(1.0, 150.0))


def test_plan_too_fast_for_the_actuator_is_refused_naming_the_segment(
    short: ExperimentPlan,
) -> None:
    # A 4.7° sine at 1.6 Hz peaks at 2π·1.6·4.7 ≈ 47 °/s.
    with pytest.raises(PlanError) as refused:
        short.validate(max_rate_deg_s=40.0)
    assert any("1.6 Hz" in p and "rate reaches 47" in p for p in refused.value.problems)
    assert "°/s above the limit 40" in str(refused.value)
    with pytest.raises(PlanError, match="above the limit 40"):
        short.validate(ActuatorLimits(max_rate_deg_s=40.0))  # a node passes its limits record
    short.validate(ActuatorLimits(max_rate_deg_s=60.0))
    with pytest.raises(PlanError, match=r"ramps: ramp_rate_deg_s 10.0°/s exceeds"):
        short.validate(max_rate_deg_s=8.0)
    with pytest.raises(PlanError, match="rate reaches"):
        build_plan(
            N=2000, f_min_hz=0.1, sine_offsets_deg=(), limits=ActuatorLimits(max_rate_deg_s=20.0)
        )

"""The campaign pipeline on an in-process simulation of the short plan (no middleware)."""

import dataclasses
import json
import math
import socket
from typing import Any

import numpy as np
import pytest

from aero_identification import estimation_sets, pipeline, pnlss_training
from aero_identification.campaign_source import campaign_dataset
from aero_identification.hyperparameters import IdentificationConfig
from aero_identification.identification_result import IdentificationResult
from aero_identification.period_assembly import CampaignAssembler
from aero_rig.simulation import T0_NS as T0
from aero_rig.simulation import simulate_plan
from multisine_gen.campaigns import short_plan
from multisine_gen.plan import ExperimentPlan
from wing_sim.wing_params import wing_params_preset


def identify(
    asm: CampaignAssembler, config: IdentificationConfig, final: bool = False, **kw: Any
) -> IdentificationResult:
    """The identifier's chain: the campaign source adapter, then the one pipeline."""
    dataset = campaign_dataset(asm, final, config.min_periods)
    return pipeline.identify(dataset, config, final, **kw)


@pytest.fixture(scope="module")
def campaign() -> tuple[ExperimentPlan, np.ndarray, np.ndarray, np.ndarray]:
    # The release-0.1 wing (repeatable high-offset periods): the identification targets below
    # are testable on it (see tests/test_campaign.py, WING).
    run = simulate_plan(short_plan(seed=0), seed=0, params=wing_params_preset("repeatable_stall"))
    return run.plan, run.stamps_ns, run.pitch_deg, run.cl


# The final identification for the tests of the data-quality account and of the identifier's
# worker: what they check does not depend on the models, so no structure scan and no
# clustering ablation (both tested below and in every campaign); a few LM iterations.
ACCOUNT_CONFIG = IdentificationConfig(max_iter=2, scan=False, clustering_ablation=False)
NO_SCAN = ("-p", "scan:=false", "-p", "clustering_ablation:=false")  # the same, as node parameters


def _assemble(campaign, drop: int | None = None, duplicate: int | None = None) -> CampaignAssembler:
    plan, stamps, u, y = campaign
    asm = CampaignAssembler(plan, T0)
    keep = np.ones(len(stamps), dtype=bool)
    if drop is not None:
        keep[drop] = False
    asm.add_many("u", stamps[keep], u[keep])
    asm.add_many("y", stamps, y)
    if duplicate is not None:  # the same stamp again with another value: a conflict
        asm.add("y", int(stamps[duplicate]), float(y[duplicate]) + 0.01)
    return asm


def test_periods_with_gaps_or_duplicates_are_excluded_and_reported(campaign) -> None:
    plan = campaign[0]
    seg = next(s for s in plan.segments if s.kind == "multisine" and s.period == 1)
    asm = _assemble(campaign, drop=seg.start_k + 17, duplicate=seg.start_k + 40)
    block = asm.blocks[(seg.level, seg.realization)]
    valid = block.period_valid()
    assert not valid[1] and valid[0] and valid[2]
    problem = block.period_problem(1)
    assert "1 pitch samples missing" in problem and "1 C_l samples duplicated" in problem
    result = identify(asm, IdentificationConfig(max_iter=5))
    excluded = next(lv for lv in result.levels.values() if lv.record.key == str(seg.level)).excluded
    assert any("period 1" in e and "missing" in e for e in excluded)


def test_identification_of_the_short_campaign(campaign) -> None:
    result = identify(_assemble(campaign), IdentificationConfig(), final=True)
    assert result.level_names == ["low", "high"]
    assert result.sine_freqs == [1.0, 1.6]
    e_all, e_1 = result.errors_all, result.errors_level1
    for f in (1.0, 1.6):
        # Low level: every model near the gust floor; high level: PNLSS beats both linear models.
        assert e_all[("PNLSS", "low", f)] < 0.15
        assert e_all[("PNLSS", "high", f)] < e_all[("BLA SS", "high", f)]
        assert e_all[("PNLSS", "high", f)] * 2 < e_1[("BLA SS", "high", f)]
    markdown, csv = result.tables()["table1_all_levels"]
    # The line naming the selected model, then the table.
    assert markdown.startswith(f"selected: {result.selection['class']} (")
    assert markdown.splitlines()[2] == "| model | low 1 Hz | low 1.6 Hz | high 1 Hz | high 1.6 Hz |"
    assert csv.count("\n") >= 3
    assert json.dumps(result.to_json_dict(), allow_nan=True)


def test_refits_reuse_unchanged_models_exactly(campaign) -> None:
    asm = _assemble(campaign)
    # No stage of the final models' own (the scan, the ablation: tested below): every refit
    # fits the final models, and the final call takes them over.
    single = IdentificationConfig(scan=False, clustering_ablation=False)
    first = identify(asm, single)
    assert first.final_models
    again = identify(asm, single, previous=first)
    assert again.pnlss_level1 is first.pnlss_level1  # level 1 unchanged: not refitted
    validated = identify(asm, single, final=True, models_from=first)
    assert validated.pnlss_all is first.pnlss_all
    assert (
        validated.errors_all == first.errors_all and validated.errors_level1 == first.errors_level1
    )


def test_a_sine_still_streaming_is_no_warning_until_the_final_refit(campaign) -> None:
    plan, stamps, u, y = campaign
    sine = next(s for s in plan.segments if s.kind == "sine")
    half = sine.start_k + sine.length // 2
    asm = CampaignAssembler(plan, T0)
    asm.add_many("u", stamps[:half], u[:half])
    asm.add_many("y", stamps[:half], y[:half])
    config = ACCOUNT_CONFIG
    interim = identify(asm, config)
    assert not any("not used for validation" in w for w in interim.warnings), interim.warnings
    final = identify(asm, config, final=True, models_from=interim)
    assert any(f"sine {sine.frequency_hz:g} Hz" in w for w in final.warnings), final.warnings
    # A gap in a record whose last sample is in is a fault at once.
    end = sine.start_k + sine.length
    gap = np.ones(end, dtype=bool)
    gap[sine.start_k + 5] = False
    asm = CampaignAssembler(plan, T0)
    asm.add_many("u", stamps[:end][gap], u[:end][gap])
    asm.add_many("y", stamps[:end], y[:end])
    gapped = identify(asm, config)
    assert any("1 pitch samples missing" in w for w in gapped.warnings), gapped.warnings
    assert any("1 pitch samples missing" in e for e in gapped.excluded_sines)


def test_anomalies_exclude_what_they_touch_and_the_table_says_so(campaign) -> None:
    plan = campaign[0]
    seg = next(s for s in plan.segments if s.kind == "multisine" and s.period == 2)
    sine = next(s for s in plan.segments if s.kind == "sine")
    asm = _assemble(campaign)
    clean = identify(asm, ACCOUNT_CONFIG, final=True)
    assert clean.data_quality["clean"]
    # No data-quality note: the selection's line, then the table.
    assert clean.tables()["table1_all_levels"][0].split("\n\n")[1].startswith("| model")
    stamp = lambda k: T0 + round(k * 1e9 / plan.fs)  # noqa: E731
    # A free run over the last sample of period 2 and the first of period 3 of one block ...
    k = seg.start_k + seg.length - 1
    asm.add_anomaly("sim_actuator/free_run/1", stamp(k), stamp(k + 1), "sim_actuator free_run")
    # ... and an episode still open from inside the first sine record to the end.
    asm.add_anomaly("lift/invalid/1", stamp(sine.start_k + 3), None, "lift invalid")
    block = asm.blocks[(seg.level, seg.realization)]
    assert list(np.flatnonzero(~block.period_valid())) == [2, 3]
    assert "sim_actuator free_run" in block.period_problem(2)
    later = [r for r in asm.sines.values() if r.mark]
    assert later and all(r.mark == "lift invalid" for r in later)
    result = identify(asm, ACCOUNT_CONFIG, final=True)
    quality = result.data_quality
    assert not quality["clean"] and len(quality["anomalies"]) == 2
    assert any("period 2" in p and "free_run" in p for p in quality["excluded_periods"])
    assert quality["excluded_sines"] and all("lift invalid" in e for e in quality["excluded_sines"])
    for markdown, _ in result.tables().values():
        assert markdown.startswith("> **Data not clean**")
    # Closed again before the sine: the sines are back, the periods stay excluded.
    asm.add_anomaly("lift/invalid/1", stamp(0), stamp(1), "lift invalid")
    assert not any(r.mark for r in asm.sines.values())
    assert not block.period_valid()[2]


def test_a_sample_delivered_twice_excludes_nothing(campaign) -> None:
    plan, stamps, u, y = campaign
    seg = next(s for s in plan.segments if s.kind == "multisine" and s.period == 1)
    asm = _assemble(campaign)
    k = seg.start_k + 40
    asm.add("y", int(stamps[k]), float(y[k]))  # a transport redelivery: identical
    asm.add("u", int(stamps[k]), float(u[k]))
    assert asm.blocks[(seg.level, seg.realization)].period_valid().all()
    result = identify(asm, ACCOUNT_CONFIG, final=True)
    assert result.data_quality["clean"]
    assert result.data_quality["samples"]["C_l"]["redelivered"] == 1


def test_every_plan_sample_is_accounted_for(campaign) -> None:
    plan, stamps, u, y = campaign
    asm = _assemble(campaign, drop=10, duplicate=20)
    accounting = asm.sample_accounting(final=True)
    total = plan.total_samples
    assert accounting["pitch"] == {
        "expected": total,
        "received": total - 1,
        "missing": 1,
        "duplicated": 0,
        "redelivered": 0,
        "outside_plan": 0,
    }
    assert accounting["C_l"]["duplicated"] == 1 and accounting["C_l"]["missing"] == 0
    # The same sample delivered again (same stamp, same value): counted, harmless.
    asm.add("y", int(stamps[30]), float(y[30]))
    accounting = asm.sample_accounting(final=True)
    assert accounting["C_l"]["redelivered"] == 1 and accounting["C_l"]["duplicated"] == 1
    # Before the end, only what both channels have reached is expected.
    partial = CampaignAssembler(plan, T0)
    partial.add_many("u", stamps[:100], u[:100])
    partial.add_many("y", stamps[:90], y[:90])
    partial.add("y", int(stamps[-1]) + 10**9, 0.0)  # after the plan's end
    counts = partial.sample_accounting()
    assert counts["pitch"]["expected"] == 90 and counts["C_l"]["missing"] == 0
    assert counts["C_l"]["outside_plan"] == 1


def test_identifier_names_a_hole_in_the_plan_index_at_once(campaign, monkeypatch) -> None:
    """Samples a writer dropped (the identifier paused past the DDS lease) show as a gap in the
    plan index as soon as the next sample arrives: logged, and in the next status."""
    from aero_identification.identifier_node import IdentifierNode
    from rig_testing.processes import graph_env, join_graph

    join_graph(graph_env(), monkeypatch.setenv)
    plan, stamps, u, _ = campaign
    ident = IdentifierNode(["--ros-args", "-p", "use_worker:=false"])
    statuses: list[dict[str, str]] = []
    ident.status_pub.publish = lambda msg: statuses.append(
        {kv.key: kv.value for st in msg.status for kv in st.values}
    )
    try:
        intake = ident.session.intake
        intake.assembler = CampaignAssembler(plan, T0)
        for k in [*range(10), *range(30, 40)]:
            intake.add("u", int(stamps[k]), float(u[k]))
        assert intake.gaps == {"u": [(10, 29)], "y": []}
        ident.publish_status()
        assert statuses[-1]["pitch gaps"].startswith("1 gap(s), 20 plan samples never arrived")
        assert "C_l gaps" not in statuses[-1]
    finally:
        ident.close()


def test_identifier_survives_its_worker_dying(campaign, monkeypatch, tmp_path) -> None:
    """The refit worker killed mid-job: the error is reported, the previous models are kept,
    a new worker is started, and the next refit (a full one) succeeds."""
    import os
    import signal

    from aero_identification.identification_session import PendingRefit
    from aero_identification.identifier_node import IdentifierNode
    from rig_testing.processes import graph_env, join_graph, wait_for

    join_graph(graph_env(), monkeypatch.setenv)
    ident = IdentifierNode(["--ros-args", "-p", "max_iter:=3", *NO_SCAN])
    session = ident.session
    try:
        session.intake.assembler = _assemble(campaign)
        session.start_refit(False, "first")
        assert wait_for(lambda: session.job is not None and session.job.future.done(), 120)
        session.collect()
        assert session.refits == 1 and not session.errors
        session.schedule.models_stale = False  # a sine-only refit: the kept models are reused
        session.start_refit(False, "second")
        assert session.worker.executor is not None
        (pid,) = [p.pid for p in session.worker.executor._processes.values()]
        assert pid is not None  # a started worker
        os.kill(pid, signal.SIGKILL)
        assert wait_for(lambda: session.job is not None and session.job.future.done(), 60)
        session.collect()
        assert session.refits == 1 and "refit failed (second)" in session.errors[-1]
        assert session.schedule.models_stale  # the new worker has no models: a full refit
        # The job the worker died in is queued again (a final identification is never lost).
        assert session.schedule.pending[-1] == PendingRefit(-1, False, "second", True)
        session.start_refit(True, "third")
        assert wait_for(lambda: session.job is not None and session.job.future.done(), 120)
        session.collect()
        assert session.refits == 2 and session.final_done
        assert session.last_summary is not None and session.last_summary["complete"]
    finally:
        ident.close()


def test_an_anomaly_during_the_final_identification_runs_it_again(
    campaign, monkeypatch, tmp_path
) -> None:
    """The final refit works on a snapshot: an anomaly that arrives while it runs must not be
    left out of the report the campaign ends with."""
    from types import SimpleNamespace

    from aero_identification.identifier_node import IdentifierNode
    from rig_runtime.anomaly import Anomaly
    from rig_testing.processes import graph_env, join_graph, wait_for

    join_graph(graph_env(), monkeypatch.setenv)
    args = ["--ros-args", "-p", "max_iter:=3", "-p", "exit_after_final:=false", *NO_SCAN]
    ident = IdentifierNode(args)
    session = ident.session
    try:
        plan, stamps = campaign[0], campaign[1]
        seg = next(s for s in plan.segments if s.kind == "multisine" and s.period == 1)
        session.intake.assembler = _assemble(campaign)
        session.start_refit(True, "plan end")
        late = Anomaly("lift/invalid/1", "lift", "invalid", int(stamps[seg.start_k + 5]), None)
        ident.on_anomaly(SimpleNamespace(data=late.to_json()))
        assert wait_for(lambda: session.job is not None and session.job.future.done(), 120)
        session.collect()
        pending = session.schedule.pending
        assert not session.final_done and pending and pending[-1].final
        session.on_timer()  # starts the final identification again, with the anomaly
        assert session.job is not None
        assert wait_for(lambda: session.job is not None and session.job.future.done(), 120)
        session.collect()
        assert session.final_done and session.last_summary is not None
        quality = session.last_summary["data_quality"]
        assert not quality["clean"] and any("lift invalid" in a for a in quality["anomalies"])
    finally:
        ident.close()


def test_final_identification_by_the_structure_scan(campaign, tmp_path) -> None:
    """config.scan: the all-levels PNLSS is the scan's choice, and the report holds the scan."""
    from aero_identification.report import write_report

    asm = _assemble(campaign)
    config = IdentificationConfig(
        scan=True, scan_nx=(1, 2), scan_degrees=((2,), (2, 3)), scan_max_iter=10, scan_workers=1,
        scan_splits=2,
    )  # fmt: skip
    result = identify(asm, config, final=True)
    # nx × degree sets × equations × the two LM starts (linear, output least squares)
    assert result.scan is not None and len(result.scan.rows) == 2 * 2 * 2 * 2
    assert {r.start for r in result.scan.rows} == {"linear", "output_ls"}
    assert result.pnlss_all is result.scan.best
    # The cross-fit (scan_splits 2): each candidate fitted again with the other realization of
    # every level held out (estimation_sets fold 1: training and held-out sets swapped); the kept
    # models are those of the one-split scan.
    estimation = [lv for lv in result.levels.values() if lv.role == "estimation"]
    train, held, _ = estimation_sets.estimation_sets(estimation, config)
    train_1, held_1, how_1 = estimation_sets.estimation_sets(estimation, config, fold=1)
    assert held is not None and held_1 is not None and how_1 == "realization 0 of each level"
    np.testing.assert_array_equal(train_1.y, held.y)
    np.testing.assert_array_equal(held_1.y, train.y)
    assert all(len(r.split_errors) == 2 for r in result.scan.rows if r.status == "ok")
    one = identify(asm, dataclasses.replace(config, scan_splits=1), final=True)
    assert one.scan is not None and all(r.split_errors == () for r in one.scan.rows)
    for a, b, ma, mb in zip(one.scan.rows, result.scan.rows, one.scan.models, result.scan.models,
                            strict=True):  # fmt: skip
        assert b.split_errors[:1] == (a.validation_error,) or a.status != "ok"
        if ma is None or mb is None:
            assert ma is mb
        else:
            np.testing.assert_array_equal(ma.E, mb.E)
    assert ("PNLSS", "high", 1.0) in result.errors_all
    interim = identify(asm, config)  # online refits keep the single structure
    assert interim.scan is None and interim.pnlss_all is not None
    # The final identification after a sine-only refit still runs the scan (the online node's
    # last refit reused the models of an online refit, which had none) ...
    final = identify(asm, config, final=True, models_from=interim)
    assert final.scan is not None and final.pnlss_all is final.scan.best
    # ... and a re-validation of a scanned result reuses it.
    again = identify(asm, config, final=True, models_from=final)
    assert again.scan is final.scan and again.pnlss_all is final.pnlss_all
    written = write_report(result, tmp_path)
    assert (tmp_path / "pnlss_scan.md").read_text().count("(selected)") == 1
    assert (tmp_path / "pnlss_scan.csv").read_text().count("\n") == 17
    assert written["pnlss_scan_plot"].stat().st_size > 10_000
    payload = json.loads((tmp_path / "models.json").read_text())
    assert sum(row["selected"] for row in payload["pnlss_scan"]["table"]) == 1


def test_final_models_fitted_while_the_last_sines_stream_are_only_validated_at_the_end(
    campaign,
) -> None:
    """final_models (the identifier's refit once every multisine period of the plan is in):
    the structure scan and the clustering ablation run then, and the final call takes their
    models over and only validates: the same tables as a final identification from scratch."""
    plan, stamps, u, y = campaign
    asm = _assemble(campaign)
    end = asm.multisine_end_k + 1
    assert 0 < end < len(stamps) and any(
        s.kind == "sine" and s.start_k >= end for s in plan.segments
    )
    streaming = CampaignAssembler(plan, T0)
    streaming.add_many("u", stamps[:end], u[:end])
    streaming.add_many("y", stamps[:end], y[:end])
    config = IdentificationConfig(
        max_iter=5, scan=True, scan_nx=(1,), scan_degrees=((2,),), scan_max_iter=5, scan_workers=1
    )
    early = identify(streaming, config, final_models=True)
    assert early.final_models and not early.complete
    assert early.scan is not None and early.no_clustering is not None
    # A refit of the sines in between (validation only) keeps them final models.
    between = identify(streaming, config, models_from=early)
    assert between.final_models and between.scan is early.scan
    final = identify(asm, config, final=True, models_from=between)
    assert final.complete and final.scan is early.scan and final.pnlss_all is early.pnlss_all
    assert final.timings_s["pnlss"] == 0.0  # nothing fitted
    scratch = identify(asm, config, final=True)
    assert scratch.scan is not early.scan
    assert (
        final.tables() == scratch.tables() and final.errors_all
    )  # Table 1, with clustering and without
    # An online refit's models are not final models: the final call fits them afresh.
    interim = identify(streaming, config)
    assert not interim.final_models and interim.scan is None
    refitted = identify(asm, config, final=True, models_from=interim)
    assert refitted.scan is not None and refitted.tables() == scratch.tables()


# A small scan (one candidate structure, 10 LM iterations) and 3 replicates: what the bootstrap
# tests need, in seconds.
BOOTSTRAP_CONFIG = IdentificationConfig(
    bootstrap=3, clustering_ablation=False, scan_nx=(1,), scan_degrees=((2,),),
    scan_max_iter=10, scan_workers=1,
)  # fmt: skip


def test_final_identification_with_the_estimation_bootstrap(campaign, tmp_path) -> None:
    """config.bootstrap: each Table 1 cell gets the std over refits on bootstrap replicates of
    the estimation periods, in the result, both tables and models.json; the estimate itself is
    the one without the bootstrap."""
    from aero_identification.report import write_report

    asm = _assemble(campaign)
    config = BOOTSTRAP_CONFIG
    result = identify(asm, config, final=True)
    boot = result.bootstrap
    assert result.scan is not None  # the replicates refit the scan's kept structure
    assert boot is not None and boot.replicates == 3 and boot.seconds > 0
    assert set(boot.spreads_all) == set(result.errors_all)
    assert set(boot.spreads_level1) == set(result.errors_level1)
    # The refits differ from the estimate and from each other: every spread is positive.
    assert all(math.isfinite(s) and s > 0 for s in boot.spreads_all.values())
    for (model, level, f), n in boot.failed_all.items():  # a failed refit is named
        assert (n == 0) == (f"{model} at {level} {f:g} Hz" not in " ".join(result.warnings))
    plain = identify(asm, dataclasses.replace(config, bootstrap=0), final=True)
    assert plain.bootstrap is None and plain.errors_all == result.errors_all
    write_report(result, tmp_path)
    md = (tmp_path / "table1_all_levels.md").read_text()
    # The note's two ±, then two per cell of the five rows with spreads (BLA FRF, BLA SS, PNLSS,
    # B-spline LPV, selected; the noise floor has none), four cells each.
    assert "std over 3 bootstrap refits" in md and md.count("±") == 2 + 2 * 5 * 4
    header = (tmp_path / "table1_all_levels.csv").read_text().splitlines()[0]
    assert header.count("estimation std") == 4 and header.count("estimation mean") == 4
    errors = json.loads((tmp_path / "models.json").read_text())["errors"]
    assert errors["bootstrap_replicates"] == 3
    rows = {(m, lv, f): s for m, lv, f, s in errors["all_levels_bootstrap_std"]}
    assert rows[("PNLSS", "high", 1.6)] == boot.spreads_all[("PNLSS", "high", 1.6)]
    # The replicates' mean per cell (bootstrap bias = mean − error), in the result and JSON.
    assert set(boot.means_all) == set(result.errors_all)
    assert all(math.isfinite(m) and m > 0 for m in boot.means_all.values())
    means = {(m, lv, f): v for m, lv, f, v in errors["level1_bootstrap_mean"]}
    assert means == {k: v if math.isfinite(v) else None for k, v in boot.means_level1.items()}


def test_estimation_bootstrap_refits_on_the_given_dask_client(campaign) -> None:
    """identify(client=...): the bootstrap's PNLSS refits run on the scan's executor (one Dask
    task per refit, here an in-process worker) and give the spreads of the serial run."""
    from dask.distributed import Client, LocalCluster

    asm = _assemble(campaign)
    config = BOOTSTRAP_CONFIG
    serial = identify(asm, config, final=True)
    said: list[str] = []
    with (
        LocalCluster(
            n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        on_dask = identify(asm, config, final=True, client=client, log=said.append)
    line = next(m for m in said if m.startswith("Table 1 estimation bootstrap"))
    assert "3 replicates, 6 PNLSS refits (Dask client" in line, line
    assert serial.bootstrap is not None and on_dask.bootstrap is not None
    assert on_dask.bootstrap.spreads_all == serial.bootstrap.spreads_all
    assert on_dask.bootstrap.spreads_level1 == serial.bootstrap.spreads_level1


def test_scan_scheduler_runs_the_scan_and_the_bootstrap_or_says_it_cannot_be_reached(
    campaign, monkeypatch: pytest.MonkeyPatch
) -> None:
    """config.scan_scheduler (``aero-rig fit --scan-scheduler``): the scan's candidates and the
    bootstrap's refits run as tasks of the Dask scheduler at that address (here a one-worker
    cluster in this process, reached over loopback TCP) and give the serial run's tables. A
    scheduler that cannot be reached costs the scan and the spreads, each named in a warning;
    the identification still finishes with its linear models and Table 1."""
    from dask.distributed import LocalCluster

    asm = _assemble(campaign)
    serial = identify(asm, BOOTSTRAP_CONFIG, final=True)
    said: list[str] = []
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
        host="127.0.0.1", dashboard_address=None,
    ) as cluster:  # fmt: skip
        config = dataclasses.replace(BOOTSTRAP_CONFIG, scan_scheduler=cluster.scheduler_address)
        remote = identify(asm, config, final=True, log=said.append)
    line = next(m for m in said if m.startswith("Table 1 estimation bootstrap"))
    assert "6 PNLSS refits (Dask client" in line, line
    assert remote.scan is not None and serial.scan is not None
    assert "Dask client" in remote.scan.workers, remote.scan.workers

    def timeless(table: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [{k: v for k, v in row.items() if k != "fit_seconds"} for row in table]

    assert timeless(remote.scan.table) == timeless(serial.scan.table)
    # The B-spline LPV scan's grid ran on the same scheduler: the same rows, the same model.
    assert remote.lpv_scan is not None and serial.lpv_scan is not None
    assert timeless(remote.lpv_scan.rows) == timeless(serial.lpv_scan.rows)
    assert remote.errors_all == serial.errors_all
    assert remote.bootstrap is not None and serial.bootstrap is not None
    assert remote.bootstrap.spreads_all == serial.bootstrap.spreads_all

    with socket.socket() as closed:  # a port nothing listens on
        closed.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{closed.getsockname()[1]}"
    monkeypatch.setattr(pnlss_training, "SCHEDULER_CONNECT_S", 2.0)
    config = dataclasses.replace(BOOTSTRAP_CONFIG, scan_scheduler=address)
    lost = identify(asm, config, final=True)
    for what in ("PNLSS structure scan failed", "B-spline LPV (all levels) failed",
                 "Table 1 estimation bootstrap failed"):  # fmt: skip
        assert any(w.startswith(what) for w in lost.warnings), lost.warnings
    assert lost.scan is None and lost.bootstrap is None and lost.lpv_all is None
    assert lost.errors_all and lost.linear_level1 is not None


def test_the_semi_empirical_baseline_is_calibrated_on_the_plans_sweep(campaign, tmp_path) -> None:
    from aero_identification.report import write_report
    from multisine_gen.plan import BaselineSweep

    plan = dataclasses.replace(campaign[0], baseline=BaselineSweep(peak_deg=28.0, rate_deg_s=2.0))
    run = simulate_plan(plan, seed=0, params=wing_params_preset("repeatable_stall"))
    asm = CampaignAssembler(run.plan, T0)
    asm.add_many("u", run.stamps_ns, run.pitch_deg)
    asm.add_many("y", run.stamps_ns, run.cl)
    result = identify(asm, ACCOUNT_CONFIG, final=True)
    model = result.beddoes_leishman
    assert model is not None and result.quasi_static is not None
    # The static curve from the sweep: the paper's slope below the stall (0.104/°, the wing's).
    assert model.static.slope_per_deg == pytest.approx(0.104, rel=0.1)
    cells = {k: v for k, v in result.errors_all.items() if k[0] == "Beddoes-Leishman"}
    assert len(cells) == 4 and all(v < 1.0 for v in cells.values())  # better than the mean
    assert not any(k[0] == "Beddoes-Leishman" for k in result.errors_level1)
    md = result.tables()["table1_all_levels"][0]
    assert (
        "| Beddoes-Leishman |" in md
        and "| Beddoes-Leishman |" not in (result.tables()["table1_level1"][0])
    )
    from aero_identification import model_payload as mm

    for prediction in result.predictions:
        assert mm.BEDDOES_LEISHMAN in dict(mm.prediction_series(prediction))
    written = write_report(result, tmp_path)
    models = json.loads((tmp_path / "models.json").read_text())
    assert models["models"]["beddoes_leishman"]["t_f_s"] == model.t_f_s
    assert "quasi_static" in written
    assert not any("Beddoes-Leishman" in w for w in result.warnings)
    # The same campaign without its sweep: no row, and one warning says why.
    plain = identify(_assemble(campaign), ACCOUNT_CONFIG, final=True)
    assert plain.beddoes_leishman is None
    assert "| Beddoes-Leishman |" not in plain.tables()["table1_all_levels"][0]
    assert sum("Beddoes-Leishman baseline not fitted: the source has no quasi-static sweep" in w
               for w in plain.warnings) == 1  # fmt: skip


def test_the_second_class_and_the_selected_model(campaign, tmp_path) -> None:
    from aero_identification import model_payload as mm
    from aero_identification.report import write_report

    result = identify(_assemble(campaign), ACCOUNT_CONFIG, final=True)
    assert result.lpv_all is not None and result.pnlss_all is not None
    sel = result.selection
    # The selected class is the one of lower error on the held-out periods (never the sines).
    assert sel["class"] == min(sel["validation_errors"], key=sel["validation_errors"].get)
    assert set(sel["validation_errors"]) == {"PNLSS", "B-spline LPV"}
    source = "PNLSS" if sel["class"] == "PNLSS" else "B-spline LPV"
    for (model, level, f), error in result.errors_all.items():
        if model == "selected":
            assert error == result.errors_all[(source, level, f)]
    assert sum(k[0] == "selected" for k in result.errors_all) == 4  # 2 levels × 2 sines
    assert not any(k[0] in ("selected", "B-spline LPV") for k in result.errors_level1)
    # On the held-out periods the second class is never worse than its linear start.
    h = result.lpv_all.history_
    assert h["kept_error"] <= h["linear_start_error"]
    md = result.tables()["table1_all_levels"][0]
    assert md.startswith(f"selected: {sel['class']} (")
    assert "| B-spline LPV |" in md and "| selected |" in md
    for prediction in result.predictions:
        series = dict(mm.prediction_series(prediction))
        assert series[mm.SELECTED] == series[mm.LPV_ALL if source != "PNLSS" else mm.PNLSS_ALL]
    write_report(result, tmp_path)
    models = json.loads((tmp_path / "models.json").read_text())
    assert models["selection"]["class"] == sel["class"]
    assert models["models"]["lpv_all_levels"]["parameters"] == result.lpv_all.n_params
    summary = (tmp_path / "summary.md").read_text()
    assert "## Selected model" in summary and "## B-spline LPV (all levels)" in summary

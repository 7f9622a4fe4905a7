"""Clustering is load-bearing: on a wing whose high-offset periods include some in the
light-stall regime, the pipeline with clustering drops them, and its BLA and PNLSS are better
than the same pipeline without clustering (the ablation every final report carries).

Scenario: the short plan (10 s periods, P = 4) on the default wing with the light-stall
episodes scaled to the short periods (mean 16 s instead of 80 s for 50 s periods); plant seed 2
puts the last period of the high level's estimation realization in the light regime (checked on
the plant's truth, so the scenario cannot drift silently). The all-levels PNLSS is trained on
that realization's mean period.

Not asserted: that clustering lowers the BLA's nonlinear variance. The robust method estimates
var_nl as the excess of the spread between the realizations' FRFs over the spread between
periods. A period in another regime raises both by the same amount in expectation when it is
the only one (M = 2), lowers var_nl when each realization has one (the default campaign's case:
only the period spread grows), and raises it only when the regime falls unevenly on the
realizations; with M = 2 the estimate's own scatter is of the same size. Measured on the default
campaign and explained in docs/plant.md §7.
"""

from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from aero_identification import pipeline
from aero_identification.campaign_source import campaign_dataset
from aero_identification.hyperparameters import IdentificationConfig
from aero_identification.identification_result import IdentificationResult
from aero_identification.period_assembly import CampaignAssembler
from aero_identification.report import write_report
from aero_rig.simulation import T0_NS, SimulatedRun, simulate_plan
from multisine_gen.campaigns import short_plan
from wing_sim.wing_params import WingParams

LIGHT_DWELL_S = 16.0
HIGH = 1  # the short plan's levels: 0 (6.6°, "low"), 1 (19.9°, "high")


def identify(
    asm: CampaignAssembler, config: IdentificationConfig, final: bool = False, **kw: Any
) -> IdentificationResult:
    """The identifier's chain: the campaign source adapter, then the one pipeline."""
    dataset = campaign_dataset(asm, final, config.min_periods)
    return pipeline.identify(dataset, config, final, **kw)


@cache
def _scenario(seed: int) -> tuple[SimulatedRun, CampaignAssembler, IdentificationResult]:
    run = simulate_plan(
        short_plan(seed=0), seed=seed, params=WingParams(light_stall_dwell_s=LIGHT_DWELL_S)
    )
    asm = CampaignAssembler(run.plan, T0_NS)
    asm.add_many("u", run.stamps_ns, run.pitch_deg)
    asm.add_many("y", run.stamps_ns, run.cl)
    return run, asm, identify(asm, IdentificationConfig(scan=False, max_iter=40), final=True)


def _light_periods(run: SimulatedRun, level: int) -> np.ndarray:
    """(P, M) bool: the period's majority regime is the light one (plant truth)."""
    periods = [
        (s.period, s.realization, s.start_k, s.stop_k)
        for s in run.plan.segments
        if s.kind == "multisine" and s.level == level and s.period is not None
    ]
    share = np.zeros((max(p for p, *_ in periods) + 1, 2))
    for period, realization, start, stop in periods:
        share[period, realization] = run.light_stall[start:stop].mean()
    return share > 0.5


def _dropped_periods_are_the_light_ones(seed: int) -> IdentificationResult:
    run, _, result = _scenario(seed)
    light = _light_periods(run, HIGH)
    # At the low offset the wing never stalls, so the regime (present there too) cannot show.
    low, high = result.levels["low"], result.levels["high"]
    assert low.clusters is not None and low.clusters.k == 1
    assert high.clusters is not None and high.clusters.k >= 2
    np.testing.assert_array_equal(high.clusters.keep, ~light)
    plain = result.no_clustering
    assert plain is not None and plain.levels["high"].periods_used == 8
    assert high.periods_used < 8
    # Every kept period is used, P_m in realization m, not the fewest of every realization.
    assert high.bla is not None
    counts = tuple(int(c) for c in high.clusters.keep.sum(axis=0))
    assert high.bla.periods_per_realization == counts
    assert high.periods_used == sum(counts)
    return result


def test_clustering_lowers_the_pnlss_error_on_the_held_out_dominant_periods() -> None:
    result = _dropped_periods_are_the_light_ones(2)
    assert _light_periods(_scenario(2)[0], HIGH)[:, 0].tolist() == [False, False, False, True]
    effect = result.clustering_effect["high"]
    assert effect["pnlss_validation_with"] < effect["pnlss_validation_without"]
    # The dropped period spread its realization's periods: the noise variance of one period's
    # FRF (the BLA's var_noise is that of the mean over M·P periods) falls.
    assert effect["bla_with"]["var_noise_db"] < effect["bla_without"]["var_noise_db"]


def test_every_final_report_carries_the_ablation(tmp_path: Path) -> None:
    result = _scenario(2)[2]
    written = write_report(result, tmp_path)
    no_clustering = (tmp_path / "table1_no_clustering.md").read_text()
    assert no_clustering.startswith("| model | low 1 Hz |")
    assert no_clustering != (tmp_path / "table1_all_levels.md").read_text()
    assert (tmp_path / "table1_no_clustering.csv").exists()
    # 3 + 4 kept periods, all used (the light one dropped)
    assert "| high | 2 | [7, 1] | 7 / 8 |" in (tmp_path / "clustering.md").read_text()
    assert written["clusters_high"].stat().st_size > 0


def test_the_ablation_runs_beside_and_gives_what_it_gives_alone() -> None:
    """The final identification runs its ablation in a thread beside its own fits
    (clustering_ablation.start_ablation): the ablation's messages come from that thread, and
    its tables are byte for byte those of the same configuration without clustering run on its
    own."""
    import dataclasses
    import threading

    _, asm, result = _scenario(2)
    threads: set[str] = set()
    config = IdentificationConfig(scan=False, max_iter=40)
    beside = identify(asm, config, final=True, log=lambda _m: threads.add(
        threading.current_thread().name))  # fmt: skip
    assert any(name.startswith("clustering_ablation") for name in threads), threads
    assert threading.main_thread().name in threads
    plain = dataclasses.replace(config, clustering=False, clustering_ablation=False, bootstrap=0)
    alone = identify(asm, plain, final=True)
    assert beside.no_clustering is not None
    assert beside.no_clustering.tables() == alone.tables()
    # and the clustered identification is the one made without any ablation
    without = identify(asm, dataclasses.replace(config, clustering_ablation=False), final=True)
    for name in ("table1_all_levels", "table1_level1"):
        assert beside.tables()[name] == without.tables()[name] == result.tables()[name]


def test_the_ablation_runs_after_where_two_threads_cannot_share_numba(
    monkeypatch: Any,
) -> None:
    """numba's workqueue layer aborts the process when two threads run parallel kernels at
    once: there the ablation runs after the clustered fits, in the calling thread, and gives
    the same tables."""
    import threading

    import numba

    _, asm, result = _scenario(2)
    monkeypatch.setattr(numba, "threading_layer", lambda: "workqueue")
    threads: set[str] = set()
    after = identify(asm, IdentificationConfig(scan=False, max_iter=40), final=True,
                     log=lambda _m: threads.add(threading.current_thread().name))  # fmt: skip
    assert threads == {threading.current_thread().name}
    assert after.tables() == result.tables()

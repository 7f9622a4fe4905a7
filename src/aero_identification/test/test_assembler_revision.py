"""The campaign assembler follows an adaptive run's plan revisions: the samples held so far are
cut into the revised plan's periods, samples that came before the revision claimed them are
kept, and an older revision is refused."""

import numpy as np
import pytest

from aero_identification.period_assembly import CampaignAssembler
from multisine_gen.campaigns import short_plan
from multisine_gen.plan import ExperimentPlan
from multisine_gen.revision import Adaptation, PlanRequest, revise

T0 = 1_000_000_000_000
BOUNDS = Adaptation(min_periods=2, min_realizations=2, max_realizations=3)


def _feed(asm: CampaignAssembler, plan: ExperimentPlan, ks: range) -> None:
    command = plan.command_deg()
    for k in ks:
        stamp = T0 + round(k * 1e9 / plan.fs)
        asm.add("u", stamp, float(command[k]))
        asm.add("y", stamp, 0.1 * float(command[k]))


def _period_start(plan: ExperimentPlan, level: int, realization: int, period: int) -> int:
    return next(
        s.start_k
        for s in plan.segments
        if s.kind == "multisine"
        and (s.level, s.realization, s.period) == (level, realization, period)
    )


def test_a_shortened_realization_keeps_its_periods_and_the_next_one_lands_right() -> None:
    plan = short_plan(seed=4)
    asm = CampaignAssembler(plan, T0)
    k2 = _period_start(plan, 0, 0, 2)
    _feed(asm, plan, range(k2 + 10))
    revised = revise(plan, k2 + 10, PlanRequest("end_realization", 0, k2 - 1), BOUNDS).plan
    asm.revise(revised)
    block = asm.blocks[(0, 0)]
    assert block.P == 3 and list(block.period_valid()) == [True, True, False]
    # The rest of the revised plan streams in: every period of it is complete.
    _feed(asm, revised, range(k2 + 10, revised.total_samples))
    assert all(b.period_valid().all() for b in asm.blocks.values())
    accounting = asm.sample_accounting(final=True)
    assert accounting["pitch"]["expected"] == revised.total_samples
    assert accounting["pitch"]["missing"] == accounting["pitch"]["duplicated"] == 0
    assert accounting["pitch"]["outside_plan"] == 0
    assert asm.experiment_account()["levels"]["level 0"]["executed_periods"] == [3, 4]


def test_samples_that_came_before_the_revision_which_added_them_are_kept() -> None:
    plan = short_plan(seed=4)
    asm = CampaignAssembler(plan, T0)
    k = _period_start(plan, 1, 1, 3)
    revised = revise(plan, k + 1, PlanRequest("add_realization", 1, k), BOUNDS).plan
    # The revised plan's samples reach the assembler before the revision itself (the plan
    # and the streams are separate topics): those past the old plan's end wait for it.
    _feed(asm, revised, range(revised.total_samples))
    assert asm.outside_plan["u"] == revised.total_samples - plan.total_samples
    asm.revise(revised)
    assert asm.outside_plan["u"] == 0
    assert (1, 2) in asm.blocks and all(b.period_valid().all() for b in asm.blocks.values())
    account = asm.experiment_account({0: "low", 1: "high"})
    assert account["levels"]["high"]["executed_periods"] == [4, 4, 4]
    assert account["multisine_executed_s"] > account["multisine_planned_s"]


def test_an_older_revision_is_refused_and_changes_nothing() -> None:
    plan = short_plan(seed=4)
    asm = CampaignAssembler(plan, T0)
    k2 = _period_start(plan, 0, 0, 2)
    revised = revise(plan, k2 + 10, PlanRequest("end_realization", 0, k2 - 1), BOUNDS).plan
    asm.revise(revised)
    with pytest.raises(ValueError, match="not newer"):
        asm.revise(plan)
    with pytest.raises(ValueError, match="not newer"):
        asm.revise(revised)
    np.testing.assert_equal(asm.total, revised.total_samples)

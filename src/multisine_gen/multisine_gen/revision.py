"""Plan revisions of an adaptive run: the identifier's requests, applied at a period boundary.

The identifier judges each measured multisine period as it completes and sends the generator
one request through the ``/experiment/control`` service (rig_runtime.interface.EXPERIMENT_CONTROL,
aero_rig_interfaces/srv/ControlExperiment; the rules are aero_identification.adaptive,
docs/design.md §7.9):

- ``go_on``: play the plan as it stands;
- ``end_realization``: the realization now streaming ends after the period now streaming
  (never below ``min_periods`` measured periods);
- ``finish_level``: the level now streaming ends after its realization now streaming (never
  below ``min_realizations`` realizations);
- ``add_realization``: one more phase realization for a level that has not ended (at most
  ``max_realizations``), drawn from the plan's seed as ``build_plan`` draws realization m, and
  crest-factor reduced when the level's realizations were, so it is the realization a plan
  designed with one more would have had.

:func:`revise` turns a request into the next revision of the plan. Only segments that have not
started change: a revision takes effect at the next segment boundary after the sample the
generator publishes next, which inside a multisine block is a period boundary, and the settling
period of a realization that has not started stays. Every sample before that boundary is
identical (checked), the revised plan is checked against the actuator's limits as the original
was, and a request that cannot be carried out is refused (:class:`RefusedRequestError`) with its
reason, changing nothing. :func:`request_from_fields` checks a request's fields (the
ControlExperiment service request's). This module is pure: no ROS, no DDS.
"""

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from multisine_gen.campaigns import derived_seed
from multisine_gen.crest import reduce_crest_factor
from multisine_gen.multisine import Multisine, random_phases
from multisine_gen.plan import ExperimentPlan, MultisineLevel, PlanError, Segment
from rig_runtime.interface import ActuatorLimits

__all__ = [
    "ACTIONS",
    "Action",
    "Adaptation",
    "PlanRequest",
    "RefusedRequestError",
    "RequestError",
    "Revision",
    "request_from_fields",
    "revise",
]

Action = Literal["go_on", "end_realization", "finish_level", "add_realization"]
ACTIONS: tuple[str, ...] = ("go_on", "end_realization", "finish_level", "add_realization")


class RequestError(ValueError):
    """A control request that is not one (an unknown action or level, a negative sample or
    level, malformed JSON in a recorded one): refused, and nothing changes."""


class RefusedRequestError(PlanError):
    """A valid request the plan cannot take (a floor, the budget, a level that has ended)."""


@dataclass(frozen=True)
class Adaptation:
    """The generator's bounds on what an adaptive run may change (its parameters).

    min_periods: fewest measured periods of a realization; min_realizations: fewest
    realizations of a level (2 keep the nonlinear distortions separable from the noise: the
    robust BLA's total variance needs M >= 2, Pintelon & Schoukens 2012, §4.3.1);
    max_realizations: the most a level may grow to.
    """

    min_periods: int = 2
    min_realizations: int = 2
    max_realizations: int = 4

    def __post_init__(self) -> None:
        if self.min_periods < 1 or self.min_realizations < 1:
            raise ValueError("adaptation: min_periods and min_realizations must be >= 1")
        if self.max_realizations < self.min_realizations:
            raise ValueError(
                f"adaptation: max_realizations ({self.max_realizations}) below "
                f"min_realizations ({self.min_realizations})"
            )

    def to_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class PlanRequest:
    """One request to the /experiment/control service (ControlExperiment's request fields).

    action: one of ACTIONS; level: the plan level it concerns; after_k: the last plan sample
    of the period it judged (the generator may hold its stream there until the request
    comes, aero-rig simulations); reason: why (logged and recorded with the decision); more:
    another request on the same period follows (a realization ended early, then the level's
    verdict), so a generator holding there waits for it.
    """

    action: Action
    level: int
    after_k: int
    reason: str = ""
    more: bool = False

    def to_fields(self) -> dict[str, Any]:
        """The ControlExperiment request's fields."""
        return dataclasses.asdict(self)


def request_from_fields(
    action: Any, level: Any, after_k: Any, reason: Any = "", more: Any = False
) -> PlanRequest:
    """The request of a ControlExperiment request's fields; RequestError saying what is wrong
    (an unknown action, a level or sample that is not an integer >= 0)."""
    if action not in ACTIONS:
        raise RequestError(f"action {action!r} is not one of {list(ACTIONS)}")
    for name, value in (("level", level), ("after_k", after_k)):
        if not isinstance(value, int) or isinstance(value, bool):
            raise RequestError(f"{name} must be an integer, got {value!r}")
        if value < 0:
            raise RequestError(f"{name} must be >= 0, got {value}")
    if not isinstance(reason, str):
        raise RequestError(f"reason must be a string, got {reason!r}")
    if not isinstance(more, bool):
        raise RequestError(f"more must be true or false, got {more!r}")
    return PlanRequest(action, int(level), int(after_k), reason, more)


@dataclass(frozen=True)
class Revision:
    """A request carried out: the revised plan, from which sample on it differs, and what
    changed (one line, for the log and the decision event)."""

    plan: ExperimentPlan
    from_k: int
    change: str


def _streaming(plan: ExperimentPlan, next_k: int) -> Segment | None:
    """The segment of the last published sample (None before the first)."""
    return plan.segment_at(next_k - 1) if 0 < next_k <= plan.total_samples else None


def _level_segments(plan: ExperimentPlan, level: int) -> list[Segment]:
    return [
        s
        for s in plan.segments
        if s.excitation == "multisine" and s.level == level and s.kind in ("settle", "multisine")
    ]


def _as_drawn(realization: Multisine) -> bool:
    """The realization's phases are its seed's random draw (not crest-factor reduced)."""
    seed = realization.seed
    return seed is not None and bool(
        np.allclose(realization.phases, random_phases(seed, realization.phases.size))
    )


def revise(
    plan: ExperimentPlan,
    next_k: int,
    request: PlanRequest,
    adaptation: Adaptation,
    limits: ActuatorLimits | None = None,
) -> Revision:
    """The plan revised by ``request``, when ``next_k`` is the next sample to publish.

    Raises RequestError for a level the plan does not have, RefusedRequestError (with the reason)
    for a request that would break a floor, the budget or a limit, that concerns a level that
    has ended (or, for end_realization and finish_level, is not streaming), or that changes
    nothing. ``go_on`` is never revised (the caller logs it).
    """
    if request.action == "go_on":
        raise ValueError("revise: go_on changes nothing")
    positions = {lv.level: i for i, lv in enumerate(plan.levels)}
    if request.level not in positions:
        raise RequestError(
            f"level {request.level} is not a multisine level of the plan "
            f"(levels {sorted(positions)})"
        )
    i = positions[request.level]
    lv = plan.levels[i]
    segments = _level_segments(plan, lv.level)
    where = f"level {lv.level} (offset {lv.offset_deg:g}°)"
    if segments[-1].stop_k < next_k:  # a sample after its last period is out
        raise RefusedRequestError(f"{request.action}: {where} has ended")
    current = _streaming(plan, next_k)
    streaming = (
        current is not None
        and current.excitation == "multisine"
        and current.level == lv.level
        and current.kind in ("settle", "multisine")
    )
    counts = [lv.periods_of(m) for m in range(len(lv.realizations))]
    realizations = list(lv.realizations)
    if request.action == "end_realization":
        if not streaming:
            raise RefusedRequestError(f"end_realization: {where} is not streaming")
        assert current is not None and current.realization is not None
        m = current.realization
        started = sum(
            1
            for s in segments
            if s.kind == "multisine" and s.realization == m and s.start_k < next_k
        )
        keep = max(started, adaptation.min_periods)
        if keep >= counts[m]:
            raise RefusedRequestError(
                f"end_realization: realization {m} of {where} ends after {counts[m]} periods "
                f"already ({started} started, min_periods {adaptation.min_periods})"
            )
        change = f"{where}, realization {m}: {keep} measured periods instead of {counts[m]}"
        counts[m] = keep
    elif request.action == "finish_level":
        if not streaming:
            raise RefusedRequestError(f"finish_level: {where} is not streaming")
        assert current is not None and current.realization is not None
        keep = max(current.realization + 1, adaptation.min_realizations)
        if keep >= len(realizations):
            raise RefusedRequestError(
                f"finish_level: {where} ends after realization {len(realizations) - 1} already "
                f"(min_realizations {adaptation.min_realizations})"
            )
        change = f"{where}: {keep} realizations instead of {len(realizations)}"
        realizations, counts = realizations[:keep], counts[:keep]
    else:  # add_realization
        m = len(realizations)
        if m >= adaptation.max_realizations:
            raise RefusedRequestError(
                f"add_realization: {where} has {m} realizations, the most allowed "
                f"(max_realizations {adaptation.max_realizations})"
            )
        if plan.seed is None:
            raise RefusedRequestError("add_realization: the plan has no seed to draw phases from")
        first = realizations[0]
        seed = derived_seed(int(plan.seed), 1, i, m)
        # build_plan's draw for realization m of level position i (campaigns.py).
        added = first.with_phases(random_phases(seed, first.phases.size), seed=seed)
        if any(not _as_drawn(r) for r in realizations):
            # The plan's realizations were crest-factor reduced (build_plan's
            # crest_factor_reduction; a plan file may carry other designed phases): the added
            # one is reduced the same way, so that it peaks no further from its mean than the
            # level's do (Pintelon & Schoukens 2012 §3.2; crest.py).
            added = reduce_crest_factor(added)
        realizations.append(added)
        counts.append(lv.periods)
        change = f"{where}: realization {m} added ({m + 1} realizations, {lv.periods} periods)"
    uniform = all(c == lv.periods for c in counts)
    level = MultisineLevel(
        lv.level,
        tuple(realizations),
        periods=lv.periods,
        settle_periods=lv.settle_periods,
        realization_periods=() if uniform else tuple(counts),
    )
    levels = (*plan.levels[:i], level, *plan.levels[i + 1 :])
    try:
        revised = dataclasses.replace(plan, levels=levels, revision=plan.revision + 1)
        if limits is not None:
            revised.validate(limits)
    except PlanError as error:
        why = f"{request.action}: the revised plan is refused: {error}"
        raise RefusedRequestError(why) from error
    # Only what has not started may change (module docstring): the same segments up to the
    # boundary, the same samples before it.
    from_k = next((s.start_k for s in plan.segments if s.start_k >= next_k), plan.total_samples)
    before_old = [s for s in plan.segments if s.start_k < from_k]
    before_new = [s for s in revised.segments if s.start_k < from_k]
    if before_old != before_new or not np.array_equal(
        plan.command_deg()[:from_k], revised.command_deg()[:from_k]
    ):
        raise RefusedRequestError(f"{request.action}: it would change samples already published")
    return Revision(revised, from_k, change)

"""Excitation design (odd random-phase multisines, sines, experiment plans) and the pitch
command generator node."""

from multisine_gen.campaigns import build_plan, default_plan, short_plan
from multisine_gen.crest import reduce_crest_factor
from multisine_gen.multisine import (
    ExcitationError,
    LineGrid,
    Multisine,
    crest_factor,
    design_line_grid,
    odd_random_phase_multisine,
    random_phase_multisine,
)
from multisine_gen.plan import (
    BaselineSweep,
    ExperimentPlan,
    MultisineLevel,
    PlanError,
    PlanSample,
    Segment,
    SineTest,
)
from multisine_gen.plan_format import (
    plan_from_dict,
    plan_from_json,
    plan_to_dict,
    plan_to_json,
    segment_event,
)
from multisine_gen.sine import Sine, design_sine

__all__ = [
    "BaselineSweep",
    "ExcitationError",
    "ExperimentPlan",
    "LineGrid",
    "Multisine",
    "MultisineLevel",
    "PlanError",
    "PlanSample",
    "Segment",
    "Sine",
    "SineTest",
    "build_plan",
    "crest_factor",
    "default_plan",
    "design_line_grid",
    "design_sine",
    "odd_random_phase_multisine",
    "plan_from_dict",
    "plan_from_json",
    "plan_to_dict",
    "plan_to_json",
    "random_phase_multisine",
    "reduce_crest_factor",
    "segment_event",
    "short_plan",
]

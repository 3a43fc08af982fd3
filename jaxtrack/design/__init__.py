"""Sampling-schedule design (Ho 1968, Sec. III): Newton, segment exchange, gradient schedules with
optax (:mod:`._schedules`); per-step periods, real-time rate allocation and maneuver compensation
(:mod:`._rates`)."""

from ._rates import (
    ManeuverCompensation as ManeuverCompensation,
    PerStepDesign as PerStepDesign,
    allocate_rates as allocate_rates,
    maneuver_period_change as maneuver_period_change,
    per_step_design as per_step_design,
)
from ._schedules import (
    NewtonResult as NewtonResult,
    NotConvergedWarning as NotConvergedWarning,
    RelaxedDesign as RelaxedDesign,
    SegmentProblem as SegmentProblem,
    exhaustive_counts as exhaustive_counts,
    ho_reduction as ho_reduction,
    local_search as local_search,
    newton_uniform_period as newton_uniform_period,
    relaxed_segment_design as relaxed_segment_design,
    round_counts as round_counts,
    segment_exchange as segment_exchange,
)

__all__ = [
    "ManeuverCompensation",
    "PerStepDesign",
    "allocate_rates",
    "maneuver_period_change",
    "per_step_design",
    "NewtonResult",
    "NotConvergedWarning",
    "RelaxedDesign",
    "SegmentProblem",
    "exhaustive_counts",
    "ho_reduction",
    "local_search",
    "newton_uniform_period",
    "relaxed_segment_design",
    "round_counts",
    "segment_exchange",
]

"""Sampling-schedule design (Ho 1968, Sec. III): Newton, segment exchange, gradient schedules with
optax (:mod:`._schedules`); per-step periods, real-time rate allocation and maneuver compensation
(:mod:`._rates`); designs by gradient on a differentiable Monte Carlo objective next to the same design
on the actual covariance (:mod:`._mc_design`); bearings-only observer trajectories designed by gradient
on the posterior Cramér–Rao bound (:mod:`._observer`); multi-target sensor schedules designed by
gradient next to the myopic brute-force manager (:mod:`._sensor_management`)."""

from ._mc_design import (
    GradientDesign as GradientDesign,
    design_by_covariance as design_by_covariance,
    design_by_monte_carlo as design_by_monte_carlo,
)
from ._observer import (
    ObserverDesign as ObserverDesign,
    bearing_position_bound as bearing_position_bound,
    constrained_turn_rates as constrained_turn_rates,
    design_observer_path as design_observer_path,
    observer_states as observer_states,
)
from ._rates import (
    ManeuverCompensation as ManeuverCompensation,
    PerStepDesign as PerStepDesign,
    allocate_rates as allocate_rates,
    maneuver_period_change as maneuver_period_change,
    per_step_design as per_step_design,
)
from ._schedule_simulation import (
    ScheduleSimulation as ScheduleSimulation,
    simulate_sensor_schedule as simulate_sensor_schedule,
)
from ._sensor_management import (
    SensorScheduleDesign as SensorScheduleDesign,
    SensorSchedulingProblem as SensorSchedulingProblem,
    greedy_sensor_schedule as greedy_sensor_schedule,
    relaxed_schedule_cost as relaxed_schedule_cost,
    relaxed_sensor_schedule as relaxed_sensor_schedule,
    schedule_cost as schedule_cost,
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
    "GradientDesign",
    "design_by_covariance",
    "design_by_monte_carlo",
    "ObserverDesign",
    "bearing_position_bound",
    "constrained_turn_rates",
    "design_observer_path",
    "observer_states",
    "ScheduleSimulation",
    "SensorScheduleDesign",
    "SensorSchedulingProblem",
    "greedy_sensor_schedule",
    "relaxed_schedule_cost",
    "relaxed_sensor_schedule",
    "schedule_cost",
    "simulate_sensor_schedule",
]

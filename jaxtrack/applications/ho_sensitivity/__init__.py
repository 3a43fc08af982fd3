"""Study: Ho (1968), "Sensitivity of the Kalman filter with respect to parameter variations".

Everything the CLI (``jaxtrack reproduce ho``), the notebooks and the tests need for Sec. III and
Sec. IV is here, as functions of the scenario; the numerics live in :mod:`jaxtrack.covariance`,
:mod:`jaxtrack.sensitivity`, :mod:`jaxtrack.design` and :mod:`jaxtrack.montecarlo`.
Specification: ``specs/ho-sensitivity.md`` (its §4.1 conventions: Q literal in τ, samples at
segment ends with the prior on the first sample, Convention 3 for the segment sensitivity).

- ``scenario``: the Sec. III-E plant, segment schedules, covariance and adjoint histories;
- ``analysis``: segment sensitivities, the velocity-measurement experiment, Sec. IV examples;
- ``schedules``: Sec. III design examples (Newton, Ho's rule, gradient, per-step, allocation,
  maneuver compensation);
- ``montecarlo``: the Monte Carlo check of the maneuver compensation;
- ``figures``: matplotlib figures; ``rows``: paper rows and :func:`reproduce`.
"""

from .analysis import Sec4Example1 as Sec4Example1
from .analysis import Sec4Example3 as Sec4Example3
from .analysis import VelocityMeasurementValue as VelocityMeasurementValue
from .analysis import sec4_example1 as sec4_example1
from .analysis import sec4_example3 as sec4_example3
from .analysis import segment_sensitivities as segment_sensitivities
from .analysis import velocity_measurement_estimate as velocity_measurement_estimate
from .figures import figure_adjoint as figure_adjoint
from .figures import figure_covariance_curves as figure_covariance_curves
from .figures import figure_covariance_histories as figure_covariance_histories
from .figures import figure_designed_schedules as figure_designed_schedules
from .figures import figure_one_stage_sensitivity as figure_one_stage_sensitivity
from .figures import figure_segment_sensitivity as figure_segment_sensitivity
from .figures import sawtooth as sawtooth
from .montecarlo import ManeuverMonteCarlo as ManeuverMonteCarlo
from .montecarlo import maneuver_monte_carlo as maneuver_monte_carlo
from .rows import design_rows as design_rows
from .rows import paper_rows as paper_rows
from .rows import reproduce as reproduce
from .scenario import COARSE as COARSE
from .scenario import HO_RULE_1G as HO_RULE_1G
from .scenario import HO_RULE_10G as HO_RULE_10G
from .scenario import POSITION as POSITION
from .scenario import SEC4_P as SEC4_P
from .scenario import SMOOTHED_R_COEFF as SMOOTHED_R_COEFF
from .scenario import UNIFORM as UNIFORM
from .scenario import adjoint_history as adjoint_history
from .scenario import covariance_at as covariance_at
from .scenario import history as history
from .scenario import integer_second_curve as integer_second_curve
from .scenario import sample_index as sample_index
from .scenario import scenario as scenario
from .scenario import segment_model_fn as segment_model_fn
from .scenario import terminal_position_variance as terminal_position_variance
from .schedules import AllocationExample as AllocationExample
from .schedules import DesignComparison as DesignComparison
from .schedules import ManeuverExample as ManeuverExample
from .schedules import ScheduleCost as ScheduleCost
from .schedules import allocation_example as allocation_example
from .schedules import design_comparison as design_comparison
from .schedules import maneuver_example as maneuver_example
from .schedules import newton_example as newton_example
from .schedules import per_step_example as per_step_example
from .schedules import segment_problem as segment_problem

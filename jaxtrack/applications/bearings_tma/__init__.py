"""Study: Lindgren & Gong (1977), "Position and Velocity Estimation Via Bearing Observations".

Bearings-only target motion analysis (TMA) from one maneuvering observer, NUSC TR 5260
(specification ``specs/bearings-tma.md``). The study assembles library parts:

- :mod:`.scenario` — report constants, observer paths, engagements R1–R3, noisy bearings;
- :mod:`.estimators` — Table 1, Table 2 and eq. (66) pseudo-linear filters
  (:class:`jaxtrack.filters.KalmanFilter` on :func:`jaxtrack.models.pseudolinear_bearing_model`)
  and the Appendix D EKF (:class:`jaxtrack.filters.ExtendedKalmanFilter` on
  :class:`jaxtrack.models.RelativeBearingModel`);
- :mod:`.analysis` — the stacked matrix ``A(k)`` for :mod:`jaxtrack.estimation` (batch formulas,
  observability), Appendix C error transitions, initial-range sensitivity, track errors;
- :mod:`.montecarlo` — runs on :func:`jaxtrack.montecarlo.monte_carlo_map` and the findings;
- :mod:`.figures`, :mod:`.rows` — figures, :func:`paper_rows` and :func:`reproduce`.

float64 is required (spec §3.5 item 6): in float32 the normalized covariance becomes indefinite
on geometry 1. Every function follows the dtype of its inputs, so that failure is reproducible.
"""

from ...estimation import (
    Observability as Observability,
    batch_estimate as batch_estimate,
    least_squares_estimate as least_squares_estimate,
    linear_estimator_matrix as linear_estimator_matrix,
    minimum_norm_estimate as minimum_norm_estimate,
    observability as observability,
    posterior_covariance as posterior_covariance,
)
from ...geometry import bearing as bearing, course as course
from ...models import (
    RelativeBearingModel as RelativeBearingModel,
    # The study's names for the library's functions (public: `bearings_tma.transition_matrix`).
    constant_velocity_transition as transition_matrix,  # noqa: F401
    pseudolinear_measurement_row as measurement_row,  # noqa: F401
)
from .analysis import (
    ErrorStatistics as ErrorStatistics,
    TrackErrors as TrackErrors,
    error_statistics as error_statistics,
    error_transition as error_transition,
    initial_range_sensitivity as initial_range_sensitivity,
    los_velocity_variances as los_velocity_variances,
    sample_index as sample_index,
    stacked_measurement_matrix as stacked_measurement_matrix,
    track_errors as track_errors,
)
from .estimators import (
    EkfEstimate as EkfEstimate,
    EkfPrior as EkfPrior,
    PseudoLinearEstimate as PseudoLinearEstimate,
    TrackSolution as TrackSolution,
    bearing_ekf as bearing_ekf,
    ekf_prior as ekf_prior,
    initial_relative_state as initial_relative_state,
    kalman_recursion as kalman_recursion,
    normalized_pseudolinear_filter as normalized_pseudolinear_filter,
    relative_state_filter as relative_state_filter,
    target_state_filter as target_state_filter,
    track_solution as track_solution,
)
from .figures import (
    figure_consistency as figure_consistency,
    figure_bounds as figure_bounds,
    figure_errors as figure_errors,
    figure_first_leg as figure_first_leg,
    figure_initial_range as figure_initial_range,
    figure_tracks as figure_tracks,
    figure_velocity_variance as figure_velocity_variance,
)
from .montecarlo import (
    DEFAULT_RUNS as DEFAULT_RUNS,
    EKF_RANGES as EKF_RANGES,
    PLKF_RANGES as PLKF_RANGES,
    GeometryStudy as GeometryStudy,
    TmaMonteCarlo as TmaMonteCarlo,
    divergence_fraction as divergence_fraction,
    geometry_study as geometry_study,
    initial_range_difference as initial_range_difference,
    leg1_collapse_factor as leg1_collapse_factor,
    monte_carlo as monte_carlo,
    overconfident_fraction as overconfident_fraction,
    run_studies as run_studies,
)
from .rows import paper_rows as paper_rows, reproduce as reproduce
from .scenario import (
    AVERAGED_BEARING_STD as AVERAGED_BEARING_STD,
    EKF_VELOCITY_STD as EKF_VELOCITY_STD,
    INITIAL_RANGE_GUESSES as INITIAL_RANGE_GUESSES,
    LEG_DURATION as LEG_DURATION,
    NOISE_CONFIGS as NOISE_CONFIGS,
    NUM_AVERAGED as NUM_AVERAGED,
    NUM_LEGS as NUM_LEGS,
    RAW_BEARING_STD as RAW_BEARING_STD,
    SAMPLE_PERIOD as SAMPLE_PERIOD,
    SPEED as SPEED,
    TURN_RATE as TURN_RATE,
    GeometrySpec as GeometrySpec,
    ObserverPath as ObserverPath,
    Scenario as Scenario,
    cross_range_noise as cross_range_noise,
    cross_range_noise_variance as cross_range_noise_variance,
    first_maneuver_index as first_maneuver_index,
    geometry as geometry,
    geometry_spec as geometry_spec,
    golden_bearing_noise as golden_bearing_noise,
    make_scenario as make_scenario,
    noisy_bearings as noisy_bearings,
    observer_input as observer_input,
)

"""Study: Layne & Blasch (1997), "Integrated SAR and navigation systems for targeting applications".

Specification: ``specs/sar-navigation.md`` (it corrects the OCR'd report; its [FIX-n] numbers are
cited in the docstrings). Equation numbers ``(E#)`` are the report's. Units are SI and radians
throughout; vectors in the navigation frame are NED.

The library holds the general parts: navigation frames and ψ angles
(:mod:`jaxtrack.geometry`: ``ned_to_ecef_rotation``, ``body_to_ned_rotation``, ``psi_from_dcm_error`` …,
E9–E13, E98–E115), the ψ-angle INS error model (:mod:`jaxtrack.models`: ``NavigationRates``,
``ins_error_dynamics``, ``ErrorModelOptions``, ``INSErrorBudget``, Schuler closed forms, ``rk4``;
Table 1, E178–E184), the CEP (:func:`jaxtrack.montecarlo.circular_error_probable`) and the
covariance recursion (:func:`jaxtrack.covariance.covariance_recursion`). The study assembles them:

- :mod:`.states`: units and the 33-state index map (21 INS states, target, β, six radar biases).
- :mod:`.geometry`: look geometry and measurements (E14–E29), SAR background (E1–E8, E62–E72).
- :mod:`.targeting`: the corrected closed-form single-look solution (§1.7, E30–E55), V-5.
- :mod:`.budgets`: Tables 5–7, per-look noise (E73–E83), state priors.
- :mod:`.error_model`: the 33-state F, Q, analytic H (Tables 2–4) and the exact measurement error.
- :mod:`.experiments`: V-16 and V-19 against nonlinear truth simulations.
- :mod:`.scenario`, :mod:`.analysis`: RS-1 [EXT], single-look and over-time covariance analysis.
- :mod:`.figures`, :mod:`.rows`: figures, paper rows and :func:`reproduce`.

Conventions that the spec leaves open, chosen here (each a keyword where it matters):

- Doppler sign (E2, FIX-38): closing gives ``F_d > 0`` and ``ṙ = −λF_d/2 < 0``.
- Attitude error (E109, FIX-24): ``C̄_b^n = (I − [ψ×]) C_b^n`` and the consistent dynamics
  ``F_vψ = +[A×]``, ``ψ̇ = −[ω×]ψ − ε − diag(ω)k_ε`` (``psi_sign_convention="consistent"``;
  ``"report_literal"`` keeps Table 1 as printed).
- Gravity gradient (FIX-25): ``Γ = ω_s² diag(−1, −1, +2)`` (``vertical_gravity_gradient``).
- Sensor-error coupling (FIX-32): local-level as printed (``sensor_frame="nav"``) or strapdown.
- δv is the nav-frame derivative of δr (FIX-39); navigation-frame tilt is neglected (FIX-40).
- Timing noise (FIX-19): ``T_d|ṙ|`` and ``T_d|r̈|`` (``timing_model="derivative"``).
- TEMP errors are random biases unless ``temperature_inverse_correlation_time > 0`` (FIX-26).
- INS white-noise units (FIX-20): the literal √PSD reading (``ins_noise_units="per_sqrt_hz"``).
"""

from .states import (
    ACCEL_BIAS as ACCEL_BIAS,
    ACCEL_SCALE as ACCEL_SCALE,
    ATTITUDE as ATTITUDE,
    DEG_PER_HOUR as DEG_PER_HOUR,
    DOPPLER_BIAS as DOPPLER_BIAS,
    FOOT as FOOT,
    FREQUENCY as FREQUENCY,
    GYRO_BIAS as GYRO_BIAS,
    GYRO_SCALE as GYRO_SCALE,
    MEASUREMENT_NAMES as MEASUREMENT_NAMES,
    MICRO_G as MICRO_G,
    MISALIGNMENT as MISALIGNMENT,
    MRAD as MRAD,
    NUM_INS_STATES as NUM_INS_STATES,
    NUM_STATES as NUM_STATES,
    POSITION as POSITION,
    PROPAGATION_SPEED as PROPAGATION_SPEED,
    RANGE_CLOCK as RANGE_CLOCK,
    SPEED_OF_LIGHT as SPEED_OF_LIGHT,
    STATE_NAMES as STATE_NAMES,
    TARGET as TARGET,
    TEMP_AZIMUTH as TEMP_AZIMUTH,
    TEMP_ELEVATION as TEMP_ELEVATION,
    VELOCITY as VELOCITY,
)
from .geometry import (
    atmospheric_loss as atmospheric_loss,
    boresight_angles as boresight_angles,
    clutter_cross_section as clutter_cross_section,
    designation_factor_ref2 as designation_factor_ref2,
    focusing_phase as focusing_phase,
    LookGeometry as LookGeometry,
    los_from_monopulse as los_from_monopulse,
    los_rotation_rate as los_rotation_rate,
    monopulse_angles as monopulse_angles,
    radar_measurements as radar_measurements,
    rain_loss as rain_loss,
    range_from_round_trip as range_from_round_trip,
    range_rate as range_rate,
    range_rate_from_doppler as range_rate_from_doppler,
    range_rate_resolution as range_rate_resolution,
    range_resolution as range_resolution,
    signal_to_clutter_noise as signal_to_clutter_noise,
    signal_to_noise as signal_to_noise,
    slant_range as slant_range,
    spotlight_azimuth_resolution as spotlight_azimuth_resolution,
    stripmap_azimuth_resolution as stripmap_azimuth_resolution,
    to_db as to_db,
)
from .targeting import (
    random_targeting_geometries as random_targeting_geometries,
    single_look_target as single_look_target,
    targeting_round_trip_error as targeting_round_trip_error,
)
from .budgets import (
    bias_covariance as bias_covariance,
    designation_noise_factor as designation_noise_factor,
    h423_budget as h423_budget,
    measurement_noise_cov as measurement_noise_cov,
    MONOPULSE_WHITE_TERMS as MONOPULSE_WHITE_TERMS,
    MonopulseErrorBudget as MonopulseErrorBudget,
    NavigationPrior as NavigationPrior,
    NoiseUnits as NoiseUnits,
    prior_std as prior_std,
    sar_noise_std as sar_noise_std,
    SARErrorBudget as SARErrorBudget,
    table6_budget as table6_budget,
    table7_budget as table7_budget,
    TimingModel as TimingModel,
)
from .error_model import (
    autodiff_measurement_matrix as autodiff_measurement_matrix,
    error_dynamics as error_dynamics,
    error_response as error_response,
    first_look_prior as first_look_prior,
    first_look_target_error as first_look_target_error,
    gps_measurement_matrix as gps_measurement_matrix,
    measurement_error as measurement_error,
    measurement_matrix as measurement_matrix,
    process_noise_density as process_noise_density,
)
from .experiments import (
    accelerometer_bias_experiment as accelerometer_bias_experiment,
    AttitudeErrorExperiment as AttitudeErrorExperiment,
    gyro_bias_attitude_experiment as gyro_bias_attitude_experiment,
    InertialErrorExperiment as InertialErrorExperiment,
    RESPONSE_TIMES as RESPONSE_TIMES,
)
from .scenario import (
    Case as Case,
    CASES as CASES,
    CovarianceScenario as CovarianceScenario,
    RS1_ANTENNA as RS1_ANTENNA,
    RS1_HEIGHT as RS1_HEIGHT,
    RS1_LATITUDE as RS1_LATITUDE,
    rs1_look as rs1_look,
    RS1_SPEED as RS1_SPEED,
    RS1_TARGET as RS1_TARGET,
    rs1_trajectory as rs1_trajectory,
    v10_look as v10_look,
    v5b_look as v5b_look,
)
from .analysis import (
    common_mode_information as common_mode_information,
    CovarianceAnalysis as CovarianceAnalysis,
    rs1_covariance_analysis as rs1_covariance_analysis,
    rs1_model as rs1_model,
    RS1Model as RS1Model,
    single_look_analysis as single_look_analysis,
    SingleLookAnalysis as SingleLookAnalysis,
    unscale_history as unscale_history,
)
from .figures import (
    figure_ins_error_responses as figure_ins_error_responses,
    figure_shared_position_error as figure_shared_position_error,
    figure_single_look as figure_single_look,
    figure_target_error as figure_target_error,
)
from .rows import (
    paper_rows as paper_rows,
    reproduce as reproduce,
)

"""Study: Wang, Chen, Jia, Progri, "Optimized Bias Estimation Model for Mobile Radar Error
Registration", *The Journal of Navigation* (2012).

Everything the CLI (``jaxtrack reproduce registration``), the notebook and the tests need is
re-exported here. Specification: ``specs/obem-registration.md`` (equation numbers are the
paper's; [R] marks a resolution of the spec where the paper is silent, [X] a finding of the spec
that is not in the paper). The study only assembles library parts: frames from :mod:`jaxtrack.geometry`
(compass-azimuth radar coordinates and the platform attitude in ``geometry._platform``), the
filter from :func:`jaxtrack.filters.run_filter` on a :class:`~jaxtrack.models.LinearGaussianModel`,
observability and batch least squares from :mod:`jaxtrack.estimation`, the Monte Carlo from
:func:`jaxtrack.montecarlo.monte_carlo_map`.

Modules: :mod:`.frames` (measurement model, registration equation), :mod:`.analysis`
(Proposition 2, the baseline rotation), :mod:`.scenario` (scenario, simulation, Z/H/R),
:mod:`.estimators` (priors, the registration filter, rectification), :mod:`.cost` (V14),
:mod:`.montecarlo`, :mod:`.figures`, :mod:`.rows` (paper rows and ``reproduce``).

**Setting.** Two ship-borne 3-D radars on gyro-stabilised platforms observe one target. Radar i has
four offset biases ``β_i = [Δr_i, k_ri, Δθ_i, Δε_i]`` (range m, range gain, azimuth and elevation
rad) and its platform three attitude biases ``α_i = [Δφ_i, Δη_i, Δψ_i]`` (yaw, pitch, roll, rad).
Mapping both radars' measurements to ECEF and equating them, to first order (eqs 12–19),

    Z(k) = X_2s − X_1s + T_2 X_2 − T_1 X_1 = [T1A1, −T2A2, D1, −D2] β_AAM + [T1C1, −T2C2] w,

a 3-row pseudo-measurement linear in the 14 biases. **AAM** (eqs 16–20) estimates all 14 with a
Kalman filter (F = I, Q = 0); **OBEM** (eqs 46–49) keeps the 8 states ``[Δr, k_r, Δθ−Δφ, Δε]`` per
radar, since the azimuth and yaw columns are exact negatives (eq. 27, Proposition 1) and pitch and
roll mainly shift elevation (Proposition 2).

**Conventions.** SI units and radians inside; degrees only in reports and figures. Radar spherical
coordinates ``[r, θ, ε]`` use the *compass* azimuth θ (from North, clockwise) of the paper, not
:mod:`jaxtrack.geometry`'s mathematical azimuth
(:func:`jaxtrack.geometry.compass_spherical_to_cartesian` converts). State orderings follow eqs (16) and (46) (0-based indices in code). A site is ``[L, λ, h]``: geodetic
latitude and longitude (rad) and height (m) on WGS-84.
"""

from .frames import (
    AAM_STATES as AAM_STATES,
    DEG as DEG,
    MERGED_STATES as MERGED_STATES,
    OBEM_STATES as OBEM_STATES,
    RegistrationTerms as RegistrationTerms,
    aam_truth as aam_truth,
    attitude_jacobian as attitude_jacobian,
    attitude_matrix as attitude_matrix,
    ecef_position as ecef_position,
    merged_columns as merged_columns,
    noise_jacobian as noise_jacobian,
    nonlinear_pseudo_measurement as nonlinear_pseudo_measurement,
    obem_columns as obem_columns,
    obem_truth as obem_truth,
    offset_corrected_position as offset_corrected_position,
    offset_jacobian as offset_jacobian,
    pseudo_measurement_noise_cov as pseudo_measurement_noise_cov,
    registration_terms as registration_terms,
)
from .analysis import (
    baseline_rotation_attitudes as baseline_rotation_attitudes,
    east_axis_azimuth_error as east_axis_azimuth_error,
    equivalent_errors_exact as equivalent_errors_exact,
    equivalent_errors_first_order as equivalent_errors_first_order,
)
from .scenario import (
    RegistrationInputs as RegistrationInputs,
    Scans as Scans,
    Scenario as Scenario,
    bias_free as bias_free,
    paper_scenario as paper_scenario,
    registration_inputs as registration_inputs,
    simulate_scans as simulate_scans,
    unequal_tilt_scenario as unequal_tilt_scenario,
)
from .estimators import (
    PRIORS as PRIORS,
    RegistrationEstimate as RegistrationEstimate,
    prior_cov as prior_cov,
    rectify as rectify,
    registration_filter as registration_filter,
    registration_model as registration_model,
)
from .cost import (
    cubic_cost_ratio as cubic_cost_ratio,
    measure_filter_times as measure_filter_times,
    update_flops as update_flops,
    update_multiply_adds as update_multiply_adds,
)
from .montecarlo import (
    CORRECTIONS as CORRECTIONS,
    MODELS as MODELS,
    RegistrationMonteCarlo as RegistrationMonteCarlo,
    RunArgs as RunArgs,
    RunErrors as RunErrors,
    linear_model_consistency as linear_model_consistency,
    monte_carlo as monte_carlo,
    run_squared_errors as run_squared_errors,
)
from .figures import (
    figure_attitude_rmse as figure_attitude_rmse,
    figure_bias_rmse as figure_bias_rmse,
    figure_observability as figure_observability,
    figure_proposition2 as figure_proposition2,
    figure_rectified_position as figure_rectified_position,
    figure_unequal_tilt as figure_unequal_tilt,
)
from .rows import (
    GEOMETRY_TABLE as GEOMETRY_TABLE,
    paper_rows as paper_rows,
    reproduce as reproduce,
)

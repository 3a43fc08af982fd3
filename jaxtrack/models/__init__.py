"""State-space models: linear-Gaussian and nonlinear, continuous→discrete, standard kinematics."""

from ._base import (
    AbstractStateSpaceModel as AbstractStateSpaceModel,
    LinearGaussianModel as LinearGaussianModel,
    NonlinearGaussianModel as NonlinearGaussianModel,
    at_step as at_step,
    wrap_angle as wrap_angle,
)
from ._discretize import (
    discretize as discretize,
    van_loan as van_loan,
)
from ._ins import (
    EARTH_MU as EARTH_MU,
    EARTH_RADIUS as EARTH_RADIUS,
    EARTH_RATE as EARTH_RATE,
    GRAVITY as GRAVITY,
    INS_ACCEL_BIAS as INS_ACCEL_BIAS,
    INS_ACCEL_SCALE as INS_ACCEL_SCALE,
    INS_ATTITUDE as INS_ATTITUDE,
    INS_GYRO_BIAS as INS_GYRO_BIAS,
    INS_GYRO_SCALE as INS_GYRO_SCALE,
    INS_POSITION as INS_POSITION,
    INS_STATE_DIM as INS_STATE_DIM,
    INS_STATE_NAMES as INS_STATE_NAMES,
    INS_VELOCITY as INS_VELOCITY,
    ErrorModelOptions as ErrorModelOptions,
    INSErrorBudget as INSErrorBudget,
    NavigationRates as NavigationRates,
    earth_rate_nav as earth_rate_nav,
    gravity_gradient as gravity_gradient,
    gyro_bias_position_response as gyro_bias_position_response,
    horizontal_accel_bias_response as horizontal_accel_bias_response,
    ins_error_dynamics as ins_error_dynamics,
    ins_process_noise_density as ins_process_noise_density,
    navigation_rates as navigation_rates,
    rk4 as rk4,
    schuler_frequency as schuler_frequency,
    schuler_rates as schuler_rates,
    transport_rate as transport_rate,
    velocity_error_position_gain as velocity_error_position_gain,
    velocity_error_position_gain_compact as velocity_error_position_gain_compact,
    vertical_accel_bias_response as vertical_accel_bias_response,
)
from ._kinematic import (
    constant_acceleration as constant_acceleration,
    constant_velocity as constant_velocity,
    ho_plant as ho_plant,
    sample_times as sample_times,
    segment_schedule as segment_schedule,
    singer as singer,
)
from ._relative import (
    RelativeBearingModel as RelativeBearingModel,
    constant_velocity_transition as constant_velocity_transition,
    pseudolinear_bearing_model as pseudolinear_bearing_model,
    pseudolinear_measurement_row as pseudolinear_measurement_row,
)
from ._components import (
    AbstractMeasurementModel as AbstractMeasurementModel,
    AbstractTransitionModel as AbstractTransitionModel,
    TrackingModel as TrackingModel,
)
from ._motion import (
    BlockTransition as BlockTransition,
    ConstantAcceleration as ConstantAcceleration,
    ConstantVelocity as ConstantVelocity,
    CoordinatedTurn as CoordinatedTurn,
    LinearTransition as LinearTransition,
    NearlyConstantTurn as NearlyConstantTurn,
)
from ._sensors import (
    Bearing as Bearing,
    RangeAzimuthElevation as RangeAzimuthElevation,
    RangeBearing as RangeBearing,
    sensor_rotation as sensor_rotation,
)
from ._converted import (
    ConvertedMeasurement as ConvertedMeasurement,
    unbiased_polar_to_cartesian as unbiased_polar_to_cartesian,
    unbiased_spherical_to_cartesian as unbiased_spherical_to_cartesian,
)

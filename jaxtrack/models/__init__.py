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
from ._kinematic import (
    constant_acceleration as constant_acceleration,
    constant_velocity as constant_velocity,
    ho_plant as ho_plant,
    sample_times as sample_times,
    segment_schedule as segment_schedule,
    singer as singer,
)

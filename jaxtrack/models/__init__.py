"""State-space models: linear-Gaussian and nonlinear, continuous→discrete, standard kinematics."""

from ._base import (
    AbstractStateSpaceModel as AbstractStateSpaceModel,
    LinearGaussianModel as LinearGaussianModel,
    NonlinearGaussianModel as NonlinearGaussianModel,
    at_step as at_step,
    wrap_angle as wrap_angle,
)

"""Ho's (1968) covariance-sensitivity analysis: analytic recursions and their autodiff counterparts.

- ``_variations``: exact (all-order) one-stage variation equations, eqs. (17)–(30), App. B.
- ``_recursions``: first-order analysis: local variations (31), error-transition matrices
  (34)–(35), multistage variations (36)–(37), adjoint matrices (42)–(43), the forward tangent
  recursion (46)–(48), and the ``Analytic``/``Autodiff`` method strategies.
- ``_indices``: sensitivity matrices of a parameter α (46)–(48), time-fixed correction (50),
  sensitivity indices (51)–(54) and Ho's segment indices; every analytic function has an
  autodiff counterpart with the same inputs and outputs.
- ``_gain``: second-order gain variation about the optimum, eqs. (55)–(64).
- ``_one_stage``: Sec. IV one-stage closed forms (99)–(134) and the App. C normalisation.
"""

from ._gain import *  # noqa: F401,F403
from ._indices import *  # noqa: F401,F403
from ._one_stage import *  # noqa: F401,F403
from ._recursions import *  # noqa: F401,F403
from ._variations import *  # noqa: F401,F403

__all__ = [
    "GainEllipsoid",
    "gain_variation_cost",
    "gain_variation_recursion",
    "allowable_gain_ellipsoid",
    "gain_hessian",
    "CovarianceSensitivity",
    "SegmentSensitivity",
    "covariance_sensitivity",
    "sensitivity_index",
    "time_fixed_sensitivity",
    "segment_sensitivity",
    "NormalizedCov",
    "Normalization",
    "one_stage_update",
    "one_stage_gain",
    "plant_noise_sensitivity",
    "period_sensitivity",
    "measurement_noise_sensitivity",
    "plant_noise_period_tradeoff",
    "measurement_noise_period_tradeoff",
    "predicted_position_variance",
    "updated_position_variance",
    "dimensionless_period_sensitivity",
    "normalize",
    "denormalize",
    "Analytic",
    "Autodiff",
    "LocalVariation",
    "Adjoint",
    "local_variations",
    "tangent_recursion",
    "error_transition",
    "adjoint",
    "first_order_variation",
    "multistage_variation",
    "UpdateVariation",
    "GainVariation",
    "CovarianceVariation",
    "update_variation",
    "prediction_variation",
    "optimal_gain_variation",
    "value_of_information",
    "exact_variation_recursion",
]

"""Batch linear estimation: weighted least squares with and without a prior, equality-constrained
least squares, minimum-norm solutions, and the observability of linear measurement sequences."""

from ._least_squares import (
    LinearEstimate as LinearEstimate,
    batch_estimate as batch_estimate,
    least_squares_estimate as least_squares_estimate,
    linear_estimator_matrix as linear_estimator_matrix,
    minimum_norm_estimate as minimum_norm_estimate,
    posterior_covariance as posterior_covariance,
    weighted_least_squares as weighted_least_squares,
)
from ._constrained import (
    ConstrainedSolution as ConstrainedSolution,
    equality_constrained_lsq as equality_constrained_lsq,
)
from ._observability import (
    Observability as Observability,
    observability as observability,
)

__all__ = [
    "LinearEstimate",
    "batch_estimate",
    "least_squares_estimate",
    "linear_estimator_matrix",
    "minimum_norm_estimate",
    "posterior_covariance",
    "weighted_least_squares",
    "ConstrainedSolution",
    "equality_constrained_lsq",
    "Observability",
    "observability",
]

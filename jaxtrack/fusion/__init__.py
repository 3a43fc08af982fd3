"""Track-to-track fusion: two estimates of one state fused with unknown or known correlation.

A layer above :mod:`jaxtrack.filters` and below :mod:`jaxtrack.multitarget`: it imports the
filters, the models and the private helpers, nothing above. Every rule is a plain function of
arrays and a strategy object (an :class:`AbstractFusionRule`) with one ``fuse`` that returns one
:class:`FusedEstimate`, so the track-fusion run takes the rule as an argument:

- ``_rules``: covariance intersection (:func:`covariance_intersection`, optimal weight by
  :func:`optimal_ci_weight`), split CI (:func:`split_covariance_intersection`,
  :func:`optimal_sci_weight`), ellipsoidal intersection (:func:`ellipsoidal_intersection`),
  Bar-Shalom–Campo with a known cross-covariance (:func:`bar_shalom_campo`) and the independent
  (naive) fusion (:func:`independent_fusion`), each with its strategy class;
- ``_track``: :func:`run_track_fusion` (two local Kalman filters on one target and a fusion
  centre, one ``lax.scan``), :func:`cross_covariance_step` (Bar-Shalom 1981) and
  :func:`stacked_sensor_model` (both sensors as one model, to simulate a run).

Many targets seen by two sensors: :class:`jaxtrack.multitarget.TrackFusionTracker` (a layer up)
pairs two multi-target trackers' tracks and fuses each pair with one of these rules.
"""

from ._rules import (
    FusedEstimate as FusedEstimate,
    bar_shalom_campo as bar_shalom_campo,
    covariance_intersection as covariance_intersection,
    ellipsoidal_intersection as ellipsoidal_intersection,
    independent_fusion as independent_fusion,
    optimal_ci_weight as optimal_ci_weight,
    optimal_sci_weight as optimal_sci_weight,
    split_covariance_intersection as split_covariance_intersection,
)
from ._strategies import (
    AbstractFusionRule as AbstractFusionRule,
    BarShalomCampo as BarShalomCampo,
    CovarianceIntersection as CovarianceIntersection,
    EllipsoidalIntersection as EllipsoidalIntersection,
    IndependentFusion as IndependentFusion,
    SplitCovarianceIntersection as SplitCovarianceIntersection,
)
from ._track import (
    TrackFusionResult as TrackFusionResult,
    cross_covariance_step as cross_covariance_step,
    run_track_fusion as run_track_fusion,
    stacked_sensor_model as stacked_sensor_model,
)

__all__ = [
    "AbstractFusionRule",
    "FusedEstimate",
    "CovarianceIntersection",
    "SplitCovarianceIntersection",
    "EllipsoidalIntersection",
    "BarShalomCampo",
    "IndependentFusion",
    "covariance_intersection",
    "optimal_ci_weight",
    "split_covariance_intersection",
    "optimal_sci_weight",
    "ellipsoidal_intersection",
    "bar_shalom_campo",
    "independent_fusion",
    "TrackFusionResult",
    "run_track_fusion",
    "cross_covariance_step",
    "stacked_sensor_model",
]

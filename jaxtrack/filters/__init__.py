"""Gaussian filters and smoothers: one predict/update pair per family, one ``lax.scan``."""

from ._base import (
    AbstractFilter as AbstractFilter,
    AbstractUpdateForm as AbstractUpdateForm,
    JosephForm as JosephForm,
    StandardForm as StandardForm,
    Conditioned as Conditioned,
    FilterResult as FilterResult,
    condition_linearized as condition_linearized,
    condition_on_moments as condition_on_moments,
    filter_step as filter_step,
    run_filter as run_filter,
)
from ._batch import (
    BatchFilterResult as BatchFilterResult,
    run_filter_batch as run_filter_batch,
)
from ._kalman import ExtendedKalmanFilter as ExtendedKalmanFilter, KalmanFilter as KalmanFilter
from ._smoother import SmootherResult as SmootherResult, rts_smoother as rts_smoother
from ._unscented import UnscentedKalmanFilter as UnscentedKalmanFilter

"""Gaussian filters and smoothers: one predict/update pair per family, one step, one ``lax.scan``.

- ``_updates``: the two measurement updates (linearised, moments) and the update forms;
- ``_base``: :class:`AbstractFilter` (``init``/``step``), :class:`FilterState`, :class:`FilterResult`;
  ``_run``: :func:`run_filter` (above ``_base`` and ``_parallel``);
- ``_kalman``, ``_unscented``: the filter families; ``_smoother``: RTS;
- ``_batch``: many runs at once, with the covariance strategy (shared or per run);
- ``_parallel``: how a run traverses time (``scan=``): sequential, or parallel-in-time;
- ``_particle``: the particle filter (same ``init``/``step``); ``_resampling``: its resampling schemes.
"""

from ._base import (
    AbstractFilter as AbstractFilter,
    FilterResult as FilterResult,
    FilterState as FilterState,
    StepOutput as StepOutput,
)
from ._batch import (
    AbstractCovarianceStrategy as AbstractCovarianceStrategy,
    AutoCovariance as AutoCovariance,
    BatchFilterResult as BatchFilterResult,
    PerRunCovariance as PerRunCovariance,
    SharedCovariance as SharedCovariance,
    covariance_pass as covariance_pass,
    run_filter_batch as run_filter_batch,
)
from ._parallel import (
    AbstractTimeScan as AbstractTimeScan,
    AutoScan as AutoScan,
    ParallelInTime as ParallelInTime,
    Sequential as Sequential,
)
from ._run import run_filter as run_filter
from ._kalman import (
    ExtendedKalmanFilter as ExtendedKalmanFilter,
    KalmanFilter as KalmanFilter,
    MeanMap as MeanMap,
    mean_step as mean_step,
)
from ._consider import (
    ConsiderKalmanFilter as ConsiderKalmanFilter,
    consider_gain as consider_gain,
    consider_model as consider_model,
)
from ._smoother import (
    SmootherResult as SmootherResult,
    lag_one_covariances as lag_one_covariances,
    rts_smoother as rts_smoother,
)
from ._unscented import UnscentedKalmanFilter as UnscentedKalmanFilter
from ._updates import (
    AbstractUpdateForm as AbstractUpdateForm,
    Conditioned as Conditioned,
    JosephForm as JosephForm,
    StandardForm as StandardForm,
    condition_linearized as condition_linearized,
    condition_on_moments as condition_on_moments,
)
from ._iterated import IteratedExtendedKalmanFilter as IteratedExtendedKalmanFilter
from ._square_root import (
    SquareRootKalmanFilter as SquareRootKalmanFilter,
    SquareRootUnscentedKalmanFilter as SquareRootUnscentedKalmanFilter,
)
from ._imm import (
    IMMResult as IMMResult,
    IMMState as IMMState,
    IMMStepOutput as IMMStepOutput,
    InteractingMultipleModel as InteractingMultipleModel,
    run_imm as run_imm,
)
from ._imm_smoother import IMMSmootherResult as IMMSmootherResult, imm_smoother as imm_smoother
from ._particle import (
    AbstractProposal as AbstractProposal,
    Bootstrap as Bootstrap,
    LocallyOptimal as LocallyOptimal,
    ParticleFilter as ParticleFilter,
    ParticleState as ParticleState,
    Regularization as Regularization,
)
from ._resampling import (
    AbstractResampling as AbstractResampling,
    AbstractResamplingScheme as AbstractResamplingScheme,
    Multinomial as Multinomial,
    Residual as Residual,
    SoftResampling as SoftResampling,
    StopGradientResampling as StopGradientResampling,
    Stratified as Stratified,
    Systematic as Systematic,
    effective_sample_size as effective_sample_size,
    multinomial_indices as multinomial_indices,
    residual_indices as residual_indices,
    stratified_indices as stratified_indices,
    systematic_indices as systematic_indices,
)

__all__ = [
    "AbstractFilter",
    "FilterResult",
    "FilterState",
    "StepOutput",
    "run_filter",
    "AbstractCovarianceStrategy",
    "AutoCovariance",
    "BatchFilterResult",
    "PerRunCovariance",
    "SharedCovariance",
    "covariance_pass",
    "run_filter_batch",
    "AbstractTimeScan",
    "AutoScan",
    "ParallelInTime",
    "Sequential",
    "ExtendedKalmanFilter",
    "KalmanFilter",
    "MeanMap",
    "mean_step",
    "ConsiderKalmanFilter",
    "consider_gain",
    "consider_model",
    "SmootherResult",
    "rts_smoother",
    "lag_one_covariances",
    "UnscentedKalmanFilter",
    "AbstractUpdateForm",
    "Conditioned",
    "JosephForm",
    "StandardForm",
    "condition_linearized",
    "condition_on_moments",
    "IteratedExtendedKalmanFilter",
    "SquareRootKalmanFilter",
    "SquareRootUnscentedKalmanFilter",
    "IMMResult",
    "IMMState",
    "IMMStepOutput",
    "InteractingMultipleModel",
    "run_imm",
    "IMMSmootherResult",
    "imm_smoother",
    "AbstractProposal",
    "Bootstrap",
    "LocallyOptimal",
    "ParticleFilter",
    "ParticleState",
    "Regularization",
    "AbstractResampling",
    "AbstractResamplingScheme",
    "Multinomial",
    "Residual",
    "SoftResampling",
    "StopGradientResampling",
    "Stratified",
    "Systematic",
    "effective_sample_size",
    "multinomial_indices",
    "residual_indices",
    "stratified_indices",
    "systematic_indices",
]

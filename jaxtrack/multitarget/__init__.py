"""Multi-target tracking: scenarios with births, deaths, detection probability and Poisson clutter;
the fixed-capacity track table and the trackers (GNN, JPDA, JIPDA) as one step and one scan.

- ``_scenario``: :class:`Scenario` (an :class:`AbstractScenario`, what the Monte Carlo
  simulates), :func:`simulate_scenario` / :func:`simulate_scenarios` (padded
  scans with validity masks and the origin of every measurement; the truth drawn per run, or
  fixed over the runs with ``truth_states``);
- ``_named_scenarios``: :func:`crossing_targets` (the library's crossing targets before a
  range–bearing radar) and :func:`williams15` (the coalescence scenario of Williams 2015 as
  García-Fernández's PMBM reference defines it, with its fixed truth and the reference's filter
  settings, :class:`Williams15Settings`) and :func:`vo_vo_linear` (the linear benchmark of Vo & Vo's
  labelled-RFS papers, with its LMB birth, :class:`VoVoLinearSettings`);
- ``_base``: the contract every multi-target method implements
  (:class:`AbstractMultiTargetFilter`: ``init``, ``step``, ``estimates``, ``capacity_events``),
  :class:`Estimates`, and :func:`run_multitarget`, the one scan that runs them all;
- ``_tracker``: :class:`TrackTable`, :class:`Tracker` (association method as a strategy),
  :func:`run_tracker`;
- ``_evaluation``: :func:`score_tracks` (GOSPA per scan, track counts) and
  :func:`multitarget_monte_carlo` (any method on a scenario through the Monte Carlo engine's run
  primitive; ``tracker_monte_carlo`` is its deprecated former name);
- ``_mixture``: :class:`GaussianMixture` (birth and time-0 intensities of the four RFS filters)
  and the mixture-reduction strategies :class:`VoMaReduction`, :class:`StoneSoupReduction`;
- ``_phd``: :class:`GMPHD` (the Gaussian-mixture PHD filter of Vo & Ma 2006 with a fixed
  component budget) and :func:`run_phd`;
- ``_cphd``: :class:`GMCPHD` (the Gaussian-mixture CPHD filter of Vo, Vo & Cantoni 2007: the
  GM-PHD's pieces plus a cardinality distribution up to ``N_max``) and :func:`run_cphd`;
- ``_multibernoulli``: :class:`PMBMState` and what the PMBM and PMB filters share, and
  :func:`run_pmbm`;
- ``_pmbm``: :class:`PMBM` (the Poisson multi-Bernoulli mixture filter of García-Fernández et al.
  2018 with fixed track, hypothesis and Poisson budgets; Murty's ranked assignment);
- ``_pmb``: :class:`PMB` (the track-oriented PMB filter of Williams 2015: the same step with the
  association marginals of :mod:`jaxtrack.association`);
- ``_glmb``: :class:`GLMB` (the δ-GLMB filter of Vo & Vo 2013 with the joint prediction–update of
  Vo, Vo & Hoang 2017: Murty's ranked assignment over all prior hypotheses, fixed track and
  hypothesis budgets) and :class:`LMB` (Reuter et al. 2014: the same step projected to an LMB),
  :class:`GLMBState`;
- ``_labelled_projection``: what they keep of the ranked posterior, the projection strategies
  :class:`DeltaGLMB` and :class:`LMBProjection` (each label a Gaussian mixture of at most
  ``max_components`` components);
- ``_labelled_ranking``: their hypothesis-generation strategies :class:`MurtyRanking` (the
  default) and :class:`GibbsSampling` (VVH17's Gibbs sampler);
- ``_two_sensors``: :class:`TwoSensorScenario`, :func:`simulate_two_sensors` (the same targets
  seen by two sensors, the scans stacked ``(T, 2, M, m)``), :class:`TwoSensorTrajectory`;
- ``_track_fusion``: :class:`TrackFusionTracker` (two local trackers, one per sensor, and a fusion
  centre: track-to-track association, a :mod:`jaxtrack.fusion` rule, fused identities in a
  fixed-capacity :class:`FusedTable`), :class:`TrackFusionState`, :class:`TrackFusionStepInfo`;
- ``_learning``: :func:`fit_detection_and_clutter` (``P_D`` and the clutter density by maximum
  likelihood of the tracker's scan log-likelihood, with standard errors).
"""

from ._scenario import (
    CLUTTER as CLUTTER,
    PADDING as PADDING,
    CapacityWarning as CapacityWarning,
    MultiTargetTrajectory as MultiTargetTrajectory,
    Scan as Scan,
    Scenario as Scenario,
    simulate_scenario as simulate_scenario,
    simulate_scenarios as simulate_scenarios,
)
from ._named_scenarios import (
    VoVoLinearSettings as VoVoLinearSettings,
    Williams15Settings as Williams15Settings,
    crossing_targets as crossing_targets,
    vo_vo_linear as vo_vo_linear,
    williams15 as williams15,
)
from ._base import (
    AbstractMultiTargetFilter as AbstractMultiTargetFilter,
    Estimates as Estimates,
    MultiTargetResult as MultiTargetResult,
    run_multitarget as run_multitarget,
)
from ._evaluation import (
    MultiTargetMonteCarloResult as MultiTargetMonteCarloResult,
    TrackScores as TrackScores,
    multitarget_monte_carlo as multitarget_monte_carlo,
    score_tracks as score_tracks,
)
from ._mixture import (
    AbstractMixtureReduction as AbstractMixtureReduction,
    GaussianMixture as GaussianMixture,
    StoneSoupReduction as StoneSoupReduction,
    VoMaReduction as VoMaReduction,
)
from ._learning import (
    DetectionClutterFit as DetectionClutterFit,
    fit_detection_and_clutter as fit_detection_and_clutter,
)
from ._phd import (
    GMPHD as GMPHD,
    GMPHDMixture as GMPHDMixture,
    GMPHDStepInfo as GMPHDStepInfo,
    PHDResult as PHDResult,
    run_phd as run_phd,
)
from ._cphd import (
    CPHDResult as CPHDResult,
    CPHDState as CPHDState,
    GMCPHD as GMCPHD,
    GMCPHDStepInfo as GMCPHDStepInfo,
    run_cphd as run_cphd,
)
from ._multibernoulli import (
    PMBMResult as PMBMResult,
    PMBMState as PMBMState,
    PMBMStepInfo as PMBMStepInfo,
    run_pmbm as run_pmbm,
)
from ._multibernoulli import AbstractGlobalHypotheses as AbstractGlobalHypotheses
from ._pmbm import PMBM as PMBM, RankedAssignment as RankedAssignment
from ._pmb import PMB as PMB, MarginalProjection as MarginalProjection
from ._glmb import (
    GLMB as GLMB,
    LMB as LMB,
    AbstractLabelledFilter as AbstractLabelledFilter,
    GLMBState as GLMBState,
    GLMBStepInfo as GLMBStepInfo,
)
from ._labelled_projection import (
    AbstractLabelledProjection as AbstractLabelledProjection,
    DeltaGLMB as DeltaGLMB,
    LMBProjection as LMBProjection,
)
from ._labelled_ranking import (
    AbstractLabelledRanking as AbstractLabelledRanking,
    GibbsSampling as GibbsSampling,
    MurtyRanking as MurtyRanking,
)
from ._scenario import AbstractScenario as AbstractScenario
from ._two_sensors import (
    TwoSensorScenario as TwoSensorScenario,
    TwoSensorTrajectory as TwoSensorTrajectory,
    simulate_two_sensors as simulate_two_sensors,
)
from ._track_fusion import (
    FusedTable as FusedTable,
    TrackFusionState as TrackFusionState,
    TrackFusionStepInfo as TrackFusionStepInfo,
    TrackFusionTracker as TrackFusionTracker,
)
from ._tracker import (
    CONFIRMED as CONFIRMED,
    EMPTY as EMPTY,
    TENTATIVE as TENTATIVE,
    IntegratedExistence as IntegratedExistence,
    OnePointInitiator as OnePointInitiator,
    Tracker as Tracker,
    TrackerResult as TrackerResult,
    TrackerStepInfo as TrackerStepInfo,
    TrackManagement as TrackManagement,
    TrackTable as TrackTable,
    run_tracker as run_tracker,
)

__all__ = [
    "AbstractScenario",
    "TwoSensorScenario",
    "TwoSensorTrajectory",
    "simulate_two_sensors",
    "TrackFusionTracker",
    "TrackFusionState",
    "TrackFusionStepInfo",
    "FusedTable",
    "CLUTTER",
    "PADDING",
    "CapacityWarning",
    "MultiTargetTrajectory",
    "Scan",
    "Scenario",
    "crossing_targets",
    "williams15",
    "Williams15Settings",
    "vo_vo_linear",
    "VoVoLinearSettings",
    "simulate_scenario",
    "simulate_scenarios",
    "CONFIRMED",
    "EMPTY",
    "TENTATIVE",
    "IntegratedExistence",
    "OnePointInitiator",
    "Tracker",
    "TrackerResult",
    "TrackerStepInfo",
    "TrackManagement",
    "TrackTable",
    "run_tracker",
    "AbstractMultiTargetFilter",
    "Estimates",
    "MultiTargetResult",
    "run_multitarget",
    "MultiTargetMonteCarloResult",
    "multitarget_monte_carlo",
    "TrackScores",
    "score_tracks",
    "DetectionClutterFit",
    "fit_detection_and_clutter",
    "GaussianMixture",
    "AbstractMixtureReduction",
    "VoMaReduction",
    "StoneSoupReduction",
    "GMPHD",
    "GMPHDMixture",
    "GMPHDStepInfo",
    "PHDResult",
    "run_phd",
    "GMCPHD",
    "GMCPHDStepInfo",
    "CPHDState",
    "CPHDResult",
    "run_cphd",
    "PMBM",
    "PMB",
    "AbstractGlobalHypotheses",
    "RankedAssignment",
    "MarginalProjection",
    "PMBMState",
    "PMBMStepInfo",
    "PMBMResult",
    "run_pmbm",
    "GLMB",
    "LMB",
    "AbstractLabelledFilter",
    "AbstractLabelledProjection",
    "DeltaGLMB",
    "LMBProjection",
    "AbstractLabelledRanking",
    "MurtyRanking",
    "GibbsSampling",
    "GLMBState",
    "GLMBStepInfo",
]


_DEPRECATED = {"tracker_monte_carlo": "multitarget_monte_carlo", "TrackerMonteCarloResult": "MultiTargetMonteCarloResult"}


def __getattr__(name: str):
    """The former names of the Monte Carlo and its result (one release, with a DeprecationWarning)."""
    if name in _DEPRECATED:
        import warnings

        from .. import _deprecation
        from . import _evaluation

        warnings.warn(f"`jaxtrack.multitarget.{name}` is deprecated: use `{_DEPRECATED[name]}`; it will be removed in "
                      f"jaxtrack {_deprecation.REMOVED_IN}.", DeprecationWarning, stacklevel=2)
        return getattr(_evaluation, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

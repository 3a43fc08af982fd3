r"""The Gaussian-mixture PHD filter (Vo & Ma 2006) with a fixed component budget.

The PHD (first-moment intensity) ``v_k(x)`` of the multi-target state is a Gaussian mixture
``Σ_i w_i N(x; m_i, P_i)``; its integral ``Σ_i w_i`` is the expected number of targets. One step
is, in the notation of Vo & Ma (2006), "The Gaussian mixture probability hypothesis density
filter", IEEE Trans. Signal Process. 54(11), 4091-4104:

1. **predict** (Proposition 1; Table I, steps 1-2, without spawning): every component survives
   with weight ``P_S w`` and the moments of the single-target filter's ``predict``; the birth
   mixture ``γ_k`` (fixed weights, means, covariances) is appended;
2. **update** (Proposition 2; Table I, steps 3-4): the missed block ``(1 − P_D) w_i`` first,
   then, for every measurement ``z_j`` of the padded scan, the block
   ``w_ij = P_D w_i q_ij / (κ + P_D Σ_l w_l q_lj)`` with ``q_ij = N(z_j; ẑ_i, S_i)`` and the
   filter's conditioned moments: ``(1 + M_max)·J`` slots, ``J`` = capacity + births;
3. **reduce** (Table II, "pruning", with thresholds ``T``, ``U`` and ``J_max``): prune below
   ``T``, then one pass per output slot (at most ``J_max``), each taking the heaviest
   remaining component and merging every remaining one within squared Mahalanobis distance ``U``
   (measured with the candidate's covariance; :mod:`._reduction`). What is left when the slots are used up is
   counted (number and weight): an overflow is flagged, never silent, and :func:`run_phd` warns
   on the host (:class:`CapacityWarning`, as :func:`run_tracker` does).

Everything has a static shape, so :func:`run_phd` is one jitted ``lax.scan`` and is
differentiable in ``P_D``, ``P_S``, ``κ`` and the birth weights wherever the reduction's discrete
choices (prune, merge, seed order) do not flip: they are piecewise constant.

``reduction=StoneSoupReduction()`` reproduces Stone Soup's ``PHDUpdater`` + ``GaussianMixtureReducer``
(``stonesoup/updater/pointprocess.py``, ``stonesoup/mixturereducer/gaussianmixture.py``), which
differ from Tables I-II in five places:

- an undetected *birth* component is dropped (no missed term for births);
- a detected birth's weight is multiplied by ``P_S`` too (its hypothesiser re-tags detected
  births, and the updater applies ``P_S`` to every component not tagged "birth");
- pruned weight (``w < T``; Table II keeps ``w > T``) is spread evenly over the kept components;
- merging is pairwise against the *running* merged component, candidates in ascending weight
  order, with ``d < U``, and the merged weight is capped at 1 after every pair;
- a zero updated weight becomes machine epsilon (then pruned, its epsilon redistributed).

Not reproduced: Stone Soup's truncation to ``max_number_components`` (which redistributes the
truncated weight); here the budget is ``capacity`` and what exceeds it is counted instead.

Both reductions run as a ``while_loop`` over the merges actually made, with the fixed-loop
form as their derivative rule (:mod:`._reduction`: the measured costs are there).
"""

from __future__ import annotations

import math
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError, is_concrete
from ..association._gating import measurement_likelihoods
from ..filters._base import AbstractFilter
from ..models._base import AbstractStateSpaceModel
from ._base import AbstractMultiTargetFilter, Estimates, check_scans, scan_method, scan_ok, warn_capacity, warn_not_ok
from ._clutter import resolve_clutter
from ._mixture import (
    AbstractMixtureReduction,
    GaussianMixture,
    check_mixture,
    empty_mixture,
    legacy_mixture,
    legacy_reduction,
    reject_unknown,
)
from ._scenario import _positive_int



class GMPHDMixture(eqx.Module):
    """The GM-PHD filter's state: a Gaussian mixture in ``J_max`` fixed slots.

    **Fields** (``J`` = ``capacity``, ``n`` = state dimension):

    - ``weights`` ``(J,)``: the components' weights (expected target counts, dimensionless; 0 in
      free slots); ``means`` ``(J, n)``, ``covs`` ``(J, n, n)``: their moments in the state's
      units (free slots hold the first birth component, so that their discarded predictions stay
      finite); ``active`` ``(J,)`` bool: slots holding a component.
    - ``step`` ``()`` int: the index of the next scan.
    - ``num_dropped`` ``()`` int, ``dropped_weight`` ``()``: components (and their weight) that
      the reduction left over for want of slots, summed over all scans so far.
    - ``num_unreported`` ``()`` int: estimates the extraction found beyond the filter's
      ``max_estimates`` slots (not reported), summed over all scans so far.
    """

    weights: Float[Array, " J"]
    means: Float[Array, "J n"]
    covs: Float[Array, "J n n"]
    active: Bool[Array, " J"]
    step: Int[Array, ""]
    num_dropped: Int[Array, ""]
    dropped_weight: Float[Array, ""]
    num_unreported: Int[Array, ""]

    @property
    def cardinality(self) -> Float[Array, ""]:
        """The expected number of targets, ``Σ_i w_i`` (the intensity's integral; Vo & Ma 2006, §II-C)."""
        return jnp.sum(jnp.where(self.active, self.weights, 0.0))

    @property
    def overflow(self) -> Bool[Array, ""]:
        """True once the reduction left components over for want of slots."""
        return self.num_dropped > 0


class GMPHDStepInfo(NamedTuple):
    """What one :meth:`GMPHD.step` computed besides the new mixture.

    ``updated_cardinality`` ``()``: ``Σ w`` of the updated mixture before reduction;
    ``log_normalizer`` ``(M,)``: ``log(κ + P_D Σ_i w_i q_ij)`` per measurement (0 for padding);
    ``num_dropped`` ``()`` int, ``dropped_weight`` ``()``: left over by this scan's reduction;
    ``num_pruned`` ``()`` int: components pruned below ``T``; ``ok`` ``()`` bool: the scan's valid
    measurements and the updated mixture are finite (a NaN ``P_D`` or measurement makes it False).
    """

    updated_cardinality: Float[Array, ""]
    log_normalizer: Float[Array, " M"]
    num_dropped: Int[Array, ""]
    dropped_weight: Float[Array, ""]
    num_pruned: Int[Array, ""]
    ok: Bool[Array, ""]


def _scalar(name, value, *, low, high=None, open_low=False):
    x = jnp.asarray(value, float)
    if x.shape != ():
        raise InputError(f"`{name}` must be a scalar; got shape {x.shape}.")
    if is_concrete(x):
        v = float(x)
        ok = (v > low if open_low else v >= low) and (high is None or v <= high) and math.isfinite(v)
        if not ok:
            interval = f"{'(' if open_low else '['}{low}, {high if high is not None else 'inf'}{']' if high is not None else ')'}"
            raise InputError(f"`{name}` must lie in {interval}; got {v}.")
    return x


def _initial_mixture_checked(initial, n: int, capacity: int, capacity_name: str) -> GaussianMixture | None:
    """The time-0 intensity (a :class:`GaussianMixture` or None), which must fit in ``capacity`` slots."""
    initial = check_mixture("initial", initial, n, optional=True)
    if initial is not None and initial.num_components > capacity:
        raise InputError(f"`{capacity_name}` ({capacity}) must hold the {initial.num_components} initial components.")
    return initial


def _common_fields(filter, model, *, prob_survival, prob_detect, birth, capacity, reduction, gate,
                   max_estimates) -> dict:
    """The checked fields shared by the Gaussian-mixture filters (each argument as documented on
    :class:`GMPHD`), as a dict of attribute name to value."""
    if not isinstance(filter, AbstractFilter):
        raise InputError(f"`filter` must be a jaxtrack filter; got {type(filter).__name__}.")
    if filter.square_root:
        raise InputError("`filter` must carry covariances, not Cholesky factors (square-root filters are not supported).")
    if not isinstance(model, AbstractStateSpaceModel):
        raise InputError(f"`model` must be a jaxtrack state-space model; got {type(model).__name__}.")
    filter.check_model(model)
    capacity = _positive_int("capacity", capacity)  # mixture slots
    max_estimates = capacity if max_estimates is None else _positive_int("max_estimates", max_estimates)
    # A leaf, not a static field: gated and ungated filters share one compiled program.
    gate_ = jnp.asarray(gate, float)
    if gate_.shape != () or (is_concrete(gate_) and not float(gate_) > 0.0):
        raise InputError(f"`gate` must be a positive scalar Mahalanobis distance (inf: no gate); got {gate!r}.")
    return {
        "filter": filter, "model": model,
        "prob_survival": _scalar("prob_survival", prob_survival, low=0.0, high=1.0, open_low=True),
        "prob_detect": _scalar("prob_detect", prob_detect, low=0.0, high=1.0, open_low=True),
        "birth": check_mixture("birth", birth, model.state_dim), "reduction": reduction,
        "capacity": int(capacity), "gate": gate_, "max_estimates": int(max_estimates),
    }


class AbstractGaussianMixtureFilter(AbstractMultiTargetFilter):
    """What the Gaussian-mixture filters (GM-PHD, GM-CPHD, PMB, PMBM) share: a birth intensity, an
    optional time-0 intensity (:class:`GaussianMixture`), and the single-target filter and model
    every component follows. The ``birth_*``/``initial_*`` properties are their arrays (the
    time-0 one empty, ``(0, …)``, when there is none)."""

    filter: eqx.AbstractVar[AbstractFilter]
    birth: eqx.AbstractVar[GaussianMixture]
    initial: eqx.AbstractVar[GaussianMixture | None]

    @property
    def birth_weights(self) -> Float[Array, " B"]:
        return self.birth.weights

    @property
    def birth_means(self) -> Float[Array, "B n"]:
        return self.birth.means

    @property
    def birth_covs(self) -> Float[Array, "B n n"]:
        return self.birth.covs

    def _initial_arrays(self):
        if self.initial is None:
            return empty_mixture(self.model.state_dim)
        return self.initial.weights, self.initial.means, self.initial.covs

    @property
    def initial_weights(self) -> Float[Array, " J0"]:
        return self._initial_arrays()[0]

    @property
    def initial_means(self) -> Float[Array, "J0 n"]:
        return self._initial_arrays()[1]

    @property
    def initial_covs(self) -> Float[Array, "J0 n n"]:
        return self._initial_arrays()[2]


def _empty_mixture(f) -> GMPHDMixture:
    """No components (free slots hold the first birth component, see :class:`GMPHDMixture`)."""
    J, dtype = f.capacity, f.birth_means.dtype
    return GMPHDMixture(
        weights=jnp.zeros((J,), dtype),
        means=jnp.broadcast_to(f.birth_means[0], (J,) + f.birth_means.shape[1:]),
        covs=jnp.broadcast_to(f.birth_covs[0], (J,) + f.birth_covs.shape[1:]),
        active=jnp.zeros((J,), bool),
        step=jnp.zeros((), jnp.int32),
        num_dropped=jnp.zeros((), jnp.int32),
        dropped_weight=jnp.zeros((), dtype),
        num_unreported=jnp.zeros((), jnp.int32),
    )


def _in_slots(f, capacity: int, weights, means, covs):
    """``J0 <= capacity`` components in the first of ``capacity`` slots, as ``(weights, means,
    covs)``; the free slots hold weight 0 and ``f``'s first birth component (finite moments)."""
    pad, dtype = capacity - weights.shape[0], f.birth_means.dtype
    return (jnp.concatenate([weights.astype(dtype), jnp.zeros((pad,), dtype)]),
            jnp.concatenate([means.astype(dtype), jnp.broadcast_to(f.birth_means[0], (pad,) + means.shape[1:])]),
            jnp.concatenate([covs.astype(dtype), jnp.broadcast_to(f.birth_covs[0], (pad,) + covs.shape[1:])]))


def _initial_mixture(f) -> GMPHDMixture:
    """The time-0 intensity ``f.initial_*`` in the first slots (an empty mixture when none)."""
    w, m, P = _in_slots(f, f.capacity, f.initial_weights, f.initial_means, f.initial_covs)
    return eqx.tree_at(lambda x: (x.weights, x.means, x.covs, x.active), _empty_mixture(f), (w, m, P, w > 0.0))


def _predict_intensity(f, mixture: GMPHDMixture):
    """Survival and births for any module ``f`` with :class:`GMPHD`'s fields (see
    :meth:`GMPHD.predict`): ``(weights, means, covs, active, is_birth)``, ``J_max + B`` rows."""
    k = mixture.step
    mean, cov = jax.vmap(lambda x, P: f.filter.predict(f.model, x, P, k))(mixture.means, mixture.covs)
    B = f.birth_weights.shape[0]
    weights = jnp.concatenate([f.prob_survival * jnp.where(mixture.active, mixture.weights, 0.0), f.birth_weights])
    means = jnp.concatenate([mean, f.birth_means])
    covs = jnp.concatenate([cov, f.birth_covs])
    active = jnp.concatenate([mixture.active, jnp.ones((B,), bool)])
    is_birth = jnp.concatenate([jnp.zeros((f.capacity,), bool), jnp.ones((B,), bool)])
    return weights, means, covs, active, is_birth


def _pair_likelihoods(f, means, covs, active, measurements, valid, k):
    """Every (component, measurement) pair's ``log N(z_j; ẑ_i, S_i)`` ``(J, M)`` (−inf where the
    pair does not count), whether it counts (active component, valid and gated-in measurement)
    ``(J, M)``, and the filter's conditioned moments ``(J, M, ...)``."""
    loglik, nis, cond = jax.vmap(
        lambda x, C: measurement_likelihoods(f.filter, f.model, x, C, measurements, valid, k)
    )(means, covs)
    pair = active[:, None] & valid[None, :]
    # Stone Soup's DistanceHypothesiser keeps a pair when its distance < missed_distance; a NaN
    # NIS compares False (outside); with gate = inf every finite NIS is inside.
    pair = pair & (nis < f.gate.astype(nis.dtype) ** 2)
    # Padded or gated-out log-likelihoods may be −inf/NaN: −inf here, and every use selects it away
    # with a second `where`, so neither values nor gradients see it.
    return jnp.where(pair, loglik, -jnp.inf), pair, cond


def _updated_layout(w_miss, miss_active, w_det, pair, means, covs, cond):
    """The updated mixture's ``(1 + M)·J`` slots: the missed block ``(J,)`` first, then one block
    of ``J`` per measurement (slot ``(1 + j)·J + i``: component ``i`` on measurement ``j``)."""
    weights = jnp.concatenate([w_miss, w_det.T.reshape(-1)])
    m = jnp.concatenate([means, jnp.swapaxes(cond.mean, 0, 1).reshape((-1,) + means.shape[1:])])
    P = jnp.concatenate([covs, jnp.swapaxes(cond.cov, 0, 1).reshape((-1,) + covs.shape[1:])])
    active = jnp.concatenate([miss_active, pair.T.reshape(-1)])
    return weights, m, P, active


class GMPHD(AbstractGaussianMixtureFilter):
    r"""The GM-PHD filter of Vo & Ma (2006) with a fixed component budget ``J_max``.

    **Arguments:**

    - ``filter``: a jaxtrack :class:`~jaxtrack.filters.AbstractFilter` whose ``predict`` and
      ``update`` give each component's moments (the Kalman filter gives Table I exactly; an
      EKF or UKF gives the linearised GM-PHD of Vo & Ma §III-B). Square-root filters are refused.
    - ``model``: the single-target state-space model (motion and sensor) every target follows.
    - ``prob_survival``: ``P_S`` in ``(0, 1]``; ``prob_detect``: ``P_D`` in ``(0, 1]``.
    - ``clutter_density``: ``κ``, clutter points per unit measurement-space volume per scan
      (e.g. per m² for positions), ``> 0`` and finite (0 would make a measurement that no
      component reaches 0/0: use a small positive value for an almost clutter-free sensor); Stone
      Soup's name ``clutter_spatial_density`` is accepted too, or ``clutter_rate`` (points per scan)
      with ``clutter_volume`` (:mod:`jaxtrack.multitarget._clutter`).
    - ``birth``: the birth intensity ``γ_k``, a :class:`~jaxtrack.multitarget.GaussianMixture`
      (weights: expected births per scan).
    - ``capacity``: ``J_max``, the number of mixture slots after reduction (static).
    - ``reduction``: the mixture-reduction strategy: :class:`~jaxtrack.multitarget.VoMaReduction`
      (default: Table II with ``T`` = 1e-5, ``U`` = 4) or
      :class:`~jaxtrack.multitarget.StoneSoupReduction` (Stone Soup's conventions, module
      docstring). ``extraction_threshold``: the weight above which a component is reported as a
      target (default 0.5, Table III).
    - ``gate``: optional Mahalanobis distance ``sqrt(yᵀS⁻¹y)`` beyond which a measurement does not
      update a component (Stone Soup's ``DistanceHypothesiser(missed_distance=...)``); default
      ``inf``: no gate, as in Vo & Ma.
    - ``max_estimates``: the static number of estimate slots (default ``capacity``). GOSPA
      scoring of the estimates solves an assignment of this size (cubic cost): in a Monte Carlo
      keep it near the number of targets you expect (``benchmarks/measured/phd_batch.txt``: 783 ms
      a run of scoring at 100 slots, 7.5 ms at 24).
    - ``undetected_births``: keep Table I's missed-detection term ``(1 − P_D) w_b`` of the birth
      components (default True, as Vo & Ma). False drops it (Stone Soup's convention): measured
      (``benchmarks/measured/phd_reductions.txt``, 100 paired runs each), a broad birth component
      left undetected is otherwise merged by Table II into a nearby target component (its
      distance is measured in the candidate's covariance), widening it: mean GOSPA 47.1 → 36.5 m
      on ``crossing_targets()`` (c = 100 m; 2,192 capacity events → 0), 4.55 → 4.13 m on the
      Williams scenario, 4.24 → 3.98 m on a sparse one. Keep the default to reproduce Vo & Ma;
      drop the term when the birth intensity is broad compared with a target's component.
    - ``initial``: the intensity before the first scan, a :class:`~jaxtrack.multitarget.GaussianMixture`
      of ``J0 <= capacity`` components (default None: no target before the first births), e.g. the
      Poisson prior a PMB/PMBM filter starts from (its ``initial``).
    - Deprecated (one release): ``birth_weights``/``birth_means``/``birth_covs``,
      ``initial_*``, ``prune_threshold``/``merge_threshold`` and a string ``reduction``.

    ``P_S``, ``P_D``, ``κ``, the birth and initial mixtures, the thresholds and the gate are array leaves
    (differentiable, and changing them does not recompile :func:`run_phd`).

    **Raises:** :class:`~jaxtrack.InputError` naming the argument (a probability outside
    ``(0, 1]``, a negative density or threshold, birth arrays of the wrong shape, a birth
    covariance not symmetric positive definite, a non-positive ``capacity``, an unknown
    ``reduction``).

    Example (a constant-velocity target in the plane, positions measured)::

        model = constant_velocity(...)                      # any LinearGaussianModel
        phd = GMPHD(KalmanFilter(), model, prob_survival=0.99, prob_detect=0.9,
                    clutter_density=1e-4, birth=GaussianMixture([0.1], [m_b], [P_b]), capacity=50)
        result = run_phd(phd, scans.measurements, scans.valid)
        result.cardinality          # (T,) expected number of targets
        result.estimates[k][result.estimate_mask[k]]        # scan k's target states

    ??? cite "Reference"

        ```bibtex
        @article{vo2006gmphd,
          author  = {Vo, Ba-Ngu and Ma, Wing-Kin},
          title   = {The {G}aussian Mixture Probability Hypothesis Density Filter},
          journal = {IEEE Transactions on Signal Processing},
          volume  = {54}, number = {11}, pages = {4091--4104}, year = {2006}}
        ```
    """

    filter: AbstractFilter
    model: AbstractStateSpaceModel
    prob_survival: Float[Array, ""]
    prob_detect: Float[Array, ""]
    clutter_density: Float[Array, ""]
    birth: GaussianMixture
    initial: GaussianMixture | None
    reduction: AbstractMixtureReduction
    extraction_threshold: Float[Array, ""]
    capacity: int = eqx.field(static=True)
    gate: Float[Array, ""]
    max_estimates: int = eqx.field(static=True)
    undetected_births: bool = eqx.field(static=True)
    labelled: ClassVar[bool] = False

    def __init__(
        self,
        filter: AbstractFilter,
        model: AbstractStateSpaceModel,
        *,
        prob_survival: ArrayLike,
        prob_detect: ArrayLike,
        clutter_density: ArrayLike | None = None,
        birth: GaussianMixture | None = None,
        capacity: int,
        reduction: AbstractMixtureReduction | None = None,
        extraction_threshold: ArrayLike = 0.5,
        gate: ArrayLike = math.inf,
        max_estimates: int | None = None,
        initial: GaussianMixture | None = None,
        clutter_spatial_density: ArrayLike | None = None,
        clutter_rate: ArrayLike | None = None,
        clutter_volume: ArrayLike | None = None,
        undetected_births: bool = True,
        **deprecated,
    ):
        if not isinstance(undetected_births, (bool, np.bool_)):
            raise InputError(f"`undetected_births` must be a bool; got {undetected_births!r}.")
        self.undetected_births = bool(undetected_births)
        clutter_density, _, _ = resolve_clutter(
            "GMPHD", clutter_density=clutter_density, clutter_spatial_density=clutter_spatial_density,
            clutter_rate=clutter_rate, clutter_volume=clutter_volume)
        n = model.state_dim if isinstance(model, AbstractStateSpaceModel) else 0
        birth = legacy_mixture("birth", deprecated, birth, n, required=True)
        initial = legacy_mixture("initial", deprecated, initial, n, required=False)
        reduction = legacy_reduction(deprecated, reduction)
        reject_unknown("GMPHD", deprecated)
        for name, value in _common_fields(
            filter, model, prob_survival=prob_survival, prob_detect=prob_detect, birth=birth, capacity=capacity,
            reduction=reduction, gate=gate, max_estimates=max_estimates,
        ).items():
            setattr(self, name, value)
        self.extraction_threshold = _scalar("extraction_threshold", extraction_threshold, low=0.0)
        # κ = 0 leaves a measurement no component reaches as 0/0 (its weight is dropped in silence):
        # refused; a clutter-free model is a small positive κ.
        self.clutter_density = _scalar("clutter_density", clutter_density, low=0.0, open_low=True)
        self.initial = _initial_mixture_checked(initial, model.state_dim, self.capacity, "capacity")

    # ------------------------------------------------------------------------------------------
    def init(self) -> GMPHDMixture:
        """The intensity before the first scan: ``initial_*`` in the first slots, or none (births
        enter in :meth:`predict`)."""
        return _initial_mixture(self)

    def predict(self, mixture: GMPHDMixture):
        r"""Prediction (Vo & Ma 2006, Proposition 1; Table I, steps 1-2, no spawning): ``P_S w``, the
        filter's predicted moments, births appended.

        **Returns:** ``(weights, means, covs, active, is_birth)`` with ``J_max + B`` rows: the
        survivors first, then the birth components (at step ``k``, not predicted).
        """
        return _predict_intensity(self, mixture)

    def update(self, predicted, measurements, valid, k):
        r"""Update (Vo & Ma 2006, Proposition 2; Table I, steps 3-4): the missed block, then one
        block per measurement.

        ``w_i^{miss} = (1 − P_D) w_i`` (with ``reduction="stonesoup"``: 0 for births, and a birth's
        ``w_i`` is ``P_S w_γ`` in the detection terms) and

        .. math::

            w_{ij} = \frac{P_D w_i q_{ij}}{κ + P_D \sum_l w_l q_{lj}}, \qquad
            q_{ij} = N(z_j; ẑ_i, S_i),

        with the filter's conditioned mean and covariance. Slot ``(1 + j)·J + i`` holds
        component ``i`` updated on measurement ``j`` (slot ``i``: missed).

        **Returns:** ``(weights, means, covs, active, log_normalizer)``, the first four with
        ``(1 + M)·J`` rows; ``log_normalizer`` ``(M,)``.
        """
        w, m, P, active, is_birth = predicted
        loglik, pair, cond = _pair_likelihoods(self, m, P, active, measurements, valid, k)
        q = jnp.where(pair, jnp.exp(jnp.where(pair, loglik, 0.0)), 0.0)
        stonesoup = self.reduction.stonesoup_update
        if stonesoup:
            # Stone Soup's hypothesiser re-tags a detected birth component, so its updater applies
            # P_S to it as well (it applies P_S in the update, to every non-"birth" tag).
            w = jnp.where(is_birth, self.prob_survival * w, w)
        numer = self.prob_detect * w[:, None] * q  # (J, M)
        denom = self.clutter_density + jnp.sum(numer, axis=0)  # (M,)
        safe = jnp.where(denom > 0.0, denom, 1.0)
        w_det = jnp.where(pair, numer / safe[None, :], 0.0)
        # Table I keeps (1 − P_D)·w_b for every birth component; Stone Soup (and undetected_births
        # False) drops it: a broad undetected birth then cannot be merged into a target component.
        miss_active = active & ~is_birth if (stonesoup or not self.undetected_births) else active
        w_miss = jnp.where(miss_active, (1.0 - self.prob_detect) * w, 0.0)
        weights, means, covs, out_active = _updated_layout(w_miss, miss_active, w_det, pair, m, P, cond)
        if stonesoup:
            # Stone Soup replaces a zero weight by machine epsilon (to keep its reducer's divisions
            # finite); the component is then pruned, but its epsilon joins the redistributed weight.
            weights = jnp.where(out_active & (weights == 0.0), jnp.finfo(weights.dtype).eps, weights)
        log_normalizer = jnp.where(valid, jnp.log(safe), 0.0)
        return weights, means, covs, out_active, log_normalizer

    def reduce(self, weights, means, covs, active):
        r"""Pruning and merging (Vo & Ma 2006, Table II, §III-C) into ``J_max`` slots.

        With ``I = {i : w_i > T}``, each pass (until ``I`` is empty, at most ``J_max``) takes ``j = argmax_{i∈I} w_i``,
        ``L = {i ∈ I : (m_i − m_j)ᵀ P_i⁻¹ (m_i − m_j) ≤ U}`` and emits
        ``w̃ = Σ_L w_i``, ``m̃ = Σ_L w_i m_i / w̃``,
        ``P̃ = Σ_L w_i (P_i + (m̃ − m_i)(m̃ − m_i)ᵀ) / w̃``, then ``I ← I \ L``. What remains in
        ``I`` after ``J_max`` passes is counted, not stored (Vo & Ma instead keep the ``J_max``
        heaviest merged components; here the first ``J_max`` seeds, in decreasing seed weight).

        **Returns:** ``(weights, means, covs, active, num_dropped, dropped_weight, num_pruned)``.
        """
        return self.reduction(weights, means, covs, active, self.capacity, self.birth_means[0], self.birth_covs[0])

    def step(self, mixture: GMPHDMixture, measurements, valid) -> tuple[GMPHDMixture, GMPHDStepInfo]:
        """One scan: :meth:`predict`, :meth:`update` on the padded scan, :meth:`reduce`.

        **Arguments:** ``mixture``: the :class:`GMPHDMixture` after scan ``k − 1`` (or
        :meth:`init`); ``measurements`` ``(M, m)`` in the sensor's units (padding may be NaN);
        ``valid`` ``(M,)`` bool. **Returns:** ``(mixture, info)``.
        """
        dtype = mixture.weights.dtype
        measurements = jnp.asarray(measurements, dtype)
        valid = jnp.asarray(valid, bool)
        predicted = self.predict(mixture)
        w, m, P, active, log_norm = self.update(predicted, measurements, valid, mixture.step)
        updated_card = jnp.sum(jnp.where(active, w, 0.0))
        w, m, P, active, n_drop, w_drop, n_pruned = self.reduce(w, m, P, active)
        new = GMPHDMixture(w, m, P, active, mixture.step + 1, mixture.num_dropped + n_drop,
                           mixture.dropped_weight + w_drop, mixture.num_unreported)
        new = eqx.tree_at(lambda s: s.num_unreported, new, mixture.num_unreported + self._unreported(new))
        ok = scan_ok(measurements, valid) & _mixture_finite(new)
        return new, GMPHDStepInfo(updated_card, log_norm, n_drop, w_drop, n_pruned, ok)

    def estimates(self, mixture: GMPHDMixture) -> Estimates:
        r"""Multi-target state extraction (Vo & Ma 2006, Table III).

        Every component with ``w_i >`` ``extraction_threshold`` gives ``round(w_i)`` copies of its
        mean (``round`` half up, ``⌊w + 1/2⌋``), padded to ``max_estimates`` rows.

        **Returns:** :class:`~jaxtrack.multitarget.Estimates` ``(states (E, n), mask (E,), ids (E,))``;
        the GM-PHD has no labels, so ``ids`` is the row index (−1 where masked).
        """
        states, mask, _ = self._extract(mixture)
        return Estimates(states, mask, jnp.where(mask, jnp.arange(self.max_estimates, dtype=jnp.int32), -1))

    def capacity_events(self, mixture: GMPHDMixture) -> Int[Array, ""]:
        """Components the reduction left over for want of slots, plus estimates beyond the
        ``max_estimates`` slots (not reported), summed over the scans so far."""
        return mixture.num_dropped + mixture.num_unreported

    def capacity_message(self, events: int) -> str:
        return (f"the GM-PHD's budgets were too small: {events} components left over by the reduction "
                f"(capacity {self.capacity}) or estimates beyond max_estimates={self.max_estimates} (not "
                "reported); raise `capacity` or `max_estimates`")

    def _unreported(self, mixture: GMPHDMixture) -> Int[Array, ""]:
        """Estimates of Table III beyond the ``max_estimates`` slots."""
        return jnp.maximum(self._extract(mixture)[2] - self.max_estimates, 0).astype(jnp.int32)

    def _extract(self, mixture: GMPHDMixture):
        """Table III: ``(states (E, n), mask (E,), count ())``, ``count`` the number of estimates
        before padding (more than ``E`` means some were not stored)."""
        w = jnp.where(mixture.active, mixture.weights, 0.0)
        copies = jnp.where(w > self.extraction_threshold.astype(w.dtype), jnp.floor(w + 0.5), 0.0).astype(jnp.int32)
        ends = jnp.cumsum(copies)
        E = self.max_estimates
        e = jnp.arange(E)
        src = jnp.searchsorted(ends, e, side="right")
        mask = e < ends[-1]
        states = jnp.where(mask[:, None], mixture.means[jnp.minimum(src, self.capacity - 1)], 0.0)
        return states, mask, ends[-1]


class PHDResult(eqx.Module):
    """A GM-PHD run over ``T`` scans.

    **Fields** (``J`` = capacity, ``E`` = ``max_estimates``): ``weights`` ``(T, J)``, ``means``
    ``(T, J, n)``, ``covs`` ``(T, J, n, n)``, ``active`` ``(T, J)``: the reduced mixture after each
    scan; ``cardinality`` ``(T,)``: ``Σ w`` after reduction; ``updated_cardinality`` ``(T,)``: before
    it; ``estimates`` ``(T, E, n)``, ``estimate_mask`` ``(T, E)``, ``num_estimates`` ``(T,)``
    (Table III); ``num_dropped`` ``(T,)``, ``dropped_weight`` ``(T,)``: left over per scan for
    want of slots; ``ok`` ``(T,)``: the scan's step was finite (:class:`GMPHDStepInfo`); ``overflow`` ``()``: some scan left components over; ``final``: the last
    :class:`GMPHDMixture`.
    """

    weights: Float[Array, "T J"]
    means: Float[Array, "T J n"]
    covs: Float[Array, "T J n n"]
    active: Bool[Array, "T J"]
    cardinality: Float[Array, " T"]
    updated_cardinality: Float[Array, " T"]
    estimates: Float[Array, "T E n"]
    estimate_mask: Bool[Array, "T E"]
    num_estimates: Int[Array, " T"]
    num_dropped: Int[Array, " T"]
    dropped_weight: Float[Array, " T"]
    ok: Bool[Array, " T"]
    overflow: Bool[Array, ""]
    final: GMPHDMixture

    @property
    def scan_overflow(self) -> Bool[Array, " T"]:
        """Per scan: True where the reduction left components over for want of slots."""
        return self.num_dropped > 0


def _mixture_finite(mixture: GMPHDMixture) -> Bool[Array, ""]:
    """The active components' weights and means are finite."""
    a = mixture.active
    return jnp.all(~a | jnp.isfinite(mixture.weights)) & jnp.all(~a[:, None] | jnp.isfinite(mixture.means))


def _record_phd(phd, mixture, info):
    states, mask, count = phd._extract(mixture)
    return (mixture.weights, mixture.means, mixture.covs, mixture.active, mixture.cardinality,
            info.updated_cardinality, states, mask, count, info.num_dropped, info.dropped_weight, info.ok)


def _run_phd(phd, measurements, valid):
    final, outs = scan_method(phd, measurements, valid, _record_phd)
    return PHDResult(*outs, final.overflow, final)


def run_phd(phd: GMPHD, measurements: ArrayLike, valid: ArrayLike, *, warn: bool = True) -> PHDResult:
    """Run a GM-PHD filter over ``T`` scans: one jitted ``lax.scan`` of :meth:`GMPHD.step`.

    **Arguments:**

    - ``phd``: the :class:`GMPHD`.
    - ``measurements``: ``(T, M, m)`` padded scans in the sensor's units (padding may be NaN);
      ``valid``: boolean ``(T, M)``, False for padding (a scenario's ``trajectory.scans``).
    - ``warn``: warn (:class:`CapacityWarning`) on the host when the reduction left components
      over for want of slots or estimates did not fit ``max_estimates`` (concrete results only).

    **Returns:** a :class:`PHDResult`.

    **Raises:** :class:`~jaxtrack.InputError` naming ``phd``, ``measurements`` or ``valid``.
    """
    if not isinstance(phd, GMPHD):
        raise InputError(f"`phd` must be a GMPHD; got {type(phd).__name__}.")
    measurements, valid = check_scans(measurements, valid, phd.model.meas_dim)
    result = _run_phd(phd, measurements, valid)
    if warn:
        warn_capacity(phd, phd.capacity_events(result.final))
        warn_not_ok(phd, result.ok)
    return result

r"""The multi-Bernoulli state and the steps the PMBM (:mod:`._pmbm`) and PMB (:mod:`._pmb`)
filters share: the checked configuration, the prior, the prediction, the Poisson part's update
and the new tracks it starts, each local hypothesis's miss and detection weights, the placement
of new tracks in free slots and the removal of dead ones, the estimates, and :func:`run_pmbm`.

The layout and the equations are those of García-Fernández, Williams, Granström & Svensson (2018),
"Poisson multi-Bernoulli mixture filter: direct derivation and implementation", IEEE Trans.
Aerosp. Electron. Syst. 54(4), 1883-1901 (G18), described in :mod:`._pmbm`.
"""

from __future__ import annotations

import abc
import warnings
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError, is_concrete
from ..association._gating import measurement_likelihoods
from ._base import Estimates, check_scans, scan_method, scan_ok
from ..filters._base import AbstractFilter
from ..models._base import AbstractStateSpaceModel
from ._clutter import resolve_clutter
from ._mixture import AbstractMixtureReduction, GaussianMixture, legacy_mixture, legacy_reduction, reject_unknown
from ._phd import (
    AbstractGaussianMixtureFilter,
    _common_fields,
    _in_slots,
    _initial_mixture_checked,
    _pair_likelihoods,
    _scalar,
)
from ._scenario import CapacityWarning, _positive_int

class PMBMState(eqx.Module):
    """A PMBM (or PMB) density in fixed slots.

    **Fields** (``J`` = ``poisson_capacity``, ``N`` = ``max_tracks``, ``H`` = ``max_hypotheses``
    (1 for :class:`~jaxtrack.multitarget.PMB`), ``n`` = state dimension):

    - Poisson part: ``poisson_weights`` ``(J,)`` (expected numbers of undetected targets),
      ``poisson_means`` ``(J, n)``, ``poisson_covs`` ``(J, n, n)``, ``poisson_active`` ``(J,)``.
    - Tracks: ``existence`` ``(N, H)`` (``r`` of each local hypothesis), ``means`` ``(N, H, n)``,
      ``covs`` ``(N, H, n, n)``, ``local_active`` ``(N, H)``; ``track_active`` ``(N,)``,
      ``track_id`` ``(N,)`` int (unique over a run, from 0), ``born_at`` ``(N,)`` int (the scan
      of the measurement that started it).
    - Global hypotheses: ``hypotheses`` ``(H, N)`` int (the local hypothesis each track takes,
      −1 where the track is not in the hypothesis), ``log_weights`` ``(H,)`` (normalised,
      ``−inf`` in free rows), ``hypothesis_active`` ``(H,)``.
    - ``step`` ``()`` int: the next scan's index; ``next_id`` ``()`` int; ``num_dropped_tracks``
      ``()`` int: new tracks that found no free slot, over the run; ``poisson_num_dropped``,
      ``poisson_dropped_weight``: Poisson components (and weight) left over by the reduction;
      ``assignment_overflow`` ``()`` int: gated measurements and tracks the PMBM's ranked
      assignment had no room for (``assignment_rows``, ``assignment_tracks``), over the run;
      ``association_failures`` ``()`` int: scans the PMB's associator could not answer (its
      ``ok`` False, e.g. a gating cluster beyond exact JPDA's caps), over the run.
    """

    poisson_weights: Float[Array, " J"]
    poisson_means: Float[Array, "J n"]
    poisson_covs: Float[Array, "J n n"]
    poisson_active: Bool[Array, " J"]
    existence: Float[Array, "N H"]
    means: Float[Array, "N H n"]
    covs: Float[Array, "N H n n"]
    local_active: Bool[Array, "N H"]
    track_active: Bool[Array, " N"]
    track_id: Int[Array, " N"]
    born_at: Int[Array, " N"]
    hypotheses: Int[Array, "H N"]
    log_weights: Float[Array, " H"]
    hypothesis_active: Bool[Array, " H"]
    step: Int[Array, ""]
    next_id: Int[Array, ""]
    num_dropped_tracks: Int[Array, ""]
    poisson_num_dropped: Int[Array, ""]
    poisson_dropped_weight: Float[Array, ""]
    assignment_overflow: Int[Array, ""]
    association_failures: Int[Array, ""]

    @property
    def num_hypotheses(self) -> Int[Array, ""]:
        """The number of global hypotheses held."""
        return jnp.sum(self.hypothesis_active).astype(jnp.int32)

    @property
    def overflow(self) -> Bool[Array, ""]:
        """True once a new track found no free slot, the Poisson reduction left components over or
        the ranked assignment had no room for a gated measurement or track."""
        return (self.num_dropped_tracks > 0) | (self.poisson_num_dropped > 0) | (self.assignment_overflow > 0)

    def expected_cardinality(self) -> Float[Array, ""]:
        """``E|X|``: the Poisson mass plus ``Σ_h w_h Σ_t r_{t, h(t)}`` (G18 Sec. II)."""
        ppp = jnp.sum(jnp.where(self.poisson_active, self.poisson_weights, 0.0))
        return ppp + jnp.sum(_hypothesis_weights(self) * _hypothesis_existence_sums(self))


class PMBMStepInfo(NamedTuple):
    """What one step computed besides the new density: ``num_hypotheses`` ``()`` int after
    pruning; ``num_tracks`` ``()`` int; ``num_dropped_tracks`` ``()`` int (this scan);
    ``log_likelihood`` ``()``: ``log`` of the scan's predictive likelihood up to the hypotheses
    not kept (``logsumexp`` of the unnormalised posterior hypothesis weights, with the Poisson
    term ``−Σ P_D w``; G18 eq. (25)); ``association_ok`` ``()`` bool: the PMB's associator answered
    within its capacity (always True for the PMBM); ``assignment_rows``, ``assignment_tracks``
    ``()`` int: the gated measurements and the tracks they reach, the size the PMBM's ranked
    assignment needed this scan (0 for the PMB); ``ok`` ``()`` bool: the associator answered and the
    valid measurements and the log-likelihood are finite (set by the filter's ``step``)."""

    num_hypotheses: Int[Array, ""]
    num_tracks: Int[Array, ""]
    num_dropped_tracks: Int[Array, ""]
    log_likelihood: Float[Array, ""]
    association_ok: Bool[Array, ""]
    assignment_rows: Int[Array, ""]
    assignment_tracks: Int[Array, ""]
    ok: Bool[Array, ""] | bool = True


def _hypothesis_weights(state):
    return jnp.where(state.hypothesis_active, jnp.exp(jnp.where(state.hypothesis_active, state.log_weights, 0.0)), 0.0)


def _hypothesis_existence_sums(state):
    l = state.hypotheses  # (H, N)
    present = (l >= 0) & state.track_active[None, :]
    r = jnp.take_along_axis(state.existence.T, jnp.maximum(l, 0), axis=0)  # (H, N): r[t, l[h, t]]
    return jnp.sum(jnp.where(present, r, 0.0), axis=1)


# ------------------------------------------------------------------------------------------------
# Shared by PMBM and PMB: checked configuration, init, predict, the Poisson update, track likelihoods,
# placement of new tracks, estimates.


def _mb_fields(filter, model, *, prob_survival, prob_detect, clutter: dict, birth, initial, poisson_capacity,
               max_tracks, poisson_reduction, existence_threshold, estimation_threshold, gate, deprecated: dict,
               cls: str) -> dict:
    """The checked fields of :class:`PMBM` and :class:`~jaxtrack.multitarget.PMB` (as documented
    there); ``clutter`` the clutter keywords (:func:`._clutter.resolve_clutter`), ``deprecated`` the
    former keywords (``birth_*``, ``initial_*``,
    ``poisson_prune_threshold``, ``poisson_merge_threshold``)."""
    n = model.state_dim if isinstance(model, AbstractStateSpaceModel) else 0
    birth = legacy_mixture("birth", deprecated, birth, n, required=True)
    initial = legacy_mixture("initial", deprecated, initial, n, required=False)
    poisson_reduction = legacy_reduction(deprecated, poisson_reduction, prefix="poisson_", allow_string=False)
    reject_unknown(cls, deprecated)
    base = _common_fields(
        filter, model, prob_survival=prob_survival, prob_detect=prob_detect, birth=birth, capacity=poisson_capacity,
        reduction=poisson_reduction, gate=gate, max_estimates=None,
    )
    # G18's prior is the Poisson intensity the first scan updates; by default the birth intensity.
    initial = _initial_mixture_checked(base["birth"] if initial is None else initial, model.state_dim,
                                       base["capacity"], "poisson_capacity")
    return {
        "filter": base["filter"], "model": base["model"], "prob_survival": base["prob_survival"],
        "prob_detect": base["prob_detect"],
        # κ = 0 would make a measurement no Poisson component or track reaches impossible (its new
        # track's weight log(e + κ) = −inf, an infeasible assignment): refused, as the PMB always did.
        "clutter_density": _scalar("clutter_density", resolve_clutter(cls, **clutter)[0], low=0.0, open_low=True),
        "birth": base["birth"], "initial": initial, "poisson_reduction": poisson_reduction,
        "poisson_capacity": base["capacity"], "max_tracks": _positive_int("max_tracks", max_tracks),
        "existence_threshold": _scalar("existence_threshold", existence_threshold, low=0.0, high=1.0),
        "estimation_threshold": _scalar("estimation_threshold", estimation_threshold, low=0.0, high=1.0),
        "gate": base["gate"],
    }


def _init_state(f, H: int) -> PMBMState:
    J, N, dtype = f.poisson_capacity, f.max_tracks, f.birth_means.dtype
    n = f.birth_means.shape[1]
    w0, m0, P0 = _in_slots(f, J, f.initial_weights, f.initial_means, f.initial_covs)
    i32 = jnp.int32
    return PMBMState(
        poisson_weights=w0, poisson_means=m0, poisson_covs=P0,
        poisson_active=jnp.arange(J) < f.initial_weights.shape[0],
        existence=jnp.zeros((N, H), dtype),
        means=jnp.broadcast_to(f.birth_means[0], (N, H, n)),
        covs=jnp.broadcast_to(f.birth_covs[0], (N, H, n, n)),
        local_active=jnp.zeros((N, H), bool),
        track_active=jnp.zeros((N,), bool),
        track_id=jnp.full((N,), -1, i32),
        born_at=jnp.full((N,), -1, i32),
        # One global hypothesis with no tracks: weight 1.
        hypotheses=jnp.full((H, N), -1, i32),
        log_weights=jnp.where(jnp.arange(H) == 0, 0.0, -jnp.inf).astype(dtype),
        hypothesis_active=jnp.arange(H) == 0,
        step=jnp.zeros((), i32), next_id=jnp.zeros((), i32), num_dropped_tracks=jnp.zeros((), i32),
        poisson_num_dropped=jnp.zeros((), i32), poisson_dropped_weight=jnp.zeros((), dtype),
        assignment_overflow=jnp.zeros((), i32), association_failures=jnp.zeros((), i32),
    )


def _predict(f, state: PMBMState) -> PMBMState:
    """G18 Sec. IV-A (Theorem 1 for the Poisson part): survival and births, then the Poisson
    reduction into ``poisson_capacity`` slots."""
    k = state.step
    pm, pc = jax.vmap(lambda x, P: f.filter.predict(f.model, x, P, k))(state.poisson_means, state.poisson_covs)
    w = jnp.concatenate([f.prob_survival * jnp.where(state.poisson_active, state.poisson_weights, 0.0), f.birth_weights])
    m = jnp.concatenate([pm, f.birth_means])
    P = jnp.concatenate([pc, f.birth_covs])
    act = jnp.concatenate([state.poisson_active, jnp.ones(f.birth_weights.shape, bool)])
    w, m, P, act, n_drop, w_drop, _ = f.poisson_reduction(w, m, P, act, f.poisson_capacity, f.birth_means[0],
                                                          f.birth_covs[0])
    N, H, n = state.means.shape
    tm, tc = jax.vmap(lambda x, P: f.filter.predict(f.model, x, P, k))(
        state.means.reshape(N * H, n), state.covs.reshape(N * H, n, n))
    return eqx.tree_at(
        lambda s: (s.poisson_weights, s.poisson_means, s.poisson_covs, s.poisson_active, s.existence, s.means,
                   s.covs, s.poisson_num_dropped, s.poisson_dropped_weight),
        state,
        (w, m, P, act, f.prob_survival * state.existence, tm.reshape(N, H, n), tc.reshape(N, H, n, n),
         state.poisson_num_dropped + n_drop, state.poisson_dropped_weight + w_drop),
    )


def _maybe_predict(f, state: PMBMState) -> PMBMState:
    """Scan 0 updates the prior (the initial intensity); every later scan is predicted first."""
    predicted = _predict(f, state)
    first = state.step == 0
    return jax.tree_util.tree_map(lambda a, b: jnp.where(first, a, b), state, predicted)


def _new_tracks(f, state, z, valid, k):
    """The Poisson part's update (G18 Theorem 2, eqs. (27)-(29), (33)): for every measurement ``j``
    the Bernoulli of its new track ``(r_j, mean_j, cov_j)``, its log weight ``log(e_j + κ)`` and
    the undetected intensity ``(1 − P_D) w``."""
    loglik, pair, cond = _pair_likelihoods(f, state.poisson_means, state.poisson_covs, state.poisson_active, z, valid, k)
    logw = jnp.log(jnp.where(state.poisson_active, state.poisson_weights, 1.0))
    la = jnp.where(pair, jnp.log(f.prob_detect) + logw[:, None] + loglik, -jnp.inf)  # (J, M)
    a_max = jnp.max(la, axis=0)
    any_pair = jnp.isfinite(a_max)
    a = jnp.where(pair, jnp.exp(la - jnp.where(any_pair, a_max, 0.0)[None, :]), 0.0)  # scaled by exp(-a_max)
    a_sum = jnp.sum(a, axis=0)
    safe = jnp.where(any_pair, a_sum, 1.0)
    mean = jnp.einsum("jm,jmn->mn", a, cond.mean) / safe[:, None]
    d = cond.mean - mean[None]
    cov = jnp.einsum("jm,jmnp->mnp", a, cond.cov + d[..., :, None] * d[..., None, :]) / safe[:, None, None]
    log_e = jnp.where(any_pair, a_max + jnp.log(safe), -jnp.inf)
    kappa = f.clutter_density.astype(z.dtype)
    log_weight = jnp.logaddexp(log_e, jnp.log(kappa))  # log(e + κ)
    r = jnp.where(any_pair, jnp.exp(log_e - log_weight), 0.0)
    # A measurement no Poisson component updates starts an empty track (r = 0, removed at once):
    # its moments are the first birth component's, finite and unused.
    mean = jnp.where(any_pair[:, None], mean, f.birth_means[0])
    cov = jnp.where(any_pair[:, None, None], cov, f.birth_covs[0])
    r = jnp.where(valid, r, 0.0)
    ppp_weights = (1.0 - f.prob_detect) * state.poisson_weights
    return r, mean, cov, jnp.where(valid, log_weight, 0.0), ppp_weights


def _track_weights(f, state, z, valid, k):
    """Every local hypothesis's miss and detection log weights (G18 eqs. (31)-(32)):
    ``(log_miss (N, H), log_det (N, H, M), r_miss (N, H))``, −inf where a pair does not count
    (inactive local hypothesis, padded or gated-out measurement)."""
    N, H, n = state.means.shape
    loglik, nis, _ = jax.vmap(lambda x, P: measurement_likelihoods(f.filter, f.model, x, P, z, valid, k))(
        state.means.reshape(N * H, n), state.covs.reshape(N * H, n, n))
    loglik = loglik.reshape(N, H, -1)
    nis = nis.reshape(N, H, -1)
    live = state.local_active & state.track_active[:, None]
    r = state.existence
    pd = f.prob_detect.astype(r.dtype)
    log_miss = jnp.where(live, jnp.log1p(-r * pd), -jnp.inf)
    r_miss = r * (1.0 - pd) / jnp.where(live, 1.0 - r * pd, 1.0)
    pair = live[:, :, None] & valid[None, None, :] & (nis < f.gate.astype(nis.dtype) ** 2)
    log_rpd = jnp.log(jnp.where(live & (r > 0.0), r * pd, 1.0))
    log_det = jnp.where(pair & (r > 0.0)[:, :, None], log_rpd[:, :, None] + jnp.where(pair, loglik, 0.0), -jnp.inf)
    return log_miss, log_det, r_miss


def _detected_moments(f, means, covs, z, k):
    """The filter's conditioned moments of a batch of local hypotheses on chosen measurements."""
    m = z.shape[-1]
    observed = jnp.ones((m,), bool)
    cond = jax.vmap(lambda x, P, zz: f.filter.update(f.model, x, P, zz, observed, k))(means, covs, z)
    return cond.mean, cond.cov


def _place_tracks(f, keep_old, new_keep):
    """Free slots for the kept new tracks (scan order), counting those that find none.

    **Returns:** ``(slot_of_new (M,) int`` (``N`` = dropped), ``num_dropped)``."""
    N = f.max_tracks
    M = new_keep.shape[0]
    free = ~keep_old
    free_slots = jnp.nonzero(free, size=M, fill_value=N)[0]
    num_free = jnp.sum(free)
    rank = jnp.cumsum(new_keep) - 1
    placed = new_keep & (rank < num_free)
    slot = jnp.where(placed, free_slots[jnp.clip(rank, 0, M - 1)], N)
    num_dropped = jnp.sum(new_keep & ~placed).astype(jnp.int32)
    return slot, num_dropped


def _merge_duplicates(table, log_w, active):
    """Global hypotheses that became equal (a track removed) merged into the first of each group,
    their weights summed (the reference's ``unique(..., 'rows')``)."""
    same = jnp.all(table[:, None, :] == table[None, :, :], axis=-1) & active[:, None] & active[None, :]
    first = jnp.argmax(same, axis=1)  # the first equal row (itself if none earlier)
    is_rep = active & (first == jnp.arange(table.shape[0]))
    merged = jax.ops.segment_max(jnp.where(active, log_w, -jnp.inf), first, num_segments=table.shape[0])
    m_safe = jnp.where(jnp.isfinite(merged), merged, 0.0)
    summed = jax.ops.segment_sum(jnp.where(active, jnp.exp(log_w - m_safe[first]), 0.0), first,
                                 num_segments=table.shape[0])
    new_log_w = jnp.where(is_rep, m_safe + jnp.log(jnp.where(is_rep, summed, 1.0)), -jnp.inf)
    return new_log_w, is_rep


def _estimates(f, state):
    """Estimator 1 of G18 Sec. VI (the reference's ``PoissonMBMtarget_estimate1.m``): the most
    likely global hypothesis; its tracks with ``r >`` ``estimation_threshold``.

    **Returns:** ``(states (N, n), mask (N,), track_id (N,))`` by track slot."""
    best = jnp.argmax(jnp.where(state.hypothesis_active, state.log_weights, -jnp.inf))
    l = state.hypotheses[best]
    present = (l >= 0) & state.track_active
    li = jnp.maximum(l, 0)
    idx = jnp.arange(f.max_tracks)
    r = state.existence[idx, li]
    mask = present & (r > f.estimation_threshold.astype(r.dtype))
    states = jnp.where(mask[:, None], state.means[idx, li], 0.0)
    return states, mask, jnp.where(mask, state.track_id, -1)


def _finish(f, state, *, existence, means, covs, local_active, table, log_w, hyp_active, new_r, new_mean,
            new_cov, new_in, k, H):
    """Shared end of an update: remove tracks whose local hypotheses all have ``r <=``
    ``existence_threshold``; place the new tracks (``new_in`` ``(H, M)``: hypothesis ``h`` holds
    new track ``j``); merge global hypotheses that became equal.

    ``existence``… ``local_active`` are the updated existing tracks ``(N, H, ...)``, ``table`` their
    columns of the posterior hypotheses ``(H, N)``."""
    N = f.max_tracks
    thr = f.existence_threshold.astype(existence.dtype)
    used_old = jnp.any(table >= 0, axis=0) & state.track_active
    keep_old = used_old & jnp.any(local_active & (existence > thr), axis=1)
    new_used = jnp.any(new_in & hyp_active[:, None], axis=0)
    new_keep = new_used & (new_r > thr)
    slot, n_drop = _place_tracks(f, keep_old, new_keep)
    table = jnp.where(keep_old[None, :], table, -1)
    local_active = local_active & keep_old[:, None]
    new_col = jnp.where(new_in, 0, -1).astype(jnp.int32)  # (H, M): local hypothesis 0 of new track j, or absent
    table = table.at[:, slot].set(new_col, mode="drop")
    placed = slot < N
    existence = existence.at[slot, 0].set(new_r, mode="drop")
    means = means.at[slot, 0].set(new_mean, mode="drop")
    covs = covs.at[slot, 0].set(new_cov, mode="drop")
    local_active = local_active.at[slot].set(jnp.arange(H)[None, :] == 0, mode="drop")
    track_active = keep_old.at[slot].set(True, mode="drop")
    new_ids = (state.next_id + jnp.cumsum(placed) - 1).astype(jnp.int32)
    track_id = jnp.where(keep_old, state.track_id, -1).at[slot].set(new_ids, mode="drop")
    born_at = jnp.where(keep_old, state.born_at, -1).at[slot].set(jnp.asarray(k, jnp.int32), mode="drop")
    table = jnp.where(hyp_active[:, None], table, -1)
    log_w, hyp_active = _merge_duplicates(table, log_w, hyp_active)
    table = jnp.where(hyp_active[:, None], table, -1)
    top = jnp.max(jnp.where(hyp_active, log_w, -jnp.inf))
    log_w = jnp.where(hyp_active, log_w - (top + jnp.log(jnp.sum(jnp.where(hyp_active, jnp.exp(log_w - top), 0.0)))),
                      -jnp.inf)
    return eqx.tree_at(
        lambda s: (s.existence, s.means, s.covs, s.local_active, s.track_active, s.track_id, s.born_at,
                   s.hypotheses, s.log_weights, s.hypothesis_active, s.next_id, s.num_dropped_tracks),
        state,
        (jnp.where(local_active, existence, 0.0), means, covs, local_active, track_active, track_id, born_at,
         table, log_w, hyp_active, state.next_id + jnp.sum(placed).astype(jnp.int32), state.num_dropped_tracks + n_drop),
    ), n_drop




class AbstractGlobalHypotheses(eqx.Module):
    """How a multi-Bernoulli filter's update forms its global hypotheses: the strategy that makes a
    :class:`~jaxtrack.multitarget.PMBM` (the ``H`` best hypotheses by ranked assignment,
    :class:`~jaxtrack.multitarget.RankedAssignment`) or a :class:`~jaxtrack.multitarget.PMB` (one
    hypothesis, the posterior projected through association marginals,
    :class:`~jaxtrack.multitarget.MarginalProjection`). Everything else of the two filters —
    prediction, the Poisson part, new tracks, pruning, estimates — is shared.

    ``max_hypotheses``: ``H``, the global hypotheses the state holds (static int).
    ``update(filter, state, measurements, valid) -> (state, PMBMStepInfo)``: the update of the
    predicted ``state`` of ``filter`` on one padded scan. ``check(filter)``: raise
    :class:`~jaxtrack.InputError` when ``filter``'s settings do not suit the strategy.
    """

    max_hypotheses: eqx.AbstractVar[int]

    @abc.abstractmethod
    def update(self, f, state: PMBMState, measurements, valid) -> tuple[PMBMState, PMBMStepInfo]:
        """One scan's update of ``f``'s predicted ``state``."""

    def check(self, f) -> None:
        """Nothing to check by default."""


class AbstractMultiBernoulliFilter(AbstractGaussianMixtureFilter):
    """What the PMBM (:class:`~jaxtrack.multitarget.PMBM`) and the PMB
    (:class:`~jaxtrack.multitarget.PMB`) share: the configuration fields (documented on each) and
    every step but the update, which each implements (ranked hypotheses, or association marginals)."""

    filter: AbstractFilter
    model: AbstractStateSpaceModel
    prob_survival: Float[Array, ""]
    prob_detect: Float[Array, ""]
    clutter_density: Float[Array, ""]
    birth: GaussianMixture
    initial: GaussianMixture
    poisson_reduction: AbstractMixtureReduction
    existence_threshold: Float[Array, ""]
    estimation_threshold: Float[Array, ""]
    gate: Float[Array, ""]
    poisson_capacity: int = eqx.field(static=True)
    max_tracks: int = eqx.field(static=True)
    hypotheses: AbstractGlobalHypotheses
    labelled: ClassVar[bool] = True

    @property
    def max_hypotheses(self) -> int:
        """``H``, the global hypotheses the state holds (the ``hypotheses`` strategy's; 1 for the PMB)."""
        return self.hypotheses.max_hypotheses

    def init(self) -> PMBMState:
        """The prior: the initial Poisson intensity, no tracks, one global hypothesis."""
        return _init_state(self, self.max_hypotheses)

    def predict(self, state: PMBMState) -> PMBMState:
        """Prediction (G18 Sec. IV-A): ``r ← P_S r``, the filter's predicted moments, the Poisson
        survival and births, the Poisson reduction."""
        return _predict(self, state)

    def update(self, state: PMBMState, measurements, valid) -> tuple[PMBMState, PMBMStepInfo]:
        """The update of the predicted density on one padded scan, by the ``hypotheses`` strategy
        (:class:`~jaxtrack.multitarget.RankedAssignment`: the PMBM's ``H`` best global hypotheses;
        :class:`~jaxtrack.multitarget.MarginalProjection`: the PMB's projection to one
        multi-Bernoulli through association marginals)."""
        return self.hypotheses.update(self, state, measurements, valid)

    def step(self, state: PMBMState, measurements, valid) -> tuple[PMBMState, PMBMStepInfo]:
        """One scan: :meth:`predict` (not on scan 0, which updates the prior), :meth:`update`.

        **Arguments:** ``state`` after scan ``k − 1`` (or :meth:`init`); ``measurements``
        ``(M, m)`` in the sensor's units (padding may hold anything); ``valid`` ``(M,)`` bool.
        """
        state, info = self.update(_maybe_predict(self, state), measurements, valid)
        answered = jnp.asarray(info.association_ok, bool)
        ok = answered & scan_ok(jnp.asarray(measurements), jnp.asarray(valid, bool)) & jnp.isfinite(info.log_likelihood)
        state = eqx.tree_at(lambda s: (s.step, s.association_failures), state,
                            (state.step + 1, state.association_failures + (~answered).astype(jnp.int32)))
        return state, info._replace(ok=ok)

    def estimates(self, state: PMBMState) -> Estimates:
        """The tracks of the most likely global hypothesis with ``r >`` ``estimation_threshold``
        (G18 Sec. VI, estimator 1; for the PMB, its one hypothesis). **Returns:**
        :class:`~jaxtrack.multitarget.Estimates` ``(states (N, n), mask (N,), track_id (N,))`` by
        track slot."""
        return Estimates(*_estimates(self, state))

    def capacity_events(self, state: PMBMState) -> Int[Array, ""]:
        """New tracks with no free slot, Poisson components left over, gated measurements or tracks
        the ranked assignment had no room for, and scans the associator could not answer, so far."""
        return (state.num_dropped_tracks + state.poisson_num_dropped + state.assignment_overflow
                + state.association_failures)

    def capacity_message(self, events: int) -> str:
        return (f"{events} capacity events in the {type(self).__name__} filter: new tracks with no free slot "
                f"(max_tracks={self.max_tracks}), Poisson components left over (poisson_capacity="
                f"{self.poisson_capacity}), gated measurements or tracks the ranked assignment had no room for "
                "(assignment_rows, assignment_tracks) or scans the associator could not answer (its cluster "
                "capacity; LoopyBP has none); raise them")

class PMBMResult(eqx.Module):
    """A PMBM or PMB run over ``T`` scans.

    **Fields** (``N`` = ``max_tracks``): ``estimates`` ``(T, N, n)``, ``estimate_mask`` ``(T, N)``,
    ``estimate_id`` ``(T, N)`` (track ids, −1 where masked); ``num_hypotheses`` ``(T,)``,
    ``num_tracks`` ``(T,)``; ``expected_cardinality`` ``(T,)``; ``log_likelihood`` ``(T,)``
    (:class:`PMBMStepInfo`); ``num_dropped_tracks`` ``(T,)`` per scan; ``association_ok``
    ``(T,)`` (the PMB's associator within its capacity); ``assignment_rows``,
    ``assignment_tracks`` ``(T,)`` (the PMBM's ranked-assignment sizes needed); ``ok`` ``(T,)``
    (:class:`PMBMStepInfo`); ``overflow`` ``()``: a new
    track found no slot or the Poisson reduction left components over; ``final``: the last
    :class:`PMBMState`.
    """

    estimates: Float[Array, "T N n"]
    estimate_mask: Bool[Array, "T N"]
    estimate_id: Int[Array, "T N"]
    num_hypotheses: Int[Array, " T"]
    num_tracks: Int[Array, " T"]
    expected_cardinality: Float[Array, " T"]
    log_likelihood: Float[Array, " T"]
    num_dropped_tracks: Int[Array, " T"]
    association_ok: Bool[Array, " T"]
    assignment_rows: Int[Array, " T"]
    assignment_tracks: Int[Array, " T"]
    ok: Bool[Array, " T"]
    overflow: Bool[Array, ""]
    final: PMBMState


def _record_mb(mb, state, info):
    states, mask, ids = mb.estimates(state)
    return (states, mask, ids, info.num_hypotheses, info.num_tracks, state.expected_cardinality(),
            info.log_likelihood, info.num_dropped_tracks, info.association_ok, info.assignment_rows,
            info.assignment_tracks, info.ok)


def _run(mb, measurements, valid):
    final, outs = scan_method(mb, measurements, valid, _record_mb)
    return PMBMResult(*outs, final.overflow, final)


def run_pmbm(mb, measurements: ArrayLike, valid: ArrayLike, *, warn: bool = True) -> PMBMResult:
    """Run a :class:`PMBM` or :class:`~jaxtrack.multitarget.PMB` filter over ``T`` scans: one
    jitted ``lax.scan`` of its ``step``.

    **Arguments:** ``mb``: the filter; ``measurements`` ``(T, M, m)`` padded scans (padding may
    be NaN), ``valid`` ``(T, M)`` bool (a scenario's ``trajectory.scans``); ``warn``: a host-side
    :class:`CapacityWarning` when a capacity was too small (concrete results only).

    **Returns:** a :class:`PMBMResult`. **Raises:** :class:`~jaxtrack.InputError` naming the argument.
    """
    if not isinstance(mb, AbstractMultiBernoulliFilter):
        raise InputError(f"`mb` must be a PMBM or PMB filter; got {type(mb).__name__}.")
    measurements, valid = check_scans(measurements, valid, mb.model.meas_dim)
    result = _run(mb, measurements, valid)
    if warn and is_concrete(result.overflow) and bool(result.overflow):
        fs = result.final
        warnings.warn(
            f"a capacity of the {type(mb).__name__} filter was too small: {int(fs.num_dropped_tracks)} new tracks found "
            f"no free slot (max_tracks={mb.max_tracks}) and the Poisson reduction left {int(fs.poisson_num_dropped)} "
            f"components over (poisson_capacity={mb.poisson_capacity}); the ranked assignment had no room for "
            f"{int(fs.assignment_overflow)} gated measurements or tracks (assignment_rows, assignment_tracks); "
            "raise them.",
            CapacityWarning, stacklevel=2,
        )
    if warn and is_concrete(result.association_ok) and not bool(jnp.all(result.association_ok)):
        warnings.warn(
            f"the associator of the {type(mb).__name__} filter could not answer on "
            f"{int(jnp.sum(~result.association_ok))} scans (its cluster capacity); use LoopyBP or raise it.",
            CapacityWarning, stacklevel=2,
        )
    return result

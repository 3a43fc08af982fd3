"""Multi-target trackers (GNN, JPDA, JIPDA) as one step function over a fixed-capacity track table.

A tracker step is ``(table, scan) → (table, info)`` (``../DESIGN``: "trackers know nothing of
scenarios"), in the order of Stone Soup's ``MultiTargetMixtureTracker.__next__``:

1. **predict** every live track with the filter's own ``predict``;
2. **hypothesise**: each track's update on every measurement of the scan (the filter's own
   ``update``, vmapped), giving the Gaussian log-likelihoods, the NIS for the χ² gate and the
   conditioned moments (:func:`jaxtrack.association.measurement_likelihoods`);
3. **associate**: the log-likelihood-ratio matrix (:func:`jaxtrack.association.log_likelihood_ratios`)
   through the ``association=`` strategy (GNN, PDA, exact JPDA, loopy BP), which returns the
   marginal association probabilities ``β``;
4. **update**: the PDA/JPDA mixture collapse of the conditioned moments with ``β``
   (:func:`jaxtrack.association.pda_update`; with GNN's one-hot rows it is the plain update);
   with integrated existence (JIPDA) also the existence probability;
5. **manage**: M-of-N confirmation, deletion after consecutive misses (or low existence);
6. **initiate**: a tentative track at every measurement no track claimed, in free slots.

Each step also reports the scan's log-likelihood given the predicted tracks,
``−λV + M_k log λ − log M_k! + log Z_k`` with ``Z_k`` the association's ``log_normalizer``
(:meth:`Tracker.step` derives it), the objective of
:func:`~jaxtrack.multitarget.fit_detection_and_clutter`.

What "a track claimed measurement j" and "a track was hit" mean follows Stone Soup: a
detection hypothesis counts when its probability exceeds the track's missed-detection
probability (``β[t, j] > β[t, 0]``); with GNN's one-hot rows that is "assigned".

Every array has a static shape: ``capacity`` tracks, the scan's ``max_measurements``. When more
measurements would start tracks than there are free slots, the births that do not fit are
counted in ``TrackTable.num_dropped_births`` (and flagged by ``overflow``), never dropped in silence;
:func:`run_tracker` warns on the host.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._validation import InputError, is_concrete
from ..association._gating import gate_threshold, log_likelihood_ratios, measurement_likelihoods
from ..association._pda_update import pda_update
from ..association._types import AbstractAssociator, Association
from ..filters._base import AbstractFilter
from ..models._base import AbstractStateSpaceModel
from ._clutter import resolve_clutter
from ._base import AbstractMultiTargetFilter, Estimates, check_scans, scan_method, scan_ok, warn_capacity, warn_not_ok

EMPTY = 0
"""Track status of a free slot in :attr:`TrackTable.status` (a deleted track's slot becomes it)."""
TENTATIVE = 1
"""Track status of a track not confirmed yet (M-of-N logic, :class:`TrackManagement`)."""
CONFIRMED = 2
"""Track status of a confirmed track."""


class TrackTable(eqx.Module):
    """The tracker's state: a fixed-capacity table of tentative and confirmed tracks.

    **Fields** (``N`` = capacity, ``n`` = state dimension):

    - ``mean`` ``(N, n)``, ``cov`` ``(N, n, n)``: each slot's filtered moments after the last
      scan. An empty slot holds the initiator's prior: a point where every filter and sensor is
      defined (zeros would put a range–bearing track on the sensor, where the Jacobian is
      singular), so its discarded computations stay finite, and so do their gradients.
    - ``status`` ``(N,)`` int: :data:`EMPTY`, :data:`TENTATIVE` or :data:`CONFIRMED`.
    - ``existence`` ``(N,)``: the probability that the track is a target (JIPDA; 1 otherwise).
    - ``hits`` ``(N,)`` int: a bit mask of the last scans the track was hit in (bit 0 = the last
      scan), for M-of-N confirmation; ``misses`` ``(N,)`` int: scans since the last hit.
    - ``track_id`` ``(N,)`` int: a unique id per track (−1 in empty slots); ``born_at`` ``(N,)``
      int: the scan index of its first measurement.
    - ``next_id`` ``()`` int: the next id to give; ``step`` ``()`` int: the next scan's index.
    - ``num_dropped_births`` ``()`` int: births refused so far for want of a free slot;
      ``num_association_failures`` ``()`` int: scans whose association method could not answer
      (``Association.ok`` False: a gating cluster beyond exact JPDA's caps, a non-finite weight).
    """

    mean: Float[Array, "N n"]
    cov: Float[Array, "N n n"]
    status: Int[Array, " N"]
    existence: Float[Array, " N"]
    hits: Int[Array, " N"]
    misses: Int[Array, " N"]
    track_id: Int[Array, " N"]
    born_at: Int[Array, " N"]
    next_id: Int[Array, ""]
    step: Int[Array, ""]
    num_dropped_births: Int[Array, ""]
    num_association_failures: Int[Array, ""]

    @property
    def live(self) -> Bool[Array, " N"]:
        """True in slots holding a track (tentative or confirmed)."""
        return self.status != EMPTY

    @property
    def confirmed(self) -> Bool[Array, " N"]:
        """True in slots holding a confirmed track."""
        return self.status == CONFIRMED

    @property
    def overflow(self) -> Bool[Array, ""]:
        """True once a birth was refused for want of a free slot."""
        return self.num_dropped_births > 0


class OnePointInitiator(eqx.Module):
    """Start a track at one measurement: the filter's update of a broad prior on it.

    The new track's moments are the update of ``N(prior_mean, prior_cov)`` on the measurement
    with the tracker's filter (Stone Soup's ``SinglePointInitiator``): with a position sensor and a
    prior broad in position, the position is the measurement and the velocity keeps the prior
    (the "one-point initiation with a velocity prior" of Bar-Shalom, Willett & Tian 2011, §3.2).
    For a nonlinear sensor pass an iterated filter as ``filter`` (a single EKF step linearised at a
    far-away prior mean is poor).

    **Arguments:**

    - ``prior_mean`` ``(n,)``, ``prior_cov`` ``(n, n)``: the prior of a new target, in the state's
      units.
    - ``filter``: the filter whose update initiates (default None: the tracker's filter).
    - ``existence``: the initial existence probability of a new track (JIPDA; default 0.5).
    """

    prior_mean: Float[Array, " n"]
    prior_cov: Float[Array, "n n"]
    filter: AbstractFilter | None = None
    existence: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.5))

    def __init__(self, prior_mean, prior_cov, filter=None, existence=0.5):
        self.prior_mean = jnp.asarray(prior_mean, float)
        self.prior_cov = jnp.asarray(prior_cov, float)
        n = self.prior_mean.shape[-1] if self.prior_mean.ndim else 0
        if self.prior_mean.ndim != 1 or self.prior_cov.shape != (n, n):
            raise InputError(
                f"`prior_mean` must be (n,) and `prior_cov` (n, n); got {self.prior_mean.shape} "
                f"and {self.prior_cov.shape}."
            )
        self.filter = filter
        self.existence = jnp.asarray(existence, float)
        if is_concrete(self.existence) and not 0.0 < float(self.existence) <= 1.0:
            raise InputError(f"`existence` must lie in (0, 1]; got {float(self.existence)}.")

    def moments(self, tracker_filter, model, z, k):
        """The new track's ``(mean (n,), cov (n, n))`` at measurement ``z`` ``(m,)`` of scan ``k``."""
        init_filter = tracker_filter if self.filter is None else self.filter
        z = jnp.where(jnp.isfinite(z), z, 0.0)  # padded rows: never used, kept finite
        post = init_filter.update(model, self.prior_mean, self.prior_cov, z, jnp.ones(z.shape, bool), k)
        return post.mean, post.cov

    def initiate(self, tracker_filter, model, table: "TrackTable", keep, measurements, new, k, first_status):
        """Start a track at every measurement in ``new`` ``(M,)`` (valid, claimed by no track), in the
        free slots (``~keep``), in ascending order of both; births beyond the free slots are counted.

        ``table`` holds the managed tracks (their ``mean``/``cov``/... where ``keep``).
        **Returns:** ``(table, born (M,), num_born (), dropped ())``."""
        dtype = table.mean.dtype
        born_mean, born_cov = jax.vmap(lambda z: self.moments(tracker_filter, model, z, k))(measurements)
        free = ~keep
        N, M = keep.shape[0], measurements.shape[0]
        free_slots = jnp.nonzero(free, size=N, fill_value=N)[0]  # free slot indices, ascending
        new_meas = jnp.nonzero(new, size=M, fill_value=M)[0]  # new measurements, ascending
        num_new = jnp.sum(new)
        num_born = jnp.minimum(num_new, jnp.sum(free))
        # Slot free_slots[q] receives measurement new_meas[q] for q < num_born.
        q = jnp.arange(N)
        meas_of_q = jnp.where(q < num_born, new_meas[jnp.minimum(q, M - 1)], M).astype(jnp.int32)
        slot_meas = jnp.full((N + 1,), M, jnp.int32).at[free_slots].set(meas_of_q)[:N]
        births = slot_meas < M
        take = jnp.minimum(slot_meas, M - 1)
        slot_rank = jnp.cumsum(births) - 1
        table = TrackTable(
            mean=jnp.where(births[:, None], born_mean[take], table.mean),
            cov=jnp.where(births[:, None, None], born_cov[take], table.cov),
            status=jnp.where(births, first_status, table.status).astype(jnp.int32),
            existence=jnp.where(births, self.existence.astype(dtype), table.existence),
            hits=jnp.where(births, 1, table.hits).astype(jnp.int32),
            misses=jnp.where(births, 0, table.misses).astype(jnp.int32),
            track_id=jnp.where(births, table.next_id + slot_rank, table.track_id).astype(jnp.int32),
            born_at=jnp.where(births, k, table.born_at).astype(jnp.int32),
            next_id=table.next_id + num_born.astype(jnp.int32),
            step=table.step,
            num_dropped_births=table.num_dropped_births + (num_new - num_born).astype(jnp.int32),
            num_association_failures=table.num_association_failures,
        )
        born = jnp.zeros((M + 1,), bool).at[slot_meas].set(births, mode="drop")[:M]
        return table, born, num_born, num_new - num_born


class TrackManagement(eqx.Module):
    """When a track is confirmed and when it is deleted (M-of-N logic; existence thresholds).

    A tentative track is confirmed once it was hit in ``confirm_hits`` of the last
    ``confirm_window`` scans (its first measurement counts; M-of-N, Blackman & Popoli 1999
    §6.3). A tentative track that can no longer reach that count within its first
    ``confirm_window`` scans is deleted; a confirmed one after ``delete_after_misses`` scans in a
    row without a hit (Stone Soup's ``UpdateTimeStepsDeleter(time_steps_since_update=...)``).
    With integrated existence (JIPDA), a track is also confirmed when its existence reaches
    ``confirm_existence`` and deleted when it falls below ``delete_existence``.

    ``confirm_hits = confirm_window = 1`` confirms every new track at once (as Stone Soup's
    single-point initiator does).
    """

    confirm_hits: int = eqx.field(static=True, default=2)
    confirm_window: int = eqx.field(static=True, default=3)
    delete_after_misses: int = eqx.field(static=True, default=3)
    confirm_existence: float | None = eqx.field(static=True, default=None)
    delete_existence: float | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if not 1 <= self.confirm_hits <= self.confirm_window <= 30:
            raise InputError(
                "`confirm_hits` (M) and `confirm_window` (N) of M-of-N confirmation need "
                f"1 <= M <= N <= 30; got M={self.confirm_hits}, N={self.confirm_window}."
            )
        if self.delete_after_misses < 1:
            raise InputError(
                f"`delete_after_misses` must be at least 1; got {self.delete_after_misses}."
            )
        for name in ("confirm_existence", "delete_existence"):
            value = getattr(self, name)
            if value is not None and not 0.0 <= value <= 1.0:
                raise InputError(f"`{name}` must lie in [0, 1]; got {value}.")

    @property
    def first_status(self) -> int:
        """A new track's status: confirmed at once when ``confirm_hits = 1``, else tentative."""
        return CONFIRMED if self.confirm_hits == 1 else TENTATIVE

    def manage(self, table: "TrackTable", hit, existence, k):
        """Confirm and delete after scan ``k``: ``hit`` ``(N,)`` the tracks hit in it, ``existence``
        ``(N,)`` their posterior existence. **Returns:** ``(status (N,), hits (N,), misses (N,),
        keep (N,))`` with the deleted slots ``EMPTY``."""
        live = table.live
        window_mask = (1 << self.confirm_window) - 1
        hits = ((table.hits << 1) | hit.astype(jnp.int32)) & window_mask
        misses = jnp.where(hit, 0, table.misses + 1)
        num_hits = _popcount(hits, self.confirm_window)
        age = k - table.born_at + 1  # scans seen, this one included
        tentative = table.status == TENTATIVE
        confirm = tentative & (num_hits >= self.confirm_hits)
        if self.confirm_existence is not None:
            confirm = confirm | (tentative & (existence >= self.confirm_existence))
        # A tentative track that cannot reach M hits within its first N scans is deleted.
        hopeless = tentative & ~confirm & (num_hits + (self.confirm_window - age) < self.confirm_hits)
        delete = live & ((misses >= self.delete_after_misses) | hopeless)
        if self.delete_existence is not None:
            delete = delete | (live & (existence < self.delete_existence))
        status = jnp.where(confirm, CONFIRMED, table.status)
        status = jnp.where(delete, EMPTY, status)
        return status, hits, misses, status != EMPTY


class IntegratedExistence(eqx.Module):
    """JIPDA's existence probability (Mušicki & Evans 2004, "Joint integrated probabilistic data
    association: JIPDA", IEEE TAES 40(3)): Markov chain 1, ``r_{k|k-1} = P_S r_{k-1|k-1}``.

    **Arguments:** ``prob_survival``: ``P_S``, the probability a target persists from one scan to
    the next (dimensionless, in (0, 1]).
    """

    prob_survival: Float[Array, ""]

    def __init__(self, prob_survival=0.99):
        self.prob_survival = jnp.asarray(prob_survival, float)
        if is_concrete(self.prob_survival) and not 0.0 < float(self.prob_survival) <= 1.0:
            raise InputError(f"`prob_survival` must lie in (0, 1]; got {float(self.prob_survival)}.")

    def predict(self, existence):
        """``r_{k|k-1} = P_S r_{k-1|k-1}`` (Markov chain 1)."""
        return self.prob_survival * existence

    def posterior(self, existence_pred, beta, detect):
        """The posterior existence and the state-mixture weights (Mušicki & Evans 2004, eqs. (27)-(31)):
        ``beta[:, 0]`` mixes "exists, not detected" and "does not exist"; the state is conditioned
        on existence. ``detect`` is ``P_D P_G``. **Returns:** ``(existence (N,), weights (N, 1 + M))``."""
        undetected = existence_pred * (1.0 - detect) / (1.0 - existence_pred * detect)
        exist_post = beta[:, 0] * undetected + jnp.sum(beta[:, 1:], axis=1)
        # A sum of probabilities can round to just above 1 (with P_S = 1 and r → 1), which the
        # next scan's log_likelihood_ratios rejects (NaN under jit): keep it a probability.
        exist_post = jnp.minimum(exist_post, 1.0)
        safe = jnp.where(exist_post > 0, exist_post, 1.0)
        weights = jnp.concatenate([(beta[:, :1] * undetected[:, None]), beta[:, 1:]], axis=1)
        return exist_post, weights / safe[:, None]


class TrackerStepInfo(NamedTuple):
    """What one tracker step computed besides the new table.

    ``association``: the scan's :class:`~jaxtrack.association.Association` (rows = table slots);
    ``log_weights``: the ``(N, 1 + M)`` matrix it was computed from; ``hit`` ``(N,)``: tracks hit
    in this scan; ``claimed`` ``(M,)``: measurements some track claimed; ``born`` ``(M,)``:
    measurements that started a track; ``births_dropped`` ``()``: births refused in this scan;
    ``log_likelihood`` ``()``: the scan's log-likelihood given the predicted tracks, nats (log of
    the scan's density in inverse measurement units; :meth:`Tracker.step` derives it); ``ok`` ``()``:
    the association answered (``Association.ok``), the valid measurements, ``P_D`` in (0, 1],
    ``λ`` (finite, > 0) and the live tracks' moments are finite: False where a number would be
    silently wrong (a traced NaN ``P_D``, a cluster beyond exact JPDA's caps).
    """

    association: Association
    log_weights: Float[Array, "N Mp1"]
    hit: Bool[Array, " N"]
    claimed: Bool[Array, " M"]
    born: Bool[Array, " M"]
    births_dropped: Int[Array, ""]
    log_likelihood: Float[Array, ""]
    ok: Bool[Array, ""]


class Tracker(AbstractMultiTargetFilter):
    """A multi-target tracker: one step function over a :class:`TrackTable`.

    The association method is a strategy: ``GNN()`` gives the GNN tracker, ``JPDA()`` the JPDA
    tracker, ``JPDA()`` with ``existence=IntegratedExistence(...)`` the JIPDA tracker,
    ``LoopyBP(...)`` the JPDA tracker with belief-propagation marginals for large clusters.

    **Arguments:**

    - ``filter``: any jaxtrack :class:`~jaxtrack.filters.AbstractFilter` (KF, EKF, UKF, …) and
      ``model``: the state-space model every target follows (its ``measurement`` is the sensor).
    - ``association``: an :class:`~jaxtrack.association.AbstractAssociator`.
    - ``initiator``: a :class:`OnePointInitiator`; ``management``: a :class:`TrackManagement`.
    - ``prob_detect``: ``P_D``; ``clutter_density``: ``λ``, clutter points per unit
      measurement-space volume per scan (Stone Soup's ``clutter_spatial_density``, accepted under
      that name too; or give ``clutter_rate``, points per scan, with ``clutter_volume``:
      :mod:`jaxtrack.multitarget._clutter`); ``prob_gate``: ``P_G`` of the χ² gate (1: no gate).
      ``P_D`` and ``λ`` are array leaves (differentiable).
    - ``capacity``: the number of track slots ``N`` (static).
    - ``existence``: None, or :class:`IntegratedExistence` for JIPDA.
    - ``clutter_volume``: ``V``, the volume of the measurement-space region the clutter falls in
      (e.g. m² for positions, m·rad for range and bearing; :attr:`Scenario.clutter_density` is
      ``λ = rate / V``), > 0; or None (default). It enters only the scan log-likelihood's Poisson
      count term ``−λV`` (:meth:`step`), which None leaves out. It is a field of the tracker, not
      an argument of the likelihood, because it belongs with ``λ``: together they say what the
      clutter is, and every run of the tracker (:func:`run_tracker`, vmapped Monte Carlo runs)
      then reports the full log-likelihood without another argument to thread through.
    """

    filter: AbstractFilter
    model: AbstractStateSpaceModel
    association: AbstractAssociator
    initiator: OnePointInitiator
    management: TrackManagement
    prob_detect: Float[Array, ""]
    clutter_density: Float[Array, ""]
    prob_gate: float = eqx.field(static=True)
    gate: float = eqx.field(static=True)
    capacity: int = eqx.field(static=True)
    existence: IntegratedExistence | None
    clutter_volume: Float[Array, ""] | None
    labelled: ClassVar[bool] = True

    def __init__(
        self,
        filter: AbstractFilter,
        model: AbstractStateSpaceModel,
        association: AbstractAssociator,
        initiator: OnePointInitiator,
        *,
        prob_detect: ArrayLike,
        clutter_density: ArrayLike | None = None,
        prob_gate: float = 1.0,
        capacity: int,
        management: TrackManagement | None = None,
        existence: IntegratedExistence | None = None,
        clutter_volume: ArrayLike | None = None,
        clutter_rate: ArrayLike | None = None,
        clutter_spatial_density: ArrayLike | None = None,
    ):
        if not isinstance(filter, AbstractFilter):
            raise InputError(f"`filter` must be a jaxtrack filter; got {type(filter).__name__}.")
        if not isinstance(association, AbstractAssociator):
            raise InputError(
                "`association` must be a jaxtrack.association method (GNN(), PDA(), JPDA(), "
                f"LoopyBP(...)); got {type(association).__name__}."
            )
        if not isinstance(initiator, OnePointInitiator):
            raise InputError(f"`initiator` must be a OnePointInitiator; got {type(initiator).__name__}.")
        if initiator.prior_mean.shape != (model.state_dim,):
            raise InputError(
                f"`initiator.prior_mean` has {initiator.prior_mean.shape[0]} states; the model has "
                f"{model.state_dim}."
            )
        if not isinstance(capacity, int | np.integer) or capacity < 1:
            raise InputError(f"`capacity` must be a positive int (track slots); got {capacity!r}.")
        self.filter = filter
        self.model = model
        self.association = association
        self.initiator = initiator
        self.management = TrackManagement() if management is None else management
        self.prob_detect = jnp.asarray(prob_detect, float)
        clutter_density, _, _ = resolve_clutter(
            "Tracker", clutter_density=clutter_density, clutter_spatial_density=clutter_spatial_density,
            clutter_rate=clutter_rate, clutter_volume=clutter_volume)
        self.clutter_density = jnp.asarray(clutter_density, float)
        if is_concrete(self.prob_detect) and not 0.0 < float(self.prob_detect) <= 1.0:
            raise InputError(f"`prob_detect` must lie in (0, 1]; got {float(self.prob_detect)}.")
        if is_concrete(self.clutter_density) and not 0.0 < float(self.clutter_density) < np.inf:
            raise InputError(
                f"`clutter_density` must be finite and positive (per unit measurement volume); got "
                f"{float(self.clutter_density)}."
            )
        self.prob_gate = float(prob_gate)
        self.gate = float(gate_threshold(self.prob_gate, model.meas_dim))
        self.capacity = int(capacity)
        self.existence = existence
        self.clutter_volume = None if clutter_volume is None else jnp.asarray(clutter_volume, float)
        if self.clutter_volume is not None and (
            self.clutter_volume.shape != ()
            or (is_concrete(self.clutter_volume) and not 0.0 < float(self.clutter_volume) < np.inf)
        ):
            raise InputError(
                "`clutter_volume` must be a finite positive scalar (the clutter region's volume in "
                f"measurement space) or None; got {np.asarray(clutter_volume)!r}."
            )

    def init(self) -> TrackTable:
        """The empty table before the first scan."""
        N, n = self.capacity, self.model.state_dim
        dtype = self.initiator.prior_cov.dtype
        zeros_i = jnp.zeros((N,), jnp.int32)
        return TrackTable(
            mean=jnp.broadcast_to(self.initiator.prior_mean.astype(dtype), (N, n)),
            cov=jnp.broadcast_to(self.initiator.prior_cov.astype(dtype), (N, n, n)),
            status=zeros_i,
            existence=jnp.zeros((N,), dtype),
            hits=zeros_i,
            misses=zeros_i,
            track_id=jnp.full((N,), -1, jnp.int32),
            born_at=jnp.full((N,), -1, jnp.int32),
            next_id=jnp.zeros((), jnp.int32),
            step=jnp.zeros((), jnp.int32),
            num_dropped_births=jnp.zeros((), jnp.int32),
            num_association_failures=jnp.zeros((), jnp.int32),
        )

    def estimates(self, table: TrackTable) -> Estimates:
        """The confirmed tracks: :class:`~jaxtrack.multitarget.Estimates` ``(mean (N, n), confirmed
        (N,), track_id (N,))`` by slot (unconfirmed slots masked: means 0, ids −1)."""
        confirmed = table.confirmed
        return Estimates(jnp.where(confirmed[:, None], table.mean, 0.0), confirmed,
                         jnp.where(confirmed, table.track_id, -1))

    def capacity_events(self, table: TrackTable) -> Int[Array, ""]:
        """Births refused for want of a free slot and scans the association could not answer, so far."""
        return table.num_dropped_births + table.num_association_failures

    def capacity_message(self, events: int) -> str:
        return (f"{events} capacity events in the tracker: track births refused because the table's capacity "
                f"({self.capacity} slots) was full (raise `capacity`), or scans its {type(self.association).__name__} "
                "association could not answer (a gating cluster beyond exact JPDA's caps: raise max_cluster_* or "
                "use LoopyBP)")

    def step(
        self, table: TrackTable, measurements: Float[Array, "M m"], valid: Bool[Array, " M"]
    ) -> tuple[TrackTable, TrackerStepInfo]:
        r"""One scan: predict, hypothesise, associate, update, manage, initiate.

        **Arguments:**

        - ``table``: the :class:`TrackTable` after the previous scan (``init()`` before the first).
        - ``measurements``: the scan, ``(M, m)`` in the sensor's units (padded rows may hold NaN);
          ``valid``: boolean ``(M,)``, False for padding.

        **Returns:** ``(new_table, TrackerStepInfo)``.

        **The scan log-likelihood** (``TrackerStepInfo.log_likelihood``). Given the ``N`` predicted
        tracks, each with predictive density ``p_t(z) = N(z; ẑ_t, S_t)`` (the filter's Gaussian
        approximation) and existence ``r_t`` (1 without JIPDA), each detected independently with
        probability ``P_D``, and clutter a Poisson process of intensity ``λ`` on a region of volume
        ``V`` (a ``Poisson(λV)`` count of points uniform on it), the scan ``Z_k = (z_1, …, z_M)``
        (``M = M_k`` valid measurements, in random order) has the density of the standard
        multi-target measurement model (Mahler 2007, *Statistical Multisource-Multitarget
        Information Fusion*, §12.3; the JPDA joint-event probabilities with the parametric
        (Poisson) clutter model, Bar-Shalom, Daum & Huang 2009, "The probabilistic data
        association filter", IEEE Control Syst. Mag. 29(6); Bar-Shalom, Willett & Tian 2011,
        *Tracking and Data Fusion*, the JPDA chapter). Summing over the joint association events
        ``θ`` (each track missed, ``θ_t = 0``, or given its own measurement ``θ_t = j``; the
        measurements no track takes are clutter):

        .. math::

            p(Z_k) &= \frac{1}{M!} \sum_θ e^{−λV} λ^{M − D(θ)}
                      \prod_{t:\,θ_t = 0} (1 − r_t P_D) \prod_{t:\,θ_t ≥ 1} r_t P_D\, p_t(z_{θ_t}) \\
                   &= \frac{e^{−λV} λ^M}{M!} \sum_θ \prod_t e^{L[t, θ_t]},

        with ``D(θ)`` the number of detected tracks: the Poisson probability of the ``M − D``
        clutter points, ``e^{−λV}(λV)^{M−D}/(M−D)!``, times their uniform densities ``V^{−(M−D)}``,
        times the ``(M−D)!/M!`` chance of the order, leaves ``e^{−λV} λ^{M−D}/M!``, and dividing
        each detected track's factor by ``λ`` turns it into ``exp L[t, θ_t]`` of
        :func:`~jaxtrack.association.log_likelihood_ratios`. The sum is the association's
        partition function ``Z_k`` (``Association.log_normalizer``: Fortmann, Bar-Shalom & Scheffe
        1983; the partition function of Williams & Lau 2014, "Approximate evaluation of marginal
        association probabilities with belief propagation", IEEE TAES 50(4)), so

        .. math::

            \log p(Z_k) = −λV + M_k \log λ − \log M_k! + \log Z_k .

        It is exact for :class:`~jaxtrack.association.JPDA` with ``P_G = 1``, given the tracks'
        Gaussian predictions (which the earlier scans' mixture collapses already approximate);
        :class:`~jaxtrack.association.LoopyBP` gives its Bethe estimate of ``log Z_k``, ``PDA`` the
        product of independent rows (events sharing a measurement counted), ``GNN`` the best event
        only (a lower bound). With a gate (``P_G < 1``) it is the usual truncated approximation: a
        track is detected inside its gate with probability ``P_D P_G`` (the missed weight
        ``1 − r P_D P_G``), with the gate-truncated density ``p_t/P_G``, and a measurement outside
        every gate counts as clutter, although a target's detection falls outside its gate with
        probability ``P_D(1 − P_G)``. Targets without a track yet (their first scan) count as
        clutter, and tracks born from clutter count as targets (with existence ``r``: JIPDA with a
        small initial existence keeps their weight small). ``clutter_volume=None`` leaves out
        ``−λV``; without it the log-likelihood grows without bound in ``λ``.
        """
        k, live, dtype = table.step, table.live, table.mean.dtype
        measurements, valid = jnp.asarray(measurements, dtype), jnp.asarray(valid, bool)
        pred_mean, pred_cov, existence_pred = self._predict(table)
        loglik, nis, conditioned = jax.vmap(
            lambda x, P: measurement_likelihoods(self.filter, self.model, x, P, measurements, valid, k)
        )(pred_mean, pred_cov)
        log_weights = self._log_weights(loglik, nis, live, valid, existence_pred)
        association = self.association(log_weights, live)
        beta = association.association_probabilities
        if self.existence is not None:
            exist_post, weights = self.existence.posterior(existence_pred, beta, self.prob_detect * self.prob_gate)
        else:
            exist_post, weights = jnp.where(live, 1.0, 0.0).astype(dtype), beta
        post_mean, post_cov = jax.vmap(pda_update)(conditioned, weights, pred_mean, pred_cov)
        # A hit: some detection more probable than the miss (Stone Soup's rule).
        hit = live & jnp.any(beta[:, 1:] > beta[:, :1], axis=1)
        claimed = jnp.any(live[:, None] & (beta[:, 1:] > beta[:, :1]), axis=0) & valid
        status, hits, misses, keep = self.management.manage(table, hit, exist_post, k)
        managed = TrackTable(
            mean=jnp.where(keep[:, None], post_mean, self.initiator.prior_mean.astype(dtype)),
            cov=jnp.where(keep[:, None, None], post_cov, self.initiator.prior_cov.astype(dtype)),
            status=status, existence=jnp.where(keep, exist_post, 0.0), hits=jnp.where(keep, hits, 0),
            misses=jnp.where(keep, misses, 0), track_id=jnp.where(keep, table.track_id, -1),
            born_at=jnp.where(keep, table.born_at, -1), next_id=table.next_id, step=k + 1,
            num_dropped_births=table.num_dropped_births,
            num_association_failures=table.num_association_failures + (~association.ok).astype(jnp.int32),
        )
        new_table, born, _, dropped = self.initiator.initiate(
            self.filter, self.model, managed, keep, measurements, valid & ~claimed, k, self.management.first_status)
        log_likelihood = self._log_likelihood(valid, association, dtype)
        ok = association.ok & scan_ok(measurements, valid) & self._parameters_ok() & jnp.all(
            ~live[:, None] | jnp.isfinite(post_mean))
        info = TrackerStepInfo(association, log_weights, hit, claimed, born, dropped.astype(jnp.int32),
                               log_likelihood, ok)
        return new_table, info

    def _predict(self, table: TrackTable):
        """Every slot predicted with the filter's ``predict`` (empty slots hold the initiator's
        prior: finite, then discarded), and the predicted existence."""
        k = table.step
        pred_mean, pred_cov = jax.vmap(lambda x, P: self.filter.predict(self.model, x, P, k))(table.mean, table.cov)
        existence_pred = table.existence if self.existence is None else self.existence.predict(table.existence)
        return pred_mean, pred_cov, existence_pred

    def _log_weights(self, loglik, nis, live, valid, existence_pred):
        """The association's log-weight matrix ``L`` ``(N, 1 + M)``
        (:func:`~jaxtrack.association.log_likelihood_ratios`)."""
        log_weights, _ = log_likelihood_ratios(
            loglik, nis, live, valid, prob_detect=self.prob_detect, clutter_density=self.clutter_density,
            gate_threshold=self.gate, prob_gate=self.prob_gate,
            # Empty slots hold existence 0; give them 1 (their rows are replaced as padding anyway)
            # so that the log(r) inside is finite there and reverse mode gets no 0·inf = NaN.
            existence=jnp.where(live, existence_pred, 1.0) if self.existence is not None else None,
        )
        return log_weights

    def _log_likelihood(self, valid, association, dtype):
        """The scan's log-likelihood given the predicted tracks (derived in :meth:`step`)."""
        num_meas = jnp.sum(valid).astype(dtype)
        clutter_density = self.clutter_density.astype(dtype)
        log_likelihood = (num_meas * jnp.log(clutter_density) - jax.scipy.special.gammaln(num_meas + 1.0)
                          + association.log_normalizer.astype(dtype))
        if self.clutter_volume is not None:
            log_likelihood = log_likelihood - clutter_density * self.clutter_volume.astype(dtype)
        return log_likelihood

    def _parameters_ok(self):
        """``P_D`` in (0, 1] and ``λ`` finite and > 0: checked at construction when concrete, here
        when traced (a NaN or 1.5 ``P_D`` under jit would otherwise give NaN or wrong weights)."""
        pd, lam = self.prob_detect, self.clutter_density
        return (pd > 0.0) & (pd <= 1.0) & (lam > 0.0) & jnp.isfinite(lam)


def _popcount(bits: Array, width: int) -> Array:
    """The number of set bits among the low ``width`` bits of an int array."""
    return sum((bits >> i) & 1 for i in range(width))


class TrackerResult(eqx.Module):
    """A tracker run over ``T`` scans: the table after each scan, and the last table.

    **Fields:** ``mean`` ``(T, N, n)``, ``cov`` ``(T, N, n, n)`` (None unless
    ``save_cov=True``), ``status`` ``(T, N)``, ``existence`` ``(T, N)``, ``track_id`` ``(T, N)``:
    the table's fields after scan ``k``; ``association_probabilities`` ``(T, N, 1 + M)``;
    ``final``: the last :class:`TrackTable`; ``overflow`` ``()``: a birth was refused;
    ``log_likelihood`` ``(T,)``: each scan's log-likelihood given the tracks predicted into it
    (nats; :meth:`Tracker.step`), whose sum is the run's log-likelihood under the tracker's
    approximations (maximised by :func:`~jaxtrack.multitarget.fit_detection_and_clutter`);
    ``ok`` ``(T,)``: each scan's :attr:`TrackerStepInfo.ok` (False where a number is not to be
    trusted: the association could not answer, a parameter or a measurement marked valid is not
    finite).
    """

    mean: Float[Array, "T N n"]
    cov: Float[Array, "T N n n"] | None
    status: Int[Array, "T N"]
    existence: Float[Array, "T N"]
    track_id: Int[Array, "T N"]
    association_probabilities: Float[Array, "T N Mp1"]
    final: TrackTable
    overflow: Bool[Array, ""]
    log_likelihood: Float[Array, " T"]
    ok: Bool[Array, " T"]


def _record_tracker(tracker, table, info):
    return (table.mean, None, table.status, table.existence, table.track_id,
            info.association.association_probabilities, info.log_likelihood, info.ok)


def _record_tracker_cov(tracker, table, info):
    return (table.mean, table.cov, table.status, table.existence, table.track_id,
            info.association.association_probabilities, info.log_likelihood, info.ok)


def _run_tracker(tracker, measurements, valid, save_cov):
    final, (mean, cov, status, existence, track_id, beta, log_likelihood, ok) = scan_method(
        tracker, measurements, valid, _record_tracker_cov if save_cov else _record_tracker)
    return TrackerResult(mean, cov, status, existence, track_id, beta, final, final.overflow, log_likelihood, ok)


def check_measurement_dim(tracker: "Tracker", measurements: Array) -> None:
    """``InputError`` unless the last axis of ``measurements`` is the tracker model's ``m``."""
    if measurements.shape[-1] != tracker.model.meas_dim:
        raise InputError(
            f"`measurements` have {measurements.shape[-1]} components; the tracker's model "
            f"measures {tracker.model.meas_dim}."
        )


def run_tracker(
    tracker: Tracker,
    measurements: ArrayLike,
    valid: ArrayLike,
    *,
    save_cov: bool = False,
    warn: bool = True,
) -> TrackerResult:
    """Run a tracker over ``T`` scans: one jitted ``lax.scan`` of :meth:`Tracker.step`.

    **Arguments:**

    - ``tracker``: the :class:`Tracker`.
    - ``measurements``: ``(T, M, m)`` padded scans in the sensor's units (padding may be NaN);
      ``valid``: boolean ``(T, M)``, False for padding. A scenario's
      ``trajectory.scans.measurements`` and ``.valid`` are in this form.
    - ``save_cov``: also keep every scan's covariances (``(T, N, n, n)``).
    - ``warn``: on the host (concrete results only), a :class:`CapacityWarning` when births were
      refused for want of track slots or the association could not answer a scan within its
      capacity (both counted in :meth:`Tracker.capacity_events`), and a ``RuntimeWarning`` when a
      scan was not ``ok``.

    **Returns:** a :class:`TrackerResult`. Under ``jax.vmap`` over runs it batches like any
    filter run. It is :func:`~jaxtrack.multitarget.run_multitarget`'s scan keeping more of the table.

    **Raises:** :class:`~jaxtrack.InputError` naming ``measurements`` or ``valid`` (shapes, or a
    non-finite measurement marked valid when concrete).
    """
    measurements = jnp.asarray(measurements)
    valid = jnp.asarray(valid, bool)
    if measurements.ndim != 3 or valid.shape != measurements.shape[:2]:
        raise InputError(
            "`measurements` must be (T, M, m) and `valid` (T, M); got "
            f"{measurements.shape} and {valid.shape}."
        )
    measurements, valid = check_scans(measurements, valid, tracker.model.meas_dim)
    result = _run_tracker(tracker, measurements, valid, save_cov)
    if warn:
        warn_capacity(tracker, tracker.capacity_events(result.final))
        warn_not_ok(tracker, result.ok)
    return result

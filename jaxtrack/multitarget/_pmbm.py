r"""The Poisson multi-Bernoulli mixture (PMBM) filter with fixed budgets, and the pieces it shares
with the PMB filter (:mod:`._pmb`).

The multi-target density is a Poisson point process (the targets never detected, a Gaussian
mixture intensity) times a mixture, over *global hypotheses*, of multi-Bernoulli densities (the
targets detected at least once). It is kept in the track-oriented form of García-Fernández,
Williams, Granström & Svensson (2018), "Poisson multi-Bernoulli mixture filter: direct derivation
and implementation", IEEE Trans. Aerosp. Electron. Syst. 54(4), 1883-1901 (G18 below), laid out as
arrays as in the authors' MATLAB reference (``Agarciafernandez/MTT``, ``PMBM filter/``):

- **tracks** (``N`` = ``max_tracks`` slots): a track is born by one measurement; it holds up to
  ``H`` *local hypotheses* (single-target hypotheses, G18 Sec. IV), each a Bernoulli density with
  existence ``r`` and a Gaussian ``N(m, P)``;
- **global hypotheses** (``H`` = ``max_hypotheses`` rows): an int table ``(H, N)`` naming, for
  every track, the local hypothesis it takes (−1: the track is not in this hypothesis), and a
  log weight per row (normalised: ``logsumexp = 0``). A track never needs more than ``H`` local
  hypotheses (each global hypothesis uses one), so ``H`` bounds both tables.

One scan (G18 Sec. IV; Theorems 1-2 for the update):

1. **predict** (from the second scan on): ``r ← P_S r``, moments by the filter's ``predict``;
   the Poisson intensity ``w ← P_S w`` with the birth mixture appended, then pruned and merged
   into ``poisson_capacity`` slots (:meth:`GMPHD.reduce <jaxtrack.multitarget.GMPHD.reduce>`);
2. **update**: the Poisson part by ``(1 − P_D)`` (undetected targets); every measurement ``z_j``
   starts a new track whose single local hypothesis collapses the Poisson components it updates,
   ``e_j = Σ_i P_D w_i N(z_j; ẑ_i, S_i)``, ``r = e_j / (e_j + κ)``, weight ``e_j + κ`` (G18 eq.
   (33)); every local hypothesis of every track has a miss child (weight ``1 − r P_D``,
   existence ``r (1 − P_D) / (1 − r P_D)``) and a detection child per measurement (weight
   ``r P_D N(z_j; ẑ, S)``, existence 1; G18 eqs. (31)-(32));
3. **global hypotheses**: each prior hypothesis ``h`` and each assignment of the scan's
   measurements to its tracks or to new tracks is a posterior hypothesis of weight
   ``w_h Π(local weights)`` (G18 eq. (25)). The ``H`` best of them over ALL prior hypotheses are
   found at once by Murty's ranked assignment (:func:`~jaxtrack.association.k_best_assignments`
   on the ``M × (N + M)`` matrices of every ``h``; the MATLAB reference instead asks each ``h``
   for ``⌈H w_h⌉`` assignments and keeps the ``H`` best of their union, which can miss
   hypotheses of the exact top ``H``);
4. **pruning**: hypotheses below ``hypothesis_threshold``; then each track keeps only the local
   hypotheses some surviving global hypothesis uses; a track whose local hypotheses all have
   ``r <= existence_threshold`` is removed, and global hypotheses that became equal are merged
   (weights summed), as in the reference's ``PoissonMBMtarget_pruning.m``.

What exceeds a capacity is counted and flagged, never silently lost: new tracks beyond the free
track slots (``num_dropped_tracks``) and Poisson components beyond ``poisson_capacity``
(``poisson_num_dropped``); :func:`run_pmbm` warns on the host (:class:`CapacityWarning`). Global
hypotheses beyond ``H`` are the approximation itself (the ``H`` best are kept, as in G18 Sec. V);
``num_hypotheses`` reports how many there are.

Everything has a static shape: :func:`run_pmbm` is one jitted ``lax.scan``, vmappable over Monte
Carlo runs. Estimates follow the reference's estimator 1: the most likely global hypothesis, the
tracks in it with ``r >`` ``estimation_threshold``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._validation import InputError, is_concrete
from ..association._murty import k_best_assignments
from ._mixture import log_normalise
from ._multibernoulli import (
    AbstractGlobalHypotheses,
    AbstractMultiBernoulliFilter,
    PMBMState,
    PMBMStepInfo,
    _detected_moments,
    _finish,
    _mb_fields,
    _new_tracks,
    _track_weights,
)
from ._phd import _scalar
from ._scenario import _positive_int


def _compact_children(child, H):
    """Per track, the distinct child ids used by the posterior hypotheses, in ascending order, in
    ``H`` local slots; and each hypothesis's slot. ``child`` ``(H, N)`` int, −1 = absent.

    **Returns:** ``(ids (N, H)`` with a sentinel where unused, ``table (H, N))``."""
    big = jnp.iinfo(jnp.int32).max
    ids = jnp.where(child >= 0, child, big).T  # (N, H)

    def one(v):
        s = jnp.sort(v)
        first = jnp.concatenate([jnp.ones((1,), bool), s[1:] != s[:-1]]) & (s < big)
        uniq = jnp.where(jnp.arange(H) < jnp.sum(first), s[jnp.nonzero(first, size=H, fill_value=0)[0]], big)
        return uniq, jnp.searchsorted(uniq, v)

    uniq, slot = jax.vmap(one)(ids)
    return uniq, jnp.where(child >= 0, slot.T, -1).astype(jnp.int32)


class PMBM(AbstractMultiBernoulliFilter):
    r"""The track-oriented Poisson multi-Bernoulli mixture filter (García-Fernández et al. 2018)
    with fixed budgets: ``max_tracks`` tracks, ``max_hypotheses`` global hypotheses (the best
    ones, by Murty's ranked assignment over all prior hypotheses at once), ``poisson_capacity``
    Poisson components.

    **Arguments:**

    - ``filter``: a jaxtrack :class:`~jaxtrack.filters.AbstractFilter` (Kalman: the PMBM of G18
      exactly for a linear Gaussian model; EKF/UKF: its linearised form); covariance form only.
    - ``model``: the single-target state-space model.
    - ``prob_survival``: ``P_S`` in ``(0, 1]``; ``prob_detect``: ``P_D`` in ``(0, 1)`` (1 is
      refused: a track with ``r = 1`` could not be missed, and the ranked assignment works on
      likelihood ratios to the miss).
    - ``clutter_density``: ``κ``, clutter points per unit measurement-space volume per scan, ``> 0``
      and finite (0 would make a measurement that no track or Poisson component reaches impossible).
    - ``birth``: the Poisson birth intensity added at every prediction, a
      :class:`~jaxtrack.multitarget.GaussianMixture`.
    - ``initial``: the Poisson intensity the first scan updates (G18's prior; default: ``birth``),
      a :class:`~jaxtrack.multitarget.GaussianMixture`. Scan 0 is not predicted.
    - ``max_tracks``: ``N``; ``max_hypotheses``: ``H`` (the reference's ``Nhyp_max``, 200 in
      its Williams (2015) study); ``poisson_capacity``: ``J``.
    - ``assignment_rows``: ``A``, the most measurements per scan that fall in some track's gate
      (only those enter the ranked assignment; the others start their own tracks), and
      ``assignment_tracks``: ``C``, the most tracks those measurements can reach (defaults 16,
      24). Beyond them a measurement can only start a new track, a track can only be missed:
      counted in ``assignment_overflow`` and warned about by :func:`run_pmbm`;
      :class:`PMBMStepInfo` reports the sizes each scan needed.
    - ``hypothesis_threshold``: global hypotheses of normalised weight below it are pruned
      (default 0: keep the ``H`` best); ``existence_threshold``: a track whose local hypotheses
      all have ``r`` at or below it is removed (default 1e-5); ``poisson_reduction``: the
      mixture-reduction strategy of the Poisson intensity, as the GM-PHD's ``reduction``
      (default :class:`~jaxtrack.multitarget.VoMaReduction` ``(1e-5, 4)``).
    - Deprecated (one release): ``birth_*``, ``initial_*``, ``poisson_prune_threshold``,
      ``poisson_merge_threshold``.
    - ``estimation_threshold``: estimates are the tracks of the best global hypothesis with
      ``r`` above it (default 0.4, the reference's estimator 1).
    - ``gate``: Mahalanobis distance beyond which a measurement does not update a track or a
      Poisson component (default ``inf``; the reference uses ``sqrt(20)``).
    - ``hypotheses``: the global-hypothesis strategy (the "k-best step"); default
      :class:`RankedAssignment` built from ``max_hypotheses``, ``assignment_rows``,
      ``assignment_tracks`` and ``hypothesis_threshold``. ``hypotheses=MarginalProjection(JPDA())``
      makes this filter the track-oriented PMB (:class:`~jaxtrack.multitarget.PMB` is exactly that).

    ``P_S``, ``P_D``, ``κ``, the intensities and thresholds are array leaves (no recompilation
    when they change). The update's discrete choices (which hypotheses are kept) make the filter
    piecewise smooth only.

    **Raises:** :class:`~jaxtrack.InputError` naming the argument.

    ??? cite "Reference"

        ```bibtex
        @article{garciafernandez2018pmbm,
          author  = {Garc{\'i}a-Fern{\'a}ndez, {\'A}ngel F. and Williams, Jason L. and
                     Granstr{\"o}m, Karl and Svensson, Lennart},
          title   = {Poisson Multi-{B}ernoulli Mixture Filter: Direct Derivation and Implementation},
          journal = {IEEE Transactions on Aerospace and Electronic Systems},
          volume  = {54}, number = {4}, pages = {1883--1901}, year = {2018}}
        ```
    """

    def __init__(self, filter, model, *, prob_survival, prob_detect, clutter_density=None, birth=None,
                 max_tracks: int, max_hypotheses: int | None = None, poisson_capacity: int = 16,
                 assignment_rows: int = 16, assignment_tracks: int = 24, initial=None, hypothesis_threshold=0.0,
                 existence_threshold=1e-5, poisson_reduction=None, estimation_threshold=0.4, gate=math.inf,
                 clutter_spatial_density=None, clutter_rate=None, clutter_volume=None,
                 hypotheses: AbstractGlobalHypotheses | None = None, **deprecated):
        fields = _mb_fields(
            filter, model, prob_survival=prob_survival, prob_detect=prob_detect,
            clutter=dict(clutter_density=clutter_density, clutter_spatial_density=clutter_spatial_density,
                         clutter_rate=clutter_rate, clutter_volume=clutter_volume),
            birth=birth, initial=initial, poisson_capacity=poisson_capacity, max_tracks=max_tracks,
            poisson_reduction=poisson_reduction, existence_threshold=existence_threshold,
            estimation_threshold=estimation_threshold, gate=gate, deprecated=deprecated, cls="PMBM",
        )
        for name, value in fields.items():
            setattr(self, name, value)
        if hypotheses is None:
            if max_hypotheses is None:
                raise InputError("PMBM needs `max_hypotheses` (H, the global hypotheses kept), or a `hypotheses` "
                                 "strategy.")
            hypotheses = RankedAssignment(max_hypotheses, assignment_rows=assignment_rows,
                                          assignment_tracks=assignment_tracks,
                                          hypothesis_threshold=hypothesis_threshold)
        elif not isinstance(hypotheses, AbstractGlobalHypotheses):
            raise InputError(f"`hypotheses` must be RankedAssignment(...) or MarginalProjection(...); got "
                             f"{type(hypotheses).__name__}.")
        hypotheses.check(self)
        self.hypotheses = hypotheses

    # The ranked assignment's settings, read through the filter (as before they were a strategy).
    @property
    def assignment_rows(self) -> int:
        return self.hypotheses.assignment_rows

    @property
    def assignment_tracks(self) -> int:
        return self.hypotheses.assignment_tracks

    @property
    def hypothesis_threshold(self) -> Float[Array, ""]:
        return self.hypotheses.hypothesis_threshold


class RankedAssignment(AbstractGlobalHypotheses):
    r"""The PMBM's global hypotheses: the ``H`` best posterior hypotheses over all prior ones at
    once, by Murty's ranked assignment (G18 Sec. V; :func:`~jaxtrack.association.k_best_assignments`),
    then pruned below ``hypothesis_threshold``.

    **Arguments:**

    - ``max_hypotheses``: ``H`` (the reference's ``Nhyp_max``; static).
    - ``assignment_rows``: ``A``, the most measurements per scan that fall in some track's gate,
      and ``assignment_tracks``: ``C``, the most tracks they reach (static; defaults 16, 24):
      beyond them a measurement can only start a new track, a track can only be missed, counted
      in ``assignment_overflow`` (a capacity event).
    - ``hypothesis_threshold``: global hypotheses of normalised weight below it are pruned
      (default 0: keep the ``H`` best).

    Needs ``P_D < 1`` (the assignment works on likelihood ratios to the miss).
    """

    max_hypotheses: int = eqx.field(static=True)
    assignment_rows: int = eqx.field(static=True)
    assignment_tracks: int = eqx.field(static=True)
    hypothesis_threshold: Float[Array, ""]

    def __init__(self, max_hypotheses: int, *, assignment_rows: int = 16, assignment_tracks: int = 24,
                 hypothesis_threshold=0.0):
        self.max_hypotheses = _positive_int("max_hypotheses", max_hypotheses)
        self.assignment_rows = _positive_int("assignment_rows", assignment_rows)
        self.assignment_tracks = _positive_int("assignment_tracks", assignment_tracks)
        self.hypothesis_threshold = _scalar("hypothesis_threshold", hypothesis_threshold, low=0.0, high=1.0)

    def check(self, f) -> None:
        if is_concrete(f.prob_detect) and float(f.prob_detect) >= 1.0:
            raise InputError("`prob_detect` must be < 1 for the PMBM (a track with r = 1 could not be missed).")

    def update(self, f, state: PMBMState, measurements, valid) -> tuple[PMBMState, PMBMStepInfo]:
        r"""Update (G18 Theorem 2) on one padded scan, with the ``H`` best posterior global
        hypotheses and the pruning of the module docstring.

        For a prior hypothesis ``h`` with local hypotheses ``l_t`` the assignment matrix has one row
        per measurement and one column per track, then one per new track:
        ``C[j, t] = −log(ℓ_det(t, l_t, j) / ℓ_miss(t, l_t))``, ``C[j, N + j] = −log(e_j + κ)``
        (+inf elsewhere; a padded row has only its own new-track column, at cost 0), and the
        offset ``−log w_h − Σ_t log ℓ_miss(t, l_t)``: a complete assignment's total is minus the
        log weight of the posterior hypothesis it makes (G18 eq. (25)).
        """
        dtype = state.existence.dtype
        valid = jnp.asarray(valid, bool)
        # Padding may hold NaN: zeros instead, so that no NaN reaches a product with a zero weight.
        z = jnp.where(valid[:, None], jnp.asarray(measurements, dtype), 0.0)
        k = state.step
        N, H = f.max_tracks, self.max_hypotheses
        M = z.shape[0]
        new_r, new_mean, new_cov, log_new, ppp_w = _new_tracks(f, state, z, valid, k)
        log_miss, log_det, r_miss = _track_weights(f, state, z, valid, k)

        l = state.hypotheses
        present = (l >= 0) & state.track_active[None, :] & state.hypothesis_active[:, None]
        li = jnp.maximum(l, 0)
        tix = jnp.arange(N)[None, :]
        lm = log_miss[tix, li]  # (H, N)
        ld = log_det[tix, li]  # (H, N, M)
        allowed = present[..., None] & jnp.isfinite(ld)
        cost_tracks = jnp.where(allowed, -(ld - jnp.where(present, lm, 0.0)[..., None]), jnp.inf)
        cost_tracks = jnp.swapaxes(cost_tracks, 1, 2)  # (H, M, N)
        # Only a measurement inside some track's gate (in some hypothesis) can be assigned in more
        # than one way; every other one starts its own track in every hypothesis. The ranked
        # assignment runs on those rows and the tracks they can take, compacted into A rows and C
        # track columns (then A new-track columns): Murty's cost is ~k·A³(A + C), not k·M³(M + N).
        A, C = self.assignment_rows, self.assignment_tracks
        in_gate = jnp.any(allowed, axis=(0, 1)) & valid  # (M,)
        rows = jnp.nonzero(in_gate, size=A, fill_value=M)[0]
        row_real = rows < M
        rows_c = jnp.minimum(rows, M - 1)
        n_rows = jnp.sum(in_gate).astype(jnp.int32)
        in_problem = jnp.zeros((M,), bool).at[rows].set(True, mode="drop")
        track_in = jnp.any(allowed[:, :, rows_c] & row_real[None, None, :], axis=(0, 2))  # (N,)
        cols = jnp.nonzero(track_in, size=C, fill_value=N)[0]
        col_real = cols < N
        cols_c = jnp.minimum(cols, N - 1)
        n_tracks = jnp.sum(track_in).astype(jnp.int32)
        sub_tracks = cost_tracks[:, rows_c][:, :, cols_c]
        sub_tracks = jnp.where(row_real[None, :, None] & col_real[None, None, :], sub_tracks, jnp.inf)
        sub_new = jnp.where(jnp.eye(A, dtype=bool), jnp.where(row_real, -log_new[rows_c], 0.0)[:, None], jnp.inf)
        sub = jnp.concatenate([sub_tracks, jnp.broadcast_to(sub_new, (H, A, A))], axis=-1)
        fixed = valid & ~in_problem  # starts its own track in every hypothesis
        offsets = -(jnp.where(state.hypothesis_active, state.log_weights, 0.0)
                    + jnp.sum(jnp.where(present, lm, 0.0), axis=1)
                    + jnp.sum(jnp.where(fixed, log_new, 0.0)))
        kb = k_best_assignments(sub, H, offsets=offsets, valid_parents=state.hypothesis_active)
        rc = kb.row_to_col  # (H, A): a compacted track column, or C + i (row i's new track)
        mapped = jnp.where(rc < C, cols_c[jnp.clip(rc, 0, C - 1)], N + rows_c[jnp.clip(rc - C, 0, A - 1)])
        rtc = jnp.broadcast_to(N + jnp.arange(M), (H, M)).at[:, rows].set(mapped, mode="drop")
        ok = kb.valid
        log_total, log_w = log_normalise(jnp.where(ok, -kb.total_cost, -jnp.inf), ok)
        hyp_active = ok & (log_w >= jnp.log(self.hypothesis_threshold.astype(dtype)))
        ppp_mass = jnp.sum(jnp.where(state.poisson_active, state.poisson_weights, 0.0))
        log_likelihood = log_total - f.prob_detect * ppp_mass

        parent = jnp.maximum(kb.parent, 0)
        par_l = state.hypotheses[parent]  # (H, N)
        par_present = (par_l >= 0) & state.track_active[None, :] & hyp_active[:, None]
        hit = rtc[:, :, None] == jnp.arange(N)[None, None, :]  # (H, M, N)
        has_det = jnp.any(hit, axis=1)
        det_j = jnp.argmax(hit, axis=1)
        child = jnp.where(par_present, par_l * (1 + M) + jnp.where(has_det, det_j + 1, 0), -1)
        new_in = hyp_active[:, None] & valid[None, :] & (rtc == (N + jnp.arange(M))[None, :])

        uniq, table = _compact_children(child, H)
        used = uniq < jnp.iinfo(jnp.int32).max
        c = jnp.where(used, uniq, 0)
        pl, a = c // (1 + M), c % (1 + M)
        rows = jnp.arange(N)[:, None]
        pm, pc = state.means[rows, pl], state.covs[rows, pl]  # (N, H, ...)
        n = pm.shape[-1]
        zj = z[jnp.maximum(a - 1, 0)]  # (N, H, m)
        dm, dc = _detected_moments(f, pm.reshape(N * H, n), pc.reshape(N * H, n, n), zj.reshape(N * H, -1), k)
        det = (a > 0)
        means = jnp.where(det[..., None], dm.reshape(N, H, n), pm)
        covs = jnp.where(det[..., None, None], dc.reshape(N, H, n, n), pc)
        existence = jnp.where(det, 1.0, r_miss[rows, pl])

        state = eqx.tree_at(lambda s: s.poisson_weights, state, ppp_w)
        state, n_drop = _finish(
            f, state, existence=existence, means=means, covs=covs, local_active=used, table=table, log_w=log_w,
            hyp_active=hyp_active, new_r=new_r, new_mean=new_mean, new_cov=new_cov, new_in=new_in, k=k, H=H,
        )
        n_over = jnp.maximum(n_rows - A, 0) + jnp.maximum(n_tracks - C, 0)
        state = eqx.tree_at(lambda s: s.assignment_overflow, state, state.assignment_overflow + n_over)
        info = PMBMStepInfo(state.num_hypotheses, jnp.sum(state.track_active).astype(jnp.int32), n_drop,
                            log_likelihood, jnp.ones((), bool), n_rows, n_tracks)
        return state, info

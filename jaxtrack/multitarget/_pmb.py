r"""The track-oriented Poisson multi-Bernoulli (PMB) filter: the PMBM's step with one global
hypothesis, the association marginals of :mod:`jaxtrack.association` in place of the ranked
hypotheses.

Williams (2015), "Marginal multi-Bernoulli filters: RFS derivation of MHT, JIPDA, and
association-based MeMBer", IEEE Trans. Aerosp. Electron. Syst. 51(3), 1664-1687 (W15): after
each update the PMBM posterior is projected back to a single multi-Bernoulli by marginalising
the global hypotheses track by track (W15 Sec. IV, the "TOMB/P" filter; the MATLAB reference's
``PMB_projection.m``). The marginals needed are exactly the JPDA marginals of the scan's
track-to-measurement problem in which a measurement taken by no existing track starts a new
track: dividing column ``j`` by the new-track weight ``e_j + κ`` turns it into the standard
problem (unassigned measurement = weight 1), so with

.. math::

    L[t, 0] = \log(1 − r_t P_D), \qquad
    L[t, 1 + j] = \log\big(r_t P_D N(z_j; ẑ_t, S_t)\big) − \log(e_j + κ)

any :class:`~jaxtrack.association.AbstractAssociator` gives ``β`` (``JPDA``: exact; ``LoopyBP``:
W15's belief propagation, Williams & Lau 2014). Track ``t`` becomes the Bernoulli with

.. math::

    r'_t = β_{t0} r^{miss}_t + \sum_j β_{tj}, \qquad
    p'_t(x) ∝ β_{t0} r^{miss}_t N(x; m_t, P_t) + \sum_j β_{tj} N(x; m_{tj}, P_{tj})

moment-matched to one Gaussian (W15 eqs. (67)-(69)), and measurement ``j``'s new track has
``r = (1 − Σ_t β_{tj}) e_j / (e_j + κ)``. With the exact marginals this is the projection of
the exact PMBM posterior (tested against :class:`~jaxtrack.multitarget.PMBM` enumerating every
hypothesis).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp

from .._validation import InputError, is_concrete
from ..association._jpda import JPDA
from ..association._types import AbstractAssociator
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


class PMB(AbstractMultiBernoulliFilter):
    r"""The track-oriented PMB filter (Williams 2015, TOMB/P) with fixed budgets.

    **Arguments:** as :class:`~jaxtrack.multitarget.PMBM` (without ``max_hypotheses`` and
    ``hypothesis_threshold``: there is one global hypothesis), plus

    - ``associator``: the association method giving the marginals, a strategy object
      (default :class:`~jaxtrack.association.JPDA`, exact within its cluster capacity;
      :class:`~jaxtrack.association.LoopyBP` for W15's belief propagation). When it cannot
      answer (``ok`` False) the scan's ``association_ok`` is False and :func:`run_pmbm` warns.

    ``clutter_density`` must be positive (the marginals are normalised by ``e_j + κ``).
    The state is a :class:`PMBMState` with ``H = 1``.

    ??? cite "Reference"

        ```bibtex
        @article{williams2015marginal,
          author  = {Williams, Jason L.},
          title   = {Marginal Multi-{B}ernoulli Filters: {RFS} Derivation of {MHT}, {JIPDA}, and
                     Association-Based {MeMBer}},
          journal = {IEEE Transactions on Aerospace and Electronic Systems},
          volume  = {51}, number = {3}, pages = {1664--1687}, year = {2015}}
        ```
    """

    def __init__(self, filter, model, *, prob_survival, prob_detect, clutter_density=None, birth=None,
                 max_tracks: int, poisson_capacity: int = 16, initial=None, existence_threshold=1e-5,
                 poisson_reduction=None, estimation_threshold=0.4, gate=math.inf,
                 associator: AbstractAssociator | None = None, clutter_spatial_density=None, clutter_rate=None,
                 clutter_volume=None, **deprecated):
        fields = _mb_fields(
            filter, model, prob_survival=prob_survival, prob_detect=prob_detect,
            clutter=dict(clutter_density=clutter_density, clutter_spatial_density=clutter_spatial_density,
                         clutter_rate=clutter_rate, clutter_volume=clutter_volume),
            birth=birth, initial=initial, poisson_capacity=poisson_capacity, max_tracks=max_tracks,
            poisson_reduction=poisson_reduction, existence_threshold=existence_threshold,
            estimation_threshold=estimation_threshold, gate=gate, deprecated=deprecated, cls="PMB",
        )
        for name, value in fields.items():
            setattr(self, name, value)
        self.hypotheses = MarginalProjection(associator)
        self.hypotheses.check(self)

    @property
    def associator(self) -> AbstractAssociator:
        """The association method of the projection (``hypotheses.associator``)."""
        return self.hypotheses.associator


class MarginalProjection(AbstractGlobalHypotheses):
    """The PMB's update (W15 Sec. IV-B): the PMBM posterior projected to one multi-Bernoulli
    through the association marginals of any :class:`~jaxtrack.association.AbstractAssociator`
    (module docstring). ``PMBM(..., hypotheses=MarginalProjection(associator))`` is the
    :class:`PMB`.

    **Arguments:** ``associator``: the association method (default
    :class:`~jaxtrack.association.JPDA`, exact within its cluster capacity; ``LoopyBP`` for W15's
    belief propagation). When it cannot answer (``ok`` False) the scan's ``association_ok`` is
    False, counted as a capacity event. Needs ``clutter_density > 0`` (the marginals are
    normalised by ``e_j + κ``).
    """

    associator: AbstractAssociator
    max_hypotheses: int = eqx.field(static=True)

    def __init__(self, associator: AbstractAssociator | None = None):
        associator = JPDA() if associator is None else associator
        if not isinstance(associator, AbstractAssociator):
            raise InputError(f"`associator` must be a jaxtrack association method (JPDA, LoopyBP, ...); got "
                             f"{type(associator).__name__}.")
        self.associator = associator
        self.max_hypotheses = 1

    def check(self, f) -> None:
        if is_concrete(f.clutter_density) and not float(f.clutter_density) > 0.0:
            raise InputError("`clutter_density` must be > 0 for the PMB (the marginals are normalised by e + κ).")

    def update(self, f, state: PMBMState, measurements, valid) -> tuple[PMBMState, PMBMStepInfo]:
        """The PMBM update projected to one multi-Bernoulli through the association marginals
        (module docstring; W15 Sec. IV-B)."""
        dtype = state.existence.dtype
        valid = jnp.asarray(valid, bool)
        # Padding may hold NaN: zeros instead, so that no NaN reaches a product with a zero weight.
        z = jnp.where(valid[:, None], jnp.asarray(measurements, dtype), 0.0)
        k = state.step
        N = f.max_tracks
        M = z.shape[0]
        new_r, new_mean, new_cov, log_new, ppp_w = _new_tracks(f, state, z, valid, k)
        log_miss, log_det, r_miss = _track_weights(f, state, z, valid, k)
        present = (state.hypotheses[0] >= 0) & state.track_active
        L = jnp.concatenate([log_miss[:, :1], log_det[:, 0, :] - log_new[None, :]], axis=1)
        L = jnp.where(present[:, None], L, -jnp.inf)
        assoc = self.associator(L, present)
        beta = jnp.where(present[:, None], assoc.association_probabilities, 0.0)
        b0, bj = beta[:, 0], beta[:, 1:]

        mean0, cov0 = state.means[:, 0], state.covs[:, 0]
        n = mean0.shape[-1]
        rep_m = jnp.repeat(mean0, M, axis=0)
        rep_c = jnp.repeat(cov0, M, axis=0)
        dm, dc = _detected_moments(f, rep_m, rep_c, jnp.tile(z, (N, 1)), k)
        dm, dc = dm.reshape(N, M, n), dc.reshape(N, M, n, n)
        w_miss = b0 * r_miss[:, 0]
        r = w_miss + jnp.sum(bj, axis=1)
        safe = jnp.where(r > 0.0, r, 1.0)
        mean = (w_miss[:, None] * mean0 + jnp.einsum("tj,tjn->tn", bj, dm)) / safe[:, None]
        d0 = mean0 - mean
        dd = dm - mean[:, None, :]
        cov = (w_miss[:, None, None] * (cov0 + d0[:, :, None] * d0[:, None, :])
               + jnp.einsum("tj,tjnp->tnp", bj, dc + dd[..., :, None] * dd[..., None, :])) / safe[:, None, None]
        mean = jnp.where(present[:, None], mean, mean0)
        cov = jnp.where(present[:, None, None], cov, cov0)

        taken = jnp.sum(bj, axis=0)
        new_r = jnp.where(valid, jnp.clip(1.0 - taken, 0.0, 1.0) * new_r, 0.0)
        table = jnp.where(present, 0, -1)[None, :].astype(jnp.int32)
        log_likelihood = (assoc.log_normalizer + jnp.sum(jnp.where(valid, log_new, 0.0))
                          - f.prob_detect * jnp.sum(jnp.where(state.poisson_active, state.poisson_weights, 0.0)))
        state = eqx.tree_at(lambda s: s.poisson_weights, state, ppp_w)
        state, n_drop = _finish(
            f, state, existence=jnp.where(present, r, 0.0)[:, None], means=mean[:, None], covs=cov[:, None],
            local_active=present[:, None], table=table, log_w=jnp.zeros((1,), dtype), hyp_active=jnp.ones((1,), bool),
            new_r=new_r, new_mean=new_mean, new_cov=new_cov, new_in=valid[None, :], k=k, H=1,
        )
        info = PMBMStepInfo(state.num_hypotheses, jnp.sum(state.track_active).astype(jnp.int32), n_drop,
                            log_likelihood, jnp.asarray(assoc.ok, bool), jnp.zeros((), jnp.int32),
                            jnp.zeros((), jnp.int32))
        return state, info

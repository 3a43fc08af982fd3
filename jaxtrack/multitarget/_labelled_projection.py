"""What a labelled filter (:mod:`._glmb`) keeps of its ranked δ-GLMB posterior: a strategy object,
as the ranking is. :class:`DeltaGLMB` keeps the hypotheses (the δ-GLMB filter);
:class:`LMBProjection` keeps each label's existence and density (the LMB filter), the density a
Gaussian mixture of at most ``max_components`` components.

Both start from the joint prediction–update's ranked hypotheses (:class:`_Ranked`, made by
:meth:`~jaxtrack.multitarget.GLMB.rank`) and form the posterior tracks themselves: the δ-GLMB one
Kalman update per (hypothesis, candidate), the LMB one per (candidate, gated measurement,
component), since all its hypotheses share one prior row.
"""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import logsumexp
from jaxtyping import Array

from .._validation import InputError
from ._base import Estimates
from ._mixture import AbstractMixtureReduction, VoMaReduction
from ._scenario import _positive_int

if TYPE_CHECKING:
    from ._glmb import GLMBState

__all__ = ["AbstractLabelledProjection", "DeltaGLMB", "LMBProjection"]


class _Ranked(NamedTuple):
    """The joint prediction–update's output: ``K`` ranked hypotheses over the ``R`` prior rows'
    ``P = N + B`` candidates (each a mixture of ``J`` components; ``J = 1`` unless the state
    stores components), ``A`` gated measurement columns."""

    parent: Array  # (K,) int: each hypothesis's prior row
    choice: Array  # (K, P) int: 0..A−1 the gated column that detected it, A missed, −1 absent
    log_w: Array  # (K,) normalised over the kept hypotheses, −inf elsewhere
    active: Array  # (K,) bool: kept
    labels: Array  # (R, P) int32
    component_log_weights: Array  # (R, P, J): normalised per candidate, −inf on unused components
    means: Array  # (R, P, J, n): predicted (births: as given)
    covs: Array  # (R, P, J, n, n)
    loglik: Array  # (R, P, J, A): log N(z; ẑ, S) of each component and gated column
    measurements: Array  # (A, m): the gated columns' measurements (unused columns: a finite copy)
    step: Array  # () int: the scan index


class _Posterior(NamedTuple):
    """The δ-GLMB's posterior hypotheses before pruning: ``K`` hypotheses × ``P`` candidates."""

    present: Array  # (K, P) bool
    labels: Array  # (K, P) int32
    means: Array  # (K, P, n)
    covs: Array  # (K, P, n, n)
    log_w: Array  # (K,) normalised over the ranked ones, −inf where not kept
    active: Array  # (K,) bool


def _place(present_old, born, N):
    """Slots for one hypothesis: candidates ``0..N−1`` keep their slot, born candidates
    (``born`` ``(B,)``) take the free slots in order. **Returns** ``(slot (B,)`` (``N`` = none),
    ``num_dropped)``."""
    B = born.shape[0]
    free = jnp.nonzero(~present_old, size=max(B, 1), fill_value=N)[0][:B]
    rank = jnp.cumsum(born) - 1
    slot = jnp.where(born, free[jnp.clip(rank, 0, B - 1)], N)
    return slot, jnp.sum(born & (slot >= N)).astype(jnp.int32)


def _scatter(present, labels, r, N, *arrays):
    """Candidates ``(P, ...)`` of one hypothesis into ``N`` slots; births (candidates ``N..``)
    into free slots. ``arrays``: per-candidate arrays, each scattered the same way.
    **Returns** ``(labels, existence, *arrays, num_dropped)``."""
    present_old = present[:N]
    slot, n_drop = _place(present_old, present[N:], N)
    labels = jnp.where(present_old, labels[:N], -1).at[slot].set(labels[N:], mode="drop")
    r = jnp.where(present_old, r[:N], 0.0).at[slot].set(r[N:], mode="drop")
    out = [a[:N].at[slot].set(a[N:], mode="drop") for a in arrays]
    return labels.astype(jnp.int32), r, *out, n_drop


def _merge_equal(labels, means, covs, log_w, active):
    """Hypotheses with the same labels and equal Gaussians merged into the first of each group,
    weights summed and the rows renormalised. "Equal": for every slot, two fixed random projections
    ``p = Wᵀx`` of its ``d = n + n²`` values agree within ``1e-9·|W|ᵀ(1 + |x|)``, i.e. to about
    1e-9 of the slot's scale (its largest values, the covariances). That merges the same history
    (the same arithmetic) and histories a Kalman filter has forgotten to that precision (an
    association many scans back); summing their weights changes the mixture by about the
    tolerance, and frees hypothesis budget. (A value-by-value test, each value within 1e-9 of
    itself, merged fewer: on Vo & Vo's benchmark at H = 128 the δ-GLMB's OSPA against the
    labeledRFS port went from +0.81 ± 0.22 m with it to +0.48 ± 0.20 m with this.) ``labels`` ``(K, N)`` (−1 empty), ``means`` ``(K, N, n)``, ``covs``
    ``(K, N, n, n)``. **Returns** ``(log_w (K,), active (K,))``."""
    big = jnp.iinfo(jnp.int32).max
    order = jnp.argsort(jnp.where(labels >= 0, labels, big), axis=1, stable=True)
    lab = jnp.take_along_axis(labels, order, axis=1)
    occ = lab >= 0
    m = jnp.take_along_axis(means, order[..., None], axis=1)
    c = jnp.take_along_axis(covs, order[..., None, None], axis=1).reshape(m.shape[:2] + (-1,))
    x = jnp.concatenate([m, c], axis=-1)  # (K, N, d), d = n + n²
    # Two projections, not the d values: O(K²·N·2), not O(K²·N·d) (18.5 → 5.1 ms at K = 512,
    # 1.5 → 0.75 ms at 128). Two, so that distinct slots agree in both only by coincidence.
    W = jnp.asarray(np.random.default_rng(20261207).normal(size=(x.shape[-1], 2)), x.dtype)  # fixed, (d, 2)
    proj = x @ W
    tol = 1e-9 * ((1.0 + jnp.abs(x)) @ jnp.abs(W))  # (K, N, 2)
    close = jnp.all(jnp.abs(proj[:, None] - proj[None, :]) <= tol[:, None], axis=-1)  # (K, K, N)
    slot_same = (lab[:, None] == lab[None, :]) & (~occ[:, None] | close)
    same = jnp.all(slot_same, axis=-1) & active[:, None] & active[None, :]
    K = labels.shape[0]
    first = jnp.argmax(same, axis=1)  # the first equal row (itself when none earlier)
    rep = active & (first == jnp.arange(K))
    top = jnp.max(jnp.where(active, log_w, -jnp.inf))
    top = jnp.where(jnp.isfinite(top), top, 0.0)
    summed = jax.ops.segment_sum(jnp.where(active, jnp.exp(log_w - top), 0.0), first, num_segments=K)
    total = jnp.sum(jnp.where(rep, summed, 0.0))
    safe = jnp.where(rep & (summed > 0.0), summed, 1.0)
    new = jnp.where(rep, jnp.log(safe) - jnp.log(jnp.where(total > 0.0, total, 1.0)), -jnp.inf)
    return new, rep


def _moments(w, means, covs):
    """One Gaussian with the first two moments of the mixture ``w`` ``(..., C)`` (summing to 1 or
    0), ``means`` ``(..., C, n)``, ``covs`` ``(..., C, n, n)``."""
    mean = jnp.einsum("...c,...cn->...n", w, means)
    d = means - mean[..., None, :]
    cov = jnp.einsum("...c,...cnq->...nq", w, covs + d[..., :, None] * d[..., None, :])
    return mean, cov


def _check_reduction(name: str, reduction) -> AbstractMixtureReduction:
    """``reduction``, or :class:`VoMaReduction` ``()`` for None; :class:`~jaxtrack.InputError`
    naming ``name`` otherwise."""
    reduction = VoMaReduction() if reduction is None else reduction
    if not isinstance(reduction, AbstractMixtureReduction):
        raise InputError(f"`{name}` must be a mixture reduction (VoMaReduction(...)); got {type(reduction).__name__}.")
    return reduction


class AbstractLabelledProjection(eqx.Module):
    """What a labelled filter keeps of the ranked δ-GLMB posterior: :class:`DeltaGLMB` (the
    δ-GLMB filter: the hypotheses themselves) or :class:`LMBProjection` (the LMB filter: the
    labels' marginals). ``rows(H)``: the hypothesis rows of the state; ``components()``: the
    Gaussian components a slot stores besides its one Gaussian (0: none, the Gaussian is its
    density); ``project(f, ranked)`` → ``(labels, existence, means, covs, log_weights, active,
    num_dropped, components)`` with ``rows(H)`` rows, ``components`` ``None`` or the slots'
    ``(log_weights, means, covs)``; ``estimates(f, state)``."""

    @abc.abstractmethod
    def rows(self, max_hypotheses: int) -> int:
        """The state's hypothesis rows."""

    def components(self) -> int:
        """The components a slot stores besides its Gaussian (0: none)."""
        return 0

    @abc.abstractmethod
    def project(self, f, ranked: _Ranked):
        """The state's arrays from the ranked posterior."""

    @abc.abstractmethod
    def estimates(self, f, state: GLMBState) -> Estimates:
        """The reported targets of ``state``."""


class DeltaGLMB(AbstractLabelledProjection):
    """The δ-GLMB filter's projection: none — the ``H`` best hypotheses, pruned below
    ``hypothesis_threshold`` (normalised weight), equal ones merged (same labels and Gaussians
    equal to about 1e-9 of their scale: they differed only in an absent track's history, or in
    an association long forgotten; :func:`_merge_equal`), renormalised (VVH17 Sec. IV). A detected
    track's Gaussian is its prediction updated on its measurement, a missed one keeps the
    prediction; one Gaussian per (hypothesis, label): the mixture over association histories is
    the hypotheses.

    Estimates (Vo & Vo's estimator, VVP14 Sec. IV-C / VVH17 Sec. IV-D): the MAP cardinality
    ``n* = argmax_n Σ_h w_h 1[|I_h| = n]``, then the heaviest hypothesis with ``|I_h| = n*``: its
    tracks' means, ids = labels."""

    def rows(self, max_hypotheses: int) -> int:
        return max_hypotheses

    def posterior(self, f, rk: _Ranked) -> _Posterior:
        """Every ranked hypothesis's tracks: one Kalman update per (hypothesis, detected candidate)."""
        K, P = rk.choice.shape
        n = rk.means.shape[-1]
        A = rk.measurements.shape[0]
        det = (rk.choice >= 0) & (rk.choice < A)
        present = rk.active[:, None] & (rk.choice >= 0)
        pm, pc = rk.means[rk.parent, :, 0], rk.covs[rk.parent, :, 0]  # (K, P, ...)
        z = rk.measurements[jnp.clip(rk.choice, 0, A - 1)]  # (K, P, m)
        observed = jnp.ones((z.shape[-1],), bool)
        upd = jax.vmap(lambda x, C, zz: f.filter.update(f.model, x, C, zz, observed, rk.step))(
            pm.reshape(K * P, n), pc.reshape(K * P, n, n), z.reshape(K * P, -1))
        means = jnp.where(det[..., None], upd.mean.reshape(K, P, n), pm)
        covs = jnp.where(det[..., None, None], upd.cov.reshape(K, P, n, n), pc)
        return _Posterior(present, rk.labels[rk.parent], means, covs, rk.log_w, rk.active)

    def project(self, f, rk: _Ranked):
        N = f.max_tracks
        post = self.posterior(f, rk)
        r = post.present.astype(post.means.dtype)
        labels, ex, means, covs, n_drop = jax.vmap(lambda p, lab, rr, m, c: _scatter(p, lab, rr, N, m, c))(
            post.present, post.labels, r, post.means, post.covs)
        ex = jnp.where(post.active[:, None], ex, 0.0)
        labels = jnp.where(post.active[:, None] & (ex > 0.0), labels, -1)
        log_w, active = _merge_equal(labels, means, covs, post.log_w, post.active)
        labels = jnp.where(active[:, None], labels, -1)
        ex = jnp.where(active[:, None], ex, 0.0)
        return labels, ex, means, covs, log_w, active, jnp.sum(jnp.where(post.active, n_drop, 0)), None

    def estimates(self, f, state: GLMBState) -> Estimates:
        N = f.max_tracks
        present = state.labels >= 0
        card = jnp.sum(present, axis=1)  # (R,)
        w = state.weights
        rho = jnp.zeros((N + 1,), w.dtype).at[card].add(w)
        n_star = jnp.argmax(rho)
        best = jnp.argmax(jnp.where(state.hypothesis_active & (card == n_star), state.log_weights, -jnp.inf))
        mask = present[best]
        return Estimates(jnp.where(mask[:, None], state.means[best], 0.0), mask,
                         jnp.where(mask, state.labels[best], -1).astype(jnp.int32))


class LMBProjection(AbstractLabelledProjection):
    r"""The LMB filter's projection (R14 Sec. III): every candidate label's existence and density
    over the ranked hypotheses,

    .. math::

        r_ℓ = Σ_h w_h 1[ℓ ∈ I_h] = Σ_{a} q_ℓ(a),\qquad
        p_ℓ = \frac{1}{r_ℓ} Σ_{a} q_ℓ(a)\, p_ℓ(· \mid a),\qquad q_ℓ(a) = Σ_h w_h 1[θ_h(ℓ) = a]

    with ``a`` "missed" or a gated measurement: ``p_ℓ(·|missed)`` is the predicted mixture,
    ``p_ℓ(·|z)`` the mixture updated on ``z`` (component ``c`` Kalman-updated, weight
    ``∝ w_c N(z; ẑ_c, S_c)``). The ``(A + 1)·J`` components of a label are then reduced to
    ``max_components``:

    - ``max_components = 1`` (default): one Gaussian with the mixture's mean and covariance
      (moment matching);
    - ``max_components = J > 1``: the ``reduction`` strategy (default
      :class:`~jaxtrack.multitarget.VoMaReduction` ``(1e-5, 4)``: Vo & Ma's pruning and merging,
      the labeledRFS port's ``elim_threshold``, ``merge_threshold``), its first ``J`` merged
      components kept and renormalised (the port's ``L_max`` cap: the budget is the
      approximation, as ``max_hypotheses`` is, so what it leaves is not a capacity event). The
      slot's ``means``/``covs`` are the kept mixture's moments; the components are in the state's
      ``component_*`` fields.

    Labels with ``r ≤ existence_threshold`` are removed; births take the free slots.

    Estimates (R14 Sec. IV-C): the MAP cardinality of the LMB (the Poisson-binomial distribution
    of the ``r_ℓ``), then that many labels of highest ``r``: the mean of each one's heaviest
    component (its only one when ``max_components = 1``; the labeledRFS port's estimator), ids =
    labels.

    **Arguments:** ``max_components``: static int ``≥ 1``; ``reduction``: an
    :class:`~jaxtrack.multitarget.AbstractMixtureReduction` (used when ``max_components > 1``).
    """

    max_components: int = eqx.field(static=True)
    reduction: AbstractMixtureReduction

    def __init__(self, max_components: int = 1, reduction: AbstractMixtureReduction | None = None):
        self.max_components = _positive_int("max_components", max_components)
        self.reduction = _check_reduction("reduction", reduction)

    def rows(self, max_hypotheses: int) -> int:
        return 1

    def components(self) -> int:
        return self.max_components if self.max_components > 1 else 0

    def project(self, f, rk: _Ranked):
        N, J = f.max_tracks, self.max_components
        P = rk.choice.shape[1]
        A = rk.measurements.shape[0]
        lw0, m0, c0, ll0 = rk.component_log_weights[0], rk.means[0], rk.covs[0], rk.loglik[0]
        Jin, n = m0.shape[1], m0.shape[-1]
        dtype = m0.dtype
        # Every ranked hypothesis has the one prior row: q_ℓ(a) over "detected by column a", "missed".
        w = jnp.where(rk.active, jnp.exp(jnp.where(rk.active, rk.log_w, 0.0)), 0.0)  # (K,)
        ch = jnp.where(rk.active[:, None] & (rk.choice >= 0), rk.choice, A + 1)
        q = jnp.einsum("k,kpa->pa", w, jax.nn.one_hot(ch, A + 2, dtype=dtype))[:, :A + 1]  # (P, A + 1)
        r_sum = jnp.sum(q, axis=1)
        r = jnp.clip(r_sum, 0.0, 1.0)
        # The components: each candidate component updated on each gated column, and the prediction.
        observed = jnp.ones((rk.measurements.shape[-1],), bool)
        mb = jnp.broadcast_to(m0[:, None], (P, A, Jin, n)).reshape(-1, n)
        cb = jnp.broadcast_to(c0[:, None], (P, A, Jin, n, n)).reshape(-1, n, n)
        zb = jnp.broadcast_to(rk.measurements[None, :, None], (P, A, Jin, rk.measurements.shape[-1]))
        upd = jax.vmap(lambda x, C, zz: f.filter.update(f.model, x, C, zz, observed, rk.step))(
            mb, cb, zb.reshape(P * A * Jin, -1))
        joint = lw0[:, None, :] + jnp.swapaxes(ll0, 1, 2)  # (P, A, Jin): log w_c N(z_a; ẑ_c, S_c)
        fin = jnp.isfinite(joint)
        top = jnp.max(jnp.where(fin, joint, -jnp.inf), axis=-1, keepdims=True)
        # log Σ_c w_c N(z_a; ...) (the label's likelihood of column a); −inf where no component is.
        track = jnp.where(jnp.isfinite(top), logsumexp(jnp.where(fin, joint, -jnp.inf), axis=-1, keepdims=True),
                          0.0)
        pos = q > 0.0
        log_q = jnp.log(jnp.where(pos, q, 1.0))
        log_det = jnp.where(pos[:, :A, None] & fin, log_q[:, :A, None] + joint - track, -jnp.inf)
        log_miss = jnp.where(pos[:, A:] & jnp.isfinite(lw0), log_q[:, A:] + lw0, -jnp.inf)
        log_c = jnp.concatenate([log_det.reshape(P, A * Jin), log_miss], axis=1)  # (P, C)
        cm = jnp.concatenate([upd.mean.reshape(P, A * Jin, n), m0], axis=1)
        cc = jnp.concatenate([upd.cov.reshape(P, A * Jin, n, n), c0], axis=1)
        safe_r = jnp.where(r_sum > 0.0, r_sum, 1.0)
        wc = jnp.where(jnp.isfinite(log_c), jnp.exp(log_c - jnp.log(safe_r)[:, None]), 0.0)  # Σ_c = 1 per label
        keep = r > f.existence_threshold.astype(dtype)
        if J == 1:
            mean, cov = _moments(wc, cm, cc)
            comps = ()
        else:
            red = jax.vmap(lambda ww, mm, cv, ac: self.reduction(ww, mm, cv, ac, J, m0[0, 0], c0[0, 0]))
            wr, mr, cr, ar = red(wc, cm, cc, wc > 0.0)[:4]
            wr = jnp.where(ar, wr, 0.0)
            tot = jnp.sum(wr, axis=1, keepdims=True)
            wr = wr / jnp.where(tot > 0.0, tot, 1.0)
            mean, cov = _moments(wr, mr, cr)
            lwr = jnp.where(keep[:, None] & (wr > 0.0), jnp.log(jnp.where(wr > 0.0, wr, 1.0)), -jnp.inf)
            comps = (lwr, mr, cr)
        # Removed labels keep a finite Gaussian (their prediction) in the slot.
        mean = jnp.where(keep[:, None], mean, m0[:, 0])
        cov = jnp.where(keep[:, None, None], cov, c0[:, 0])
        labels, ex, means, covs, *comps, n_drop = _scatter(keep, rk.labels[0], r, N, mean, cov, *comps)
        labels = jnp.where(ex > 0.0, labels, -1)
        zero = jnp.zeros((1,), dtype)
        if J == 1:
            comps = None
        else:  # free slots: no component
            slot_lw, slot_m, slot_c = comps
            comps = (jnp.where((labels >= 0)[:, None], slot_lw, -jnp.inf)[None], slot_m[None], slot_c[None])
        return labels[None], ex[None], means[None], covs[None], zero, jnp.ones((1,), bool), n_drop, comps

    def estimates(self, f, state: GLMBState) -> Estimates:
        N = f.max_tracks
        r = jnp.where(state.labels[0] >= 0, state.existence[0], 0.0)

        def conv(dist, ri):  # the Poisson-binomial cardinality distribution, one label at a time
            return dist * (1.0 - ri) + jnp.concatenate([jnp.zeros((1,), dist.dtype), dist[:-1]]) * ri, None

        dist, _ = jax.lax.scan(conv, jnp.zeros((N + 1,), r.dtype).at[0].set(1.0), r)
        n_star = jnp.argmax(dist)
        rank = jnp.argsort(jnp.argsort(-r, stable=True), stable=True)
        mask = (rank < n_star) & (r > 0.0)
        if state.component_log_weights is None:
            means = state.means[0]
        else:  # each label's heaviest component
            best = jnp.argmax(state.component_log_weights[0], axis=1)
            means = jnp.take_along_axis(state.component_means[0], best[:, None, None], axis=1)[:, 0]
        return Estimates(jnp.where(mask[:, None], means, 0.0), mask,
                         jnp.where(mask, state.labels[0], -1).astype(jnp.int32))

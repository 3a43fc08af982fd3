"""Soft association: PDA (each track alone), exact JPDA marginals, and loopy belief propagation.

All three take the shared log-weight matrix ``L`` (``_types``: column 0 the missed detection,
column ``j`` the log likelihood ratio of measurement ``j − 1`` against clutter, ``−inf`` outside
the gate and for padding) and return an :class:`~jaxtrack.association.Association`. They work in
log space throughout, have static shapes (one compilation per ``(T, M)``), are jittable and
vmappable, and are differentiable with respect to ``L`` (entries at ``−inf`` get gradient 0).

- :class:`PDA` (Bar-Shalom & Tse 1975): every track normalises its own row, ignoring the others.
- :class:`JPDA` (Fortmann, Bar-Shalom & Scheffe 1983): the exact marginals of the joint
  association, by a forward–backward dynamic program over subsets: of each cluster's tracks
  over the measurements that two tracks or more gate (``_jpda_sparse``), or, where that path
  does not answer, of the smaller side over everything (``O(max(T, M) · min(T, M) ·
  2^min(T, M))``, whatever the gates).
- :class:`LoopyBP` (Williams & Lau 2014): the belief-propagation approximation of the same
  marginals, a fixed number of iterations in ``lax.fori_loop``, ``O(num_iters · T · M)``; exact
  when the gating graph has no cycle.
"""

from __future__ import annotations

import functools
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._validation import CapacityWarning, InputError, is_concrete, nan_where_traced
from ._clusters import solve_by_cluster
from ._jpda_sparse import batch_any, sparse_marginals, subset_tables
from ._types import AbstractAssociator, Association

# ---------------------------------------------------------------------------------------------
# Log-space primitives whose gradients stay finite where every input is −inf.
#
# jax.nn.logsumexp and jnp.logaddexp give NaN gradients when all their inputs are −inf (a gated-
# out row, an unreachable subset of the dynamic program): log(0)' = inf meets exp(−inf)' = 0.
# Here the log of an empty sum is −inf with gradient 0 (the double-`where` of optax's
# numerics), which is the derivative of the sum of exponentials (0 in a neighbourhood).


def _lse(x: Array, axis: int = -1) -> Array:
    """``log Σ exp(x)`` along ``axis``; ``−inf`` (gradient 0) when every entry is ``−inf``."""
    m = jnp.max(x, axis=axis, keepdims=True, initial=-jnp.inf)
    # The shift only keeps exp in range; it does not change the value, so no gradient through it.
    m = jax.lax.stop_gradient(jnp.where(jnp.isfinite(m), m, 0.0))
    s = jnp.sum(jnp.exp(x - m), axis=axis, keepdims=True)
    positive = s > 0
    out = jnp.where(positive, jnp.log(jnp.where(positive, s, 1.0)), -jnp.inf) + m
    return jnp.squeeze(out, axis=axis)


def _logaddexp(a: ArrayLike, b: ArrayLike) -> Array:
    """``log(exp(a) + exp(b))`` elementwise, with :func:`_lse`'s gradient at ``−inf``."""
    return _lse(jnp.stack(jnp.broadcast_arrays(a, b)), axis=0)


def _leave_one_out_lse(x: Array, axis: int) -> Array:
    """``log Σ_{k ≠ j} exp(x_k)`` for every ``j`` along ``axis``, in ``O(size)``.

    Each entry is shifted by the largest of the *other* entries (the maximum, or for the
    maximum itself the runner-up), so the subtraction ``Σ_k − term_j`` leaves at least the
    shifted maximum's ``exp(0) = 1`` and never cancels catastrophically; the maximum's own sum
    is formed directly without it. (``log(Σ_k e^{x_k} − e^{x_j})`` unshifted would lose every
    other message of a track that is nearly certain of one measurement.) The shifts are
    constants to autodiff (they cancel), so gradients are those of the exact expression.
    """
    x = jnp.moveaxis(x, axis, -1)
    if x.shape[-1] == 0:
        return jnp.moveaxis(x, -1, axis)
    first = jnp.argmax(x, axis=-1, keepdims=True)
    is_first = jnp.arange(x.shape[-1]).reshape((1,) * (x.ndim - 1) + (-1,)) == first
    m1 = jnp.max(x, axis=-1, keepdims=True)
    m2 = jnp.max(jnp.where(is_first, -jnp.inf, x), axis=-1, keepdims=True, initial=-jnp.inf)
    m1, m2 = (jax.lax.stop_gradient(jnp.where(jnp.isfinite(m), m, 0.0)) for m in (m1, m2))
    e1 = jnp.exp(x - m1)
    others_than_first = jnp.sum(e1, axis=-1, keepdims=True) - e1  # ≥ 1 unless all −inf
    without_first = jnp.sum(jnp.where(is_first, 0.0, jnp.exp(x - m2)), axis=-1, keepdims=True)
    s = jnp.where(is_first, without_first, others_than_first)
    shift = jnp.where(is_first, m2, m1)
    positive = s > 0
    out = jnp.where(positive, jnp.log(jnp.where(positive, s, 1.0)), -jnp.inf) + shift
    return jnp.moveaxis(out, -1, axis)


# ---------------------------------------------------------------------------------------------
# Shared input handling.


def _prepare(log_weights: ArrayLike, valid_tracks: ArrayLike | None) -> tuple[Array, Array]:
    """``L`` as a float array with padded tracks made inert, and the boolean track mask.

    A padded track's row becomes ``[0, −inf, …, −inf]``: it is certainly missed with weight 1, so
    it claims no measurement and multiplies every joint event by 1, whatever its row held (NaN
    included: a select, not arithmetic). A valid row keeps what it holds, NaN and ``+inf``
    included: :func:`_result` reports them (the log-space sums would otherwise read a NaN as
    ``−inf``, i.e. as gated out, and answer with finite marginals).
    """
    L = jnp.asarray(log_weights)
    if not jnp.issubdtype(L.dtype, jnp.floating):
        L = L.astype(jnp.result_type(float))
    if L.ndim != 2 or L.shape[1] < 1:
        raise InputError(
            f"`log_weights` must have shape (T, 1 + M) (column 0: missed detection); got {L.shape}."
        )
    T = L.shape[0]
    if valid_tracks is None:
        valid = jnp.ones((T,), bool)
    else:
        valid = jnp.asarray(valid_tracks, bool)
        if valid.shape != (T,):
            raise InputError(f"`valid_tracks` must have shape ({T},); got {valid.shape}.")
    inert = jnp.concatenate(
        [jnp.zeros((T, 1), L.dtype), jnp.full((T, L.shape[1] - 1), -jnp.inf, L.dtype)], axis=1
    )
    return jnp.where(valid[:, None], L, inert), valid


def _result(beta, clutter, log_normalizer, residual, valid, L, overflow=None) -> Association:
    """The :class:`Association`, with padded rows zeroed and ``ok`` = everything finite, no
    capacity exceeded.

    ``L`` is the prepared matrix (:func:`_prepare`: padded rows inert). A valid row holding NaN
    or ``+inf`` has no probabilities (``−inf`` is legal: gated out; ``+inf`` is a certain event
    whose weight no sum can normalise): that row of ``β``, the clutter probabilities and
    ``log_normalizer`` become NaN, so ``ok`` is False whatever the method made of the entry.
    ``overflow`` (default False) is the method's capacity flag; it makes ``ok`` False too.
    """
    bad_rows = jnp.any(jnp.isnan(L) | (L == jnp.inf), axis=1)  # padded rows are inert: never bad
    bad = jnp.any(bad_rows)
    beta = jnp.where(bad_rows[:, None], jnp.nan, beta)
    beta = jnp.where(valid[:, None], beta, 0.0)
    clutter = jnp.where(bad, jnp.nan, clutter)
    log_normalizer = jnp.where(bad, jnp.nan, log_normalizer)
    overflow = jnp.zeros((), bool) if overflow is None else jnp.asarray(overflow, bool)
    ok = (
        jnp.isfinite(log_normalizer)
        & jnp.all(jnp.isfinite(beta))
        & jnp.all(jnp.isfinite(clutter))
        & jnp.isfinite(residual)
        & ~overflow
    )
    return Association(
        association_probabilities=beta,
        clutter_probabilities=clutter,
        log_normalizer=log_normalizer,
        residual=residual,
        ok=ok,
        overflow=overflow,
    )


# ---------------------------------------------------------------------------------------------
# PDA.


class PDA(AbstractAssociator):
    r"""Probabilistic data association: every track normalises its own row (Bar-Shalom & Tse 1975).

    .. math::

        β_{t j} = \frac{e^{L_{t j}}}{\sum_{j'=0}^{M} e^{L_{t j'}}}

    i.e. the single-target PDAF association probabilities (Bar-Shalom, Daum & Huang 2009, the
    ``β_i(k)`` of the PDAF) with ``L[t, 0] = log(1 − P_D P_G)`` and
    ``L[t, j] = log(P_D N(z_j; ẑ_t, S_t)/λ)``: Stone Soup's ``PDA`` with ``PDAHypothesiser``. The
    tracks do not compete for measurements, so ``clutter_probabilities = 1 − Σ_t β[t, j + 1]``
    can be negative where gates overlap (use :class:`JPDA` there).

    ``log_normalizer`` is ``Σ_t log Σ_j e^{L_{t j}}`` over valid tracks: the log of the
    normaliser of the product of independent rows (it counts events in which two tracks share a
    measurement). ``residual`` is 0; ``overflow`` False; ``ok`` is False when a valid row has no
    finite entry or holds a NaN or ``+inf`` (that row's ``β`` and ``log_normalizer`` are then NaN).
    """

    def __call__(
        self,
        log_weights: Float[ArrayLike, "T Mp1"],
        valid_tracks: Bool[ArrayLike, " T"] | None = None,
    ) -> Association:
        L, valid = _prepare(log_weights, valid_tracks)
        row = _lse(L, axis=1)
        beta = jnp.exp(L - jnp.where(jnp.isfinite(row), row, 0.0)[:, None])
        # A valid row whose every entry is −inf has no event: its probabilities are undefined.
        beta = jnp.where(jnp.isfinite(row)[:, None], beta, jnp.nan)
        beta = jnp.where(valid[:, None], beta, 0.0)
        clutter = 1.0 - jnp.sum(beta[:, 1:], axis=0)
        log_normalizer = jnp.sum(jnp.where(valid, row, 0.0))
        return _result(beta, clutter, log_normalizer, jnp.zeros((), L.dtype), valid, L)


# ---------------------------------------------------------------------------------------------
# Exact JPDA.


# The largest cluster (in tracks) that the sparse path solves (2^5 states); larger ones go
# through the log-space DP.
SPARSE_CLUSTER_TRACKS = 5
# Whether the sparse path runs at all (read at trace time). False reproduces the log-space DP's
# bits everywhere: the multi-target contract tests hold the refactor to results computed before
# the sparse path existed (the two agree to rounding, tests/test_association_jpda.py).
SPARSE_PATH = True


def _subset_dp(null: Array, pair: Array, unused: Array):
    r"""Exact marginals of a one-to-one matching by forward–backward over subsets of the bits.

    The matching: ``N`` *items* are processed in order; item ``i`` is either unmatched (log
    weight ``null[i]``) or takes one of the ``K`` *bits* not taken yet (log weight
    ``pair[i, b]``); a bit no item took contributes ``unused[b]``. The weight of a complete
    event is the product, ``Z`` the sum over all events. With ``α_i(S)`` the log weight of the
    events of items ``< i`` that took exactly the bits in ``S`` and ``γ_i(S)`` that of completing
    from ``(i, S)``:

    .. math::

        α_{i+1}(S) &= \mathrm{lse}\big(α_i(S) + \mathrm{null}_i,\;
                      \mathrm{lse}_{b∈S}\, α_i(S∖b) + \mathrm{pair}_{i b}\big),\quad
                      α_0 = [0, −∞, …] \\
        γ_N(S) &= \textstyle\sum_{b∉S} \mathrm{unused}_b,\quad
        γ_i(S) = \mathrm{lse}\big(\mathrm{null}_i + γ_{i+1}(S),\;
                  \mathrm{lse}_{b∉S}\, \mathrm{pair}_{i b} + γ_{i+1}(S∪b)\big)

    and every marginal is one ``lse`` over ``S`` of ``α + edge + γ − log Z``.

    **Arguments:** ``null`` ``(N,)``, ``pair`` ``(N, K)``, ``unused`` ``(K,)`` (log weights).

    **Returns:** ``(log_null (N,), log_pair (N, K), log_unused (K,), log_Z ())``: the log
    marginal probabilities that item ``i`` is unmatched, that it takes bit ``b``, that bit ``b``
    is not taken, and the log of the sum over all events.
    """
    N, K = pair.shape
    member_np, without_np, with_np = subset_tables(K)
    member = jnp.asarray(member_np)
    without, with_ = jnp.asarray(without_np), jnp.asarray(with_np)
    dtype = pair.dtype
    alpha0 = jnp.full((2**K,), -jnp.inf, dtype).at[0].set(0.0)

    def forward(alpha, inputs):
        null_i, pair_i = inputs
        take = jnp.where(member, alpha[without] + pair_i[None, :], -jnp.inf)
        new = _lse(jnp.concatenate([(alpha + null_i)[:, None], take], axis=1), axis=1)
        return new, alpha

    alpha_N, alphas = jax.lax.scan(forward, alpha0, (null, pair))
    # The bits no item took: a sum of their log weights per subset (a select, so that a −inf
    # weight of a bit that IS taken never meets a 0 coefficient).
    tail = jnp.sum(jnp.where(member, 0.0, unused[None, :]), axis=1)
    end = alpha_N + tail
    log_Z = _lse(end)
    # An infeasible problem (Z = 0, e.g. a track that must be detected but gates nothing) gives
    # NaN marginals through −inf − (−inf); keep them −inf instead and let `ok` report it.
    log_Z_safe = jnp.where(jnp.isfinite(log_Z), log_Z, 0.0)

    def backward(gamma, inputs):
        alpha_i, null_i, pair_i = inputs
        via = jnp.where(member, -jnp.inf, pair_i[None, :] + gamma[with_])  # (2^K, K)
        log_pair_i = _lse(alpha_i[:, None] + via, axis=0) - log_Z_safe
        log_null_i = _lse(alpha_i + null_i + gamma) - log_Z_safe
        gamma_prev = _lse(jnp.concatenate([(null_i + gamma)[:, None], via], axis=1), axis=1)
        return gamma_prev, (log_null_i, log_pair_i)

    _, (log_null, log_pair) = jax.lax.scan(backward, tail, (alphas, null, pair), reverse=True)
    log_unused = _lse(jnp.where(member, -jnp.inf, end[:, None]), axis=0) - log_Z_safe
    return log_null, log_pair, log_unused, log_Z


class JPDA(AbstractAssociator):
    r"""Exact joint probabilistic data association marginals (Fortmann, Bar-Shalom & Scheffe 1983).

    A joint event ``θ`` gives each track ``t`` a column ``θ_t`` (0: missed) such that no
    measurement goes to two tracks; its weight is ``Π_t exp L[t, θ_t]`` (measurements no track
    takes are clutter, weight 1 because ``L`` is a ratio against clutter). The marginals are

    .. math::

        β_{t j} = \frac{1}{Z} \sum_{θ:\, θ_t = j} \prod_{u} e^{L_{u θ_u}},\qquad
        Z = \sum_θ \prod_u e^{L_{u θ_u}}

    (Fortmann, Bar-Shalom & Scheffe 1983, the feasible joint events and their probabilities,
    with the clutter density ``λ`` in place of the gate-volume estimate; Stone Soup's ``JPDA``
    enumerates the same events with ``itertools.product``).

    **How.** Enumerating events costs ``Π_t (1 + m_t)``; here dynamic programs over subsets do
    it with static shapes. First the sparse path (:mod:`~jaxtrack.association._jpda_sparse`):
    a measurement only one track gates is folded into that track's missed weight, one no track
    gates drops out, and the remaining *shared* measurements are processed one by one (a loop
    as long as their number) by a DP whose state is the set of tracks of the measurement's
    cluster (tracks linked by shared measurements) already used, in linear space with each row
    divided by its missed weight; ``O(shared · bits · 2^bits)`` with ``bits`` = 5, the largest
    cluster it takes. Where it does not answer (a cluster of more than 5 tracks, more than 32
    shared measurements, weights out of its range, NaN), the log-space DP over subsets of the
    smaller side does, in ``O(max(T, M) · k · 2^k)`` with ``k = min(T, M)`` (with ``T ≤ M`` the
    measurements are the items and the state is the set of tracks already used; with ``T > M``
    the roles swap), forward and backward passes (``lax.scan``) in log space. Under ``vmap``
    the second runs only if some scan of the batch needs it. Both are exact; derivatives are
    those of the log-space DP (``custom_jvp``), the sparse path's loops having traced lengths.

    **Arguments:**

    - ``max_exact``: the largest ``k = min(T, M)`` solved as one problem, with ``T``, ``M`` the
      *padded* sizes (the subset table has ``2^k`` rows). Default 8 (256 subsets).
    - ``max_cluster_tracks``, ``max_cluster_measurements``, ``max_large_clusters``: for larger
      problems the scan is split into the clusters of its gating graph (tracks linked by a
      shared gated measurement; the joint events factor over them, Fortmann, Bar-Shalom &
      Scheffe 1983), each holding only the measurements its tracks gate, and each cluster is
      solved exactly (:func:`~jaxtrack.association._clusters.solve_by_cluster`, static shapes:
      every track a potential root of a cluster of up to 3 tracks, plus the
      ``max_large_clusters`` largest clusters of up to ``max_cluster_tracks`` tracks). Defaults
      8 tracks, 24 measurements, 2 large clusters. A cluster beyond a cap is not truncated in
      silence: ``ok`` is False and ``overflow`` True (the marginals of the clusters beyond the
      caps are wrong, by up to 1), and an eager call (concrete result, outside ``jit``/``vmap``)
      warns with :class:`~jaxtrack.multitarget.CapacityWarning`.

    **Returns** (from ``__call__``): an :class:`~jaxtrack.association.Association` with
    ``log_normalizer = log Z`` (the scan's log likelihood ratio against "every measurement is
    clutter and no target is detected"), ``clutter_probabilities`` the exact probability that
    each measurement is clutter (1 for a column no track can take, padded or not), ``residual``
    0, ``overflow`` True when a cluster exceeded a cap (``max_cluster_tracks``,
    ``max_cluster_measurements`` or ``max_large_clusters``), and ``ok`` False when ``Z = 0`` (no
    feasible event), ``overflow``, a valid row of ``L`` holds a NaN or ``+inf`` (that row's ``β``
    and ``log_normalizer`` are then NaN), or anything is not finite.

    **Warns:** :class:`~jaxtrack.multitarget.CapacityWarning` naming the caps to raise (or
    :class:`LoopyBP`, which has none) when called eagerly and ``overflow`` is True. Under
    ``jit``/``vmap`` there is no warning: read ``overflow``.

    Padded tracks (``valid_tracks`` False) and all-``−inf`` columns change nothing: a padded
    track is certainly missed with weight 1 and claims nothing; an all-``−inf`` column can only
    be clutter.
    """

    max_exact: int = eqx.field(static=True, default=8)
    max_cluster_tracks: int = eqx.field(static=True, default=8)
    max_cluster_measurements: int = eqx.field(static=True, default=24)
    max_large_clusters: int = eqx.field(static=True, default=2)

    def __check_init__(self):
        if not 1 <= self.max_exact <= 16:
            raise InputError(f"JPDA needs 1 <= max_exact <= 16; got max_exact={self.max_exact}.")
        if not 1 <= self.max_cluster_tracks <= 16:
            raise InputError(
                f"JPDA needs 1 <= max_cluster_tracks <= 16; got {self.max_cluster_tracks}."
            )
        if self.max_cluster_measurements < 1 or self.max_large_clusters < 1:
            raise InputError(
                "JPDA needs max_cluster_measurements >= 1 and max_large_clusters >= 1; got "
                f"{self.max_cluster_measurements} and {self.max_large_clusters}."
            )

    def __call__(
        self,
        log_weights: Float[ArrayLike, "T Mp1"],
        valid_tracks: Bool[ArrayLike, " T"] | None = None,
    ) -> Association:
        L, valid = _prepare(log_weights, valid_tracks)
        T, M = L.shape[0], L.shape[1] - 1
        overflow = largest = None
        if min(T, M) <= self.max_exact:
            beta, log_Z, _ = _jpda_dense(L, valid)
            ok = jnp.ones((), bool)
        else:
            beta, log_Z, ok, largest, overflow = solve_by_cluster(
                _jpda_dense, L, valid,
                max_cluster_tracks=self.max_cluster_tracks,
                max_cluster_measurements=self.max_cluster_measurements,
                max_large_clusters=self.max_large_clusters,
            )
        clutter = jnp.where(jnp.isfinite(log_Z), 1.0 - jnp.sum(beta[:, 1:], axis=0), jnp.nan)
        result = _result(beta, clutter, log_Z, jnp.zeros((), L.dtype), valid, L, overflow)
        result = eqx.tree_at(lambda r: r.ok, result, result.ok & ok)
        if overflow is not None and is_concrete(overflow) and bool(overflow):
            warnings.warn(
                f"JPDA's cluster capacities were exceeded (largest cluster: {int(largest)} tracks; "
                f"max_cluster_tracks={self.max_cluster_tracks}, max_cluster_measurements="
                f"{self.max_cluster_measurements}, max_large_clusters={self.max_large_clusters}): the "
                "marginals of the clusters beyond them are wrong (ok=False, overflow=True). Raise "
                "`max_cluster_tracks`, `max_cluster_measurements` or `max_large_clusters`, or use "
                "LoopyBP(), which has no capacity.",
                CapacityWarning,
                stacklevel=2,
            )
        return result


def _subset_exact(L: Array) -> tuple[Array, Array]:
    """Exact marginals of one (sub-)problem by the log-space subset DP: ``(beta, log_Z)``.

    Over subsets of the smaller side, whatever the gates; ``beta`` is NaN where ``Z = 0``.
    """
    T, M = L.shape[0], L.shape[1] - 1
    missed, ratios = L[:, 0], L[:, 1:]
    if T <= M:
        # Items: measurements (unmatched = clutter, log 1); bits: tracks (unused = missed).
        _, log_pair, log_missed, log_Z = _subset_dp(jnp.zeros((M,), L.dtype), ratios.T, missed)
        log_assoc = log_pair.T
    else:
        # Items: tracks (unmatched = missed); bits: measurements (unused = clutter, log 1).
        log_missed, log_assoc, _, log_Z = _subset_dp(missed, ratios, jnp.zeros((M,), L.dtype))
    beta = jnp.exp(jnp.concatenate([log_missed[:, None], log_assoc], axis=1))
    return jnp.where(jnp.isfinite(log_Z), beta, jnp.nan), log_Z


@functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
def _exact(L: Array, bits: int) -> tuple[Array, Array]:
    """``(beta, log_Z)`` of :func:`_subset_exact`, computed by the sparse path where it can.

    :func:`~jaxtrack.association._jpda_sparse.sparse_marginals` answers scans whose clusters
    have at most ``bits`` tracks (and whose normalisers are in range); the others, and a
    ``vmap`` batch in which any scan needs it, go through the log-space DP (``lax.cond`` on a
    batch-wide predicate, so that the DP runs only when needed). Derivatives are those of the
    log-space DP (the sparse path's loops have traced bounds).
    """
    T, M = L.shape[0], L.shape[1] - 1
    if T == 0 or M == 0:
        return _subset_exact(L)
    beta, log_Z, fallback = sparse_marginals(L, bits)

    def dense(_):
        beta_dp, log_Z_dp = _subset_exact(L)
        return jnp.where(fallback, beta_dp, beta), jnp.where(fallback, log_Z_dp, log_Z)

    return jax.lax.cond(batch_any(fallback), dense, lambda _: (beta, log_Z), None)


@_exact.defjvp
def _exact_jvp(bits, primals, tangents):
    del bits
    return jax.jvp(_subset_exact, primals, tangents)


def _jpda_dense(L: Array, valid: Array) -> tuple[Array, Array, Array]:
    """Exact marginals of one (sub-)problem: ``(beta, log_Z, ok)`` (invalid rows zeroed)."""
    # Padded rows are already inert ([0, -inf, ...]): _prepare, or solve_by_cluster's padding.
    beta, log_Z = _exact(L, SPARSE_CLUSTER_TRACKS) if SPARSE_PATH else _subset_exact(L)
    beta = jnp.where(valid[:, None], beta, 0.0)
    return beta, log_Z, jnp.isfinite(log_Z)


# ---------------------------------------------------------------------------------------------
# Loopy belief propagation.


class LoopyBP(AbstractAssociator):
    r"""Approximate JPDA marginals by loopy belief propagation (Williams & Lau 2014).

    With each valid row normalised by its missed weight, $ψ_{tj} = \exp(L[t, j] − L[t, 0])$,
    the messages between track ``t`` and measurement ``j`` are (Williams & Lau 2014, Section
    III; Stone Soup's ``JPDAwithLBP._loopy_belief_propagation``)

    .. math::

        μ_{t→j} = \frac{ψ_{tj}}{1 + \sum_{j' ≠ j} ψ_{tj'} ν_{j'→t}},\qquad
        ν_{j→t} = \frac{1}{1 + \sum_{t' ≠ t} μ_{t'→j}},\qquad ν^{(0)} = 1,

    and the beliefs $β_{tj} = ψ_{tj} ν_{j→t} / (1 + \sum_{j'} ψ_{tj'} ν_{j'→t})$,
    $β_{t0} = 1 / (1 + \sum_{j'} ψ_{tj'} ν_{j'→t})$. Everything is in log space; the
    leave-one-out sums are prefix/suffix ``logsumexp`` (no cancellation when one term
    dominates). A fixed ``num_iters`` iterations run in ``lax.fori_loop`` (no data-dependent
    loop: one compilation, reverse-mode differentiable).

    **Exactness.** BP is exact (to rounding, once converged) when the gating graph — tracks
    and measurements as nodes, an edge where ``L[t, j] > −inf`` — has no cycle: one track;
    tracks sharing no measurement; chains and trees such as ``t₁–z₁–t₂–z₂–t₃``. Two tracks that
    share two measurements make a cycle. It converges in as many iterations as the longest path
    in the graph; on graphs with cycles Williams & Lau show that the iteration converges, to an
    approximation (see ``tests/test_association_jpda.py`` for the error measured there).

    **Arguments:**

    - ``num_iters``: the number of message iterations (static), a Python int ≥ 1. Default 50.
    - ``damping``: ``δ ∈ [0, 1)``; the new ``log ν`` is ``(1 − δ)·new + δ·old`` (geometric
      damping). Default 0 (Williams & Lau's undamped iteration). (``δ = 1`` would never move
      the messages and report ``residual`` 0, "converged".)

    **Returns** (from ``__call__``): an :class:`~jaxtrack.association.Association` with

    - ``clutter_probabilities``: the measurement beliefs ``1 / (1 + Σ_t μ_{t→j})`` (equal to
      ``1 − Σ_t β_{tj}`` at a fixed point; 1 for a column no track can take);
    - ``log_normalizer``: the Bethe estimate of ``log Z`` (exact on trees at convergence),
      ``−F_B`` at the current beliefs, ``log Z_B`` below;
    - ``residual``: ``max |Δ log ν_{j→t}|`` over gated pairs in the last iteration;
    - ``ok``: False if anything is not finite — e.g. a valid row with ``L[t, 0] = −inf``
      (``P_D P_G = 1``), which the missed-weight normalisation cannot represent, a valid row
      holding NaN or ``+inf``, or a traced ``damping`` outside ``[0, 1)`` (it becomes NaN, and so
      does every message);
    - ``overflow``: False (no capacity).

    **The Bethe estimate** of the log partition function at the beliefs ``β`` and the measurement
    beliefs ``c_j``:

    .. math::

        \log Z_B = \sum_t L_{t0} + \sum_{t, j ≥ 1} β_{tj}(\log ψ_{tj} − \log β_{tj})
        − \sum_t β_{t0}\log β_{t0} − \sum_j c_j \log c_j
        + \sum_{t, j ≥ 1} (1 − β_{tj}) \log (1 − β_{tj})

    (the Bethe free energy of the matching; the last term is minus the mutual information of the
    track and measurement variables on each edge, cf. Vontobel 2013, "The Bethe permanent of a
    nonnegative matrix", for the square case without misses).

    **Raises:** :class:`~jaxtrack.InputError` at construction, naming the field, for
    ``num_iters`` not an int ≥ 1 or a concrete ``damping`` outside ``[0, 1)`` (NaN included). A
    traced ``damping`` (a ``LoopyBP`` passed through ``jit`` or ``vmap``) cannot be checked
    there: out of range, it gives ``ok`` False.
    """

    num_iters: int = eqx.field(static=True, default=50)
    damping: float | Float[Array, ""] = 0.0

    def __check_init__(self):
        if (isinstance(self.num_iters, (bool, np.bool_)) or not isinstance(self.num_iters, (int, np.integer))
                or self.num_iters < 1):
            raise InputError(f"LoopyBP needs `num_iters` a Python int >= 1; got num_iters={self.num_iters!r}.")
        if is_concrete(self.damping):
            d = np.asarray(self.damping, dtype=np.float64)
            if not np.all((d >= 0.0) & (d < 1.0)):
                raise InputError(
                    f"LoopyBP needs 0 <= `damping` < 1 (1 would never update the messages); got "
                    f"damping={self.damping!r}."
                )

    def __call__(
        self,
        log_weights: Float[ArrayLike, "T Mp1"],
        valid_tracks: Bool[ArrayLike, " T"] | None = None,
    ) -> Association:
        L, valid = _prepare(log_weights, valid_tracks)
        # log ψ: each row divided by its missed weight (Williams & Lau's normalisation).
        log_psi = L[:, 1:] - L[:, :1]
        gated = jnp.isfinite(log_psi)
        dtype = L.dtype
        # A traced damping skipped __check_init__: out of [0, 1) it becomes NaN, so that every
        # message, the residual and `ok` say so (a concrete one passed the check unchanged).
        damping = nan_where_traced(jnp.asarray(self.damping, dtype), lambda d: ~((d >= 0) & (d < 1)))

        def track_to_measurement(log_nu):
            # log μ_{t→j} = log ψ_tj − log(1 + Σ_{j'≠j} ψ_tj' ν_j't), and the row's
            # leave-one-out sums, reused by the Bethe estimate.
            loo = _leave_one_out_lse(log_psi + log_nu, axis=1)
            return log_psi - _logaddexp(0.0, loo), loo

        def measurement_to_track(log_mu):
            return -_logaddexp(0.0, _leave_one_out_lse(log_mu, axis=0))

        def body(_, carry):
            log_nu, _ = carry
            log_mu, _ = track_to_measurement(log_nu)
            new = measurement_to_track(log_mu)
            new = (1.0 - damping) * new + damping * log_nu
            change = jnp.max(jnp.where(gated, jnp.abs(new - log_nu), 0.0), initial=0.0)
            return new, change

        log_nu0 = jnp.zeros(log_psi.shape, dtype)
        log_nu, residual = jax.lax.fori_loop(
            0, self.num_iters, body, (log_nu0, jnp.zeros((), dtype))
        )

        # Beliefs from the last ν; the measurement beliefs from the μ those ν give.
        log_mu, loo = track_to_measurement(log_nu)
        weighted = log_psi + log_nu
        row = _logaddexp(0.0, _lse(weighted, axis=1))  # log(1 + Σ_j ψ ν) = −log β_t0
        log_beta = jnp.concatenate([-row[:, None], weighted - row[:, None]], axis=1)
        beta = jnp.exp(log_beta)
        col = _logaddexp(0.0, _lse(log_mu, axis=0))  # −log c_j
        clutter = jnp.exp(-col)

        # Bethe log Z in forms with no 0·log 0: β_tj (log ψ − log β_tj) = β_tj (row_t − log ν),
        # −β_t0 log β_t0 = β_t0 row_t, so each row gives row_t − Σ_j β_tj log ν_jt;
        # log(1 − β_tj) = log(1 + Σ_{j'≠j} ψ ν) − row_t, finite even where β_tj → 1.
        b = beta[:, 1:]
        log_one_minus = _logaddexp(0.0, loo) - row[:, None]
        rows = jnp.where(valid, L[:, 0] + row - jnp.sum(jnp.where(gated, b * log_nu, 0.0), axis=1), 0.0)
        edges = jnp.where(gated, jnp.exp(log_one_minus) * log_one_minus, 0.0)
        log_normalizer = jnp.sum(rows) + jnp.sum(clutter * col) + jnp.sum(edges)
        result = _result(beta, clutter, log_normalizer, residual, valid, L)
        # Explicitly too: with no measurement (M = 0) no message carries the NaN.
        return eqx.tree_at(lambda r: r.ok, result, result.ok & jnp.isfinite(damping))

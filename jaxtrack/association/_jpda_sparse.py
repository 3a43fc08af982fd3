"""Exact JPDA marginals that use the sparsity of the gates (the fast path of :class:`JPDA`).

Two exact reductions of the joint events of one scan (``L`` as in ``_types``):

- **Private measurements.** A measurement gated by exactly one track ``t`` is ``t``'s or
  clutter (weight 1) whatever the other tracks do, so "``t`` takes none of the shared
  measurements" splits into "missed" and "takes private measurement ``j``" in proportion to
  their weights. With ``u_t = e^{L[t,0]} + Σ_{j private} e^{L[t,j]}`` in place of the missed
  weight, only the *shared* measurements (gated by two tracks or more) are left; a
  measurement no track gates is clutter in every event and drops out.
- **Clusters.** Tracks linked through shared measurements form clusters whose events are
  independent (Fortmann, Bar-Shalom & Scheffe 1983), so ``Z`` is a product over clusters and
  each cluster's subset DP needs a bit per track *of that cluster*: ``2^bits`` states with
  ``bits`` the largest cluster allowed, one DP row per cluster, instead of ``2^T`` over every
  track or ``2^M`` over every measurement.

The DP is that of :func:`jaxtrack.association._jpda._subset_dp` over the shared measurements
(items, in index order; item ``k`` updates only its cluster's row), in linear space: ``α`` the
weight of the events of the items before ``k`` per set of used cluster bits, ``γ`` that of
completing them (the ``u`` of the bits never used); the marginal that item ``k`` is taken by
bit ``b`` is ``Σ_S α_k(S) w_kb γ_{k+1}(S ∪ b) / Z_c``, and a track's probability of taking no
shared measurement is the mass of the end states without its bit, which is then split over
"missed" and its private measurements.

Every row of ``L`` is divided by its missed weight ``e^{L[t,0]}`` (a factor common to every
joint event, so no marginal changes), which makes the all-missed event weigh 1: ``Z_c ≥ 1``
in these units, and the DP only adds and multiplies non-negative numbers (no cancellation).
Where that cannot hold — a row with ``L[t,0] = −inf`` (kept unscaled) whose cluster's
normaliser falls below ``TINY``, a NaN or infinite weight — and beyond the static capacities —
a cluster of more than ``bits`` tracks, more than ``HISTORY`` shared measurements — this path
does not answer: ``fallback`` is True (never a truncated answer) and the caller uses the
log-space DP, which answers everything (or reports ``Z = 0``).

Static shapes (one compilation per ``(T, M, bits)``). The number of shared measurements is a
loop bound (``lax.fori_loop`` with a traced bound) shared by every scan of a ``vmap`` batch
(:func:`batch_max`), so that the loop counter stays a scalar and the history of the forward
pass is written in place. Such loops are not reverse-differentiable; :class:`JPDA`
differentiates the log-space DP instead (``custom_jvp``), which has the same derivatives.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_batching import custom_vmap
from jaxtyping import Array, Bool, Float

# Smallest cluster normaliser answered in linear space (in units of the product of the
# missed weights, where it is >= 1 unless a missed weight is 0): an event that underflows
# (< 2.2e-308 in those units) is then below 1e-108 of Z and changes no marginal.
TINY = 1e-200

# The most shared measurements (gated by two tracks or more) a scan may have on this path: the
# forward pass keeps a 2^bits-state row per shared measurement for the backward pass.
HISTORY = 32


def subset_tables(K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For the ``2^K`` subsets ``S`` of ``K`` bits: membership ``(2^K, K)``, ``S∖{b}``, ``S∪{b}``."""
    states = np.arange(2**K, dtype=np.int64)[:, None]
    bits = np.left_shift(1, np.arange(K, dtype=np.int64))[None, :]
    member = (states & bits) != 0
    return member, (states & ~bits).astype(np.int32), (states | bits).astype(np.int32)


# ---------------------------------------------------------------------------------------------
# The same value for every scan of a vmap batch.


@custom_vmap
def batch_any(x: Bool[Array, ""]) -> Bool[Array, ""]:
    """``x`` itself; under ``jax.vmap``, ``any`` over the batch, *unbatched*.

    A ``lax.cond`` on a batched predicate becomes a ``select`` that runs both branches for
    every scan; on this unbatched one it stays a branch, run for the whole batch only when some
    scan needs it. (Nested ``vmap`` reduces over every level.)
    """
    return x


@batch_any.def_vmap
def _batch_any_rule(axis_size, in_batched, x):
    del axis_size
    return (batch_any(jnp.any(x, axis=0)) if in_batched[0] else x), False


@custom_vmap
def batch_max(x: Array) -> Array:
    """``x`` itself; under ``jax.vmap``, the maximum over the batch, unbatched (a shared loop
    bound, so that the loop counter stays a scalar and its writes stay in place)."""
    return x


@batch_max.def_vmap
def _batch_max_rule(axis_size, in_batched, x):
    del axis_size
    return (batch_max(jnp.max(x, axis=0)) if in_batched[0] else x), False



def _small_sum(x: Array, axis: int) -> Array:
    """``jnp.sum`` over a short axis (a state's bits) as unrolled adds, which XLA fuses into the
    loop that makes ``x``; a ``reduce`` there is a kernel of its own, and in a large ``vmap``
    batch a YNNPACK call (measured: the 8x80 batch 10 % faster, the 5x20 one 20 %)."""
    x = jnp.moveaxis(x, axis, 0)
    out = x[0]
    for i in range(1, x.shape[0]):
        out = out + x[i]
    return out


# ---------------------------------------------------------------------------------------------


def sparse_marginals(L: Float[Array, "T Mp1"], bits: int):
    """Exact JPDA marginals by the private/shared split and a subset DP per cluster.

    **Arguments:**

    - ``L``: ``(T, 1 + M)`` log weights with padded rows already inert (``[0, −inf, …]``);
      ``T ≥ 1``, ``M ≥ 1``.
    - ``bits``: the largest cluster (in tracks) solved here (static; ``2^bits`` DP states).
      With ``bits ≥ T`` all tracks form one DP row and no clusters are computed.

    **Returns:** ``(beta (T, 1 + M), log_Z (), fallback ())``: the marginals (an inert row gets
    ``[1, 0, …]``) and ``log Z``, valid where ``fallback`` is False (see the module docstring
    for when it is True).
    """
    T, M = L.shape[0], L.shape[1] - 1
    bits = max(1, min(bits, T))
    one_cluster = bits == T
    K = 2**bits
    H = min(M, HISTORY)  # shared measurements a scan may have
    dtype = L.dtype
    tracks, cols = jnp.arange(T), jnp.arange(M)

    # Gates (NaN counts as gated, so that it reaches the sums and sets `fallback`); rows
    # divided by their missed weights; `own`: the missed and private weights, summed in `u`.
    gated = L[:, 1:] != -jnp.inf
    shared = jnp.sum(gated, axis=0) >= 2
    gs = gated & shared[None, :]
    m = jnp.where(L[:, 0] > -jnp.inf, L[:, 0], 0.0)
    W = jnp.exp(L - m[:, None])
    own = jnp.where(jnp.concatenate([jnp.zeros((1,), bool), shared])[None, :], 0.0, W)
    u = jnp.sum(own, axis=1)

    # Clusters: connected components of "shares a measurement" by boolean squaring, labelled
    # by their smallest track; `local`: a track's bit, its rank in its cluster. `in_dp`: the
    # tracks the DP covers (those sharing something).
    if one_cluster:
        in_dp = jnp.ones((T,), bool)
        label = jnp.zeros((T,), tracks.dtype)
        local = tracks
        overflow = jnp.zeros((), bool)
        rows = 1
    else:
        in_dp = jnp.any(gs, axis=1)
        reach = jnp.any(gs[:, None, :] & gs[None, :, :], axis=2) | (tracks[:, None] == tracks[None, :])
        for _ in range(math.ceil(math.log2(T))):
            reach = jnp.any(reach[:, :, None] & reach[None, :, :], axis=1)
        label = jnp.argmax(reach, axis=1)
        local = jnp.sum((label[:, None] == label[None, :]) & (tracks[None, :] < tracks[:, None]), axis=1)
        overflow = jnp.any(in_dp & (local >= bits))
        local = jnp.minimum(local, bits - 1)
        rows = T
    bit_of = (local[:, None] == jnp.arange(bits)[None, :]) & in_dp[:, None]  # (T, bits)

    # Per cluster row and bit: the "takes no shared measurement" weight (1 for an unused bit),
    # and the end weights Π_{b ∉ S} U_b of every state. (One track per (row, bit): the sums
    # add one term to zeros.)
    if one_cluster:  # track t is bit t of the one row
        slot = np.eye(T, dtype=bool)[None]
        U = u[None, :]
    else:
        slot = (label[None, :] == jnp.arange(rows)[:, None])[:, :, None] & bit_of[None, :, :]
        U = jnp.where(jnp.any(slot, axis=1), jnp.sum(jnp.where(slot, u[None, :, None], 0.0), axis=1), 1.0)
    member_np, without_np, with_np = subset_tables(bits)
    member, without, with_ = jnp.asarray(member_np), jnp.asarray(without_np), jnp.asarray(with_np)
    tails = jnp.prod(jnp.where(member[None, :, :], 1.0, U[:, None, :]), axis=2)  # (rows, 2^bits)
    col_row = jnp.max(jnp.where(gs, label[:, None], 0), axis=0)  # a shared column's cluster row
    row_ids = jnp.arange(rows)

    def item(j):
        """Column ``j``'s cluster row (a mask) and its weight per cluster bit (0 if ``j = M``)."""
        jj = jnp.minimum(j, M - 1)
        w = jnp.where(j < M, jax.lax.dynamic_index_in_dim(W, jj + 1, 1, keepdims=False), 0.0)  # (T,)
        if one_cluster:
            return None, w
        p = jnp.sum(jnp.where(bit_of, w[:, None], 0.0), axis=0)
        return (row_ids == col_row[jj])[:, None], p

    def get_row(x, here):
        return x[0] if one_cluster else jnp.sum(jnp.where(here, x, 0.0), axis=0)

    def set_row(x, here, row):
        return row[None, :] if one_cluster else jnp.where(here, row[None, :], x)

    # Forward over the shared measurements in index order (each found by a search; past the
    # last one, j = M and the step changes nothing).
    def forward(k, carry):
        j, alpha, history, visited = carry
        j = jnp.min(jnp.where(shared & (cols > j), cols, M))
        here, p = item(j)
        a = get_row(alpha, here)
        history = jax.lax.dynamic_update_index_in_dim(history, a, k, 0)
        visited = jax.lax.dynamic_update_index_in_dim(visited, j, k, 0)
        a = a + _small_sum(jnp.where(member, a[without] * p[None, :], 0.0), axis=1)
        return j, set_row(alpha, here, a), history, visited

    n_s = jnp.sum(shared)
    n = batch_max(jnp.minimum(n_s, H))
    empty = jnp.zeros((rows, K), dtype).at[:, 0].set(1.0)
    init = (jnp.full((), -1, cols.dtype), empty, jnp.zeros((H, K), dtype), jnp.zeros((H,), cols.dtype))
    _, alpha, history, visited = jax.lax.fori_loop(0, n, forward, init)

    # Each cluster's normaliser and its tracks' probability of taking no shared measurement.
    end = alpha * tails
    z = jnp.sum(jnp.where(end >= 0, end, jnp.nan), axis=1)  # (a select, not a dot; keeps NaN)
    z_safe = jnp.where(z > 0, z, 1.0)
    unused = jnp.sum(jnp.where(member[None, :, :], 0.0, end[:, :, None]), axis=1) / z_safe[:, None]
    q = jnp.where(in_dp, unused[label, local], 1.0)
    used = np.ones((1,), bool) if one_cluster else jnp.any(slot, axis=(1, 2))  # a row that is a cluster's

    def backward(k, carry):
        gamma, taken = carry
        k = n - 1 - k
        j = visited[k]
        here, p = item(j)
        g = get_row(gamma, here)
        a = history[k]
        via = jnp.where(member, 0.0, p[None, :] * g[with_])  # (2^bits, bits)
        # (Selects rather than products with 0/1 masks, which XLA turns into dots.)
        pair = jnp.sum(jnp.where(member, 0.0, a[:, None] * via), axis=0)
        zk = jnp.sum(jnp.where(a * g >= 0, a * g, jnp.nan)) + _small_sum(pair, axis=0)  # Z_c again
        taken = jax.lax.dynamic_update_index_in_dim(taken, pair / jnp.where(zk > 0, zk, 1.0), j, 0)
        return set_row(gamma, here, g + _small_sum(via, axis=1)), taken

    # (Row M takes the steps past the last shared measurement.)
    _, taken = jax.lax.fori_loop(0, n, backward, (tails, jnp.zeros((M + 1, bits), dtype)))

    # Back to the tracks' rows: shared columns from the DP, the missed and private ones by
    # splitting each track's "no shared measurement" probability `q` in proportion.
    beta_shared = jnp.where(gs, taken[:M, local].T, 0.0)  # (T, M)
    u_safe = jnp.where(u > 0, u, 1.0)
    beta = own * (q / u_safe)[:, None] + jnp.concatenate([jnp.zeros((T, 1), dtype), beta_shared], axis=1)
    log_Z = jnp.sum(jnp.where(used, jnp.log(z_safe), 0.0)) + jnp.sum(jnp.where(in_dp, 0.0, jnp.log(u_safe))) + jnp.sum(m)
    bad = jnp.any(used & ~(z >= TINY)) | jnp.any(~in_dp & ~(u > 0)) | ~jnp.isfinite(log_Z)
    return beta, log_Z, bad | overflow | (n_s > H)

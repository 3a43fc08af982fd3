"""Clusters of a scan: tracks that share no gated measurement associate independently.

The joint events of a scan factor over the connected components of the gating graph (tracks
linked by a measurement both gate), so the exact JPDA marginals of a large scan are those of its
clusters solved one by one (Fortmann, Bar-Shalom & Scheffe 1983, §III; Stone Soup and pyehm
cluster the same way). With static shapes: every track is a potential cluster root, each
cluster gathers at most ``max_cluster_tracks`` tracks (padded), and the exact method runs on
every root's sub-problem under ``jax.vmap``. A cluster larger than the cap is never truncated
in silence: the result's ``ok`` is False, its ``overflow`` True, and :func:`cluster_sizes`
reports the sizes.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int


def track_clusters(log_weights: Float[Array, "T Mp1"], valid_tracks: Bool[Array, " T"]) -> Int[Array, " T"]:
    """The cluster label of every track: the smallest track index of its connected component.

    Two valid tracks are linked when some measurement is inside both gates (a finite entry in
    both rows of ``L[:, 1:]``); the components come from ``⌈log₂ T⌉`` boolean squarings of the
    link matrix (static iteration count). Invalid tracks are their own singleton clusters.

    **Arguments:** ``log_weights``: ``L`` ``(T, 1 + M)``; ``valid_tracks``: boolean ``(T,)``.

    **Returns:** int ``(T,)`` labels.
    """
    T = log_weights.shape[0]
    gated = jnp.isfinite(log_weights[:, 1:]) & valid_tracks[:, None]
    g = gated.astype(jnp.float32)
    reach = ((g @ g.T) > 0) | jnp.eye(T, dtype=bool)
    for _ in range(max(1, math.ceil(math.log2(max(T, 2))))):
        r = reach.astype(jnp.float32)
        reach = (r @ r) > 0
    return jnp.argmax(reach, axis=1).astype(jnp.int32)  # first True: the smallest member


def cluster_sizes(labels: Int[Array, " T"]) -> Int[Array, " T"]:
    """The number of tracks in the cluster rooted at each track (0 where a track is not a root)."""
    T = labels.shape[0]
    return jnp.zeros((T,), jnp.int32).at[labels].add(1)


@functools.partial(
    jax.jit,
    static_argnames=("solve", "max_cluster_tracks", "max_cluster_measurements", "max_large_clusters", "small"),
)
def solve_by_cluster(
    solve,
    log_weights,
    valid_tracks,
    *,
    max_cluster_tracks: int,
    max_cluster_measurements: int,
    max_large_clusters: int,
    small: int = 3,
):
    """Run ``solve(L_sub, valid_sub) -> (beta_sub, log_Z_sub, ok_sub)`` on every cluster.

    A cluster's sub-problem holds its tracks and only the measurements they gate (a measurement
    outside every gate of the cluster is clutter in every event, weight 1, so leaving it out is
    exact). Two tiers keep the static cost low where most clusters are small: every track is a
    potential root of a cluster of at most ``small`` tracks (sub-problems
    ``(small, 1 + max_cluster_measurements)``), and the ``max_large_clusters`` largest clusters
    beyond that are solved with up to ``max_cluster_tracks`` tracks. Jitted (``solve`` and the caps
    static): called eagerly (a JPDA outside ``jit``) it runs as one program, not op by op
    through its vmapped sub-problems; inside a trace it is inlined.

    **Arguments:**

    - ``solve``: the exact method on a padded sub-problem.
    - ``log_weights`` ``(T, 1 + M)``, ``valid_tracks`` ``(T,)``.
    - ``max_cluster_tracks``, ``max_cluster_measurements``: the caps of a cluster (static).
    - ``max_large_clusters``: how many clusters may exceed ``small`` tracks (static).

    **Returns:** ``(beta (T, 1 + M), log_Z (), ok (), largest (), overflow ())``: the marginals
    scattered back to the tracks' rows, the sum of the clusters' log normalisers, False when a
    cap was exceeded (or a sub-problem failed), the largest cluster's size, and True exactly
    when a cap was exceeded (a cluster with more than ``max_cluster_tracks`` tracks or gating
    more than ``max_cluster_measurements`` measurements, or more than ``max_large_clusters``
    clusters beyond ``small`` tracks).
    """
    T, Mp1 = log_weights.shape
    M = Mp1 - 1
    K = min(max_cluster_tracks, T)
    k_small = max(1, min(small, K - 1))  # below K, so that the large tier is the one with K
    C = min(max_cluster_measurements, M)
    labels = track_clusters(log_weights, valid_tracks)
    sizes = cluster_sizes(labels)
    gated = jnp.isfinite(log_weights[:, 1:]) & valid_tracks[:, None]
    # The measurements each cluster gates, on its root's row.
    cluster_cols = jnp.zeros((T, M), bool).at[labels].max(gated)
    num_cols = jnp.sum(cluster_cols, axis=1)
    is_root = sizes > 0
    L_pad = jnp.concatenate([log_weights, jnp.full((T, 1), -jnp.inf, log_weights.dtype)], axis=1)

    def one(root, k):
        members = jnp.nonzero(labels == root, size=k, fill_value=T)[0]
        cols = jnp.nonzero(cluster_cols[root], size=C, fill_value=M)[0]  # M: the -inf column
        present = members < T
        rows = jnp.minimum(members, T - 1)
        sub = L_pad[rows][:, jnp.concatenate([jnp.zeros((1,), cols.dtype), cols + 1])]
        sub_valid = present & valid_tracks[rows]
        # Padding rows (copies of a real row) become inert: certainly missed, weight 1.
        inert = jnp.concatenate([jnp.zeros_like(sub[:, :1]), jnp.full_like(sub[:, 1:], -jnp.inf)], axis=1)
        beta, log_z, ok = solve(jnp.where(sub_valid[:, None], sub, inert), sub_valid)
        return members, cols, beta, log_z, ok

    def scatter(beta, members, cols, beta_sub, use):
        members = jnp.where(use[:, None], members, T)  # unused sub-problems write to row T
        k = members.shape[1]
        col_index = jnp.concatenate([jnp.zeros_like(cols[:, :1]), cols + 1], axis=1)  # (R, 1 + C)
        r = jnp.broadcast_to(members[:, :, None], (members.shape[0], k, 1 + C))
        c = jnp.broadcast_to(col_index[:, None, :], r.shape)
        return beta.at[r.reshape(-1), c.reshape(-1)].set(beta_sub.reshape(-1), mode="drop")

    beta = jnp.zeros((T + 1, Mp1 + 1), log_weights.dtype)
    small_roots = is_root & (sizes <= k_small)
    members, cols, b, log_z_small, ok_small = jax.vmap(lambda r: one(r, k_small))(jnp.arange(T))
    beta = scatter(beta, members, cols, b, small_roots)
    # The largest clusters beyond the small tier (top-k by size: static count).
    big_size = jnp.where(is_root & (sizes > k_small), sizes, 0)
    num_big = jnp.sum(big_size > 0)
    top = jax.lax.top_k(big_size, min(max_large_clusters, T))[1]
    use_big = big_size[top] > 0
    members, cols, b, log_z_big, ok_big = jax.vmap(lambda r: one(r, K))(top)
    beta = scatter(beta, members, cols, b, use_big)
    beta = beta[:T, :Mp1]
    log_Z = jnp.sum(jnp.where(small_roots, log_z_small, 0.0)) + jnp.sum(jnp.where(use_big, log_z_big, 0.0))
    largest = jnp.max(sizes)
    overflow = (
        (largest > K)
        | (num_big > max_large_clusters)
        | jnp.any(jnp.where(is_root, num_cols > C, False))
    )
    ok = (
        jnp.all(jnp.where(small_roots, ok_small, True))
        & jnp.all(jnp.where(use_big, ok_big, True))
        & ~overflow
    )
    return beta, log_Z, ok, largest, overflow

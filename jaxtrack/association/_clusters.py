"""Clusters of a scan: tracks that share no gated measurement associate independently.

The joint events of a scan factor over the connected components of the gating graph (tracks
linked by a measurement both gate), so the exact JPDA marginals of a large scan are those of its
clusters solved one by one (Fortmann, Bar-Shalom & Scheffe 1983, §III; Stone Soup and pyehm
cluster the same way). With static shapes: every track is a potential cluster root, each
cluster gathers at most ``max_cluster_tracks`` tracks (padded), and the exact method runs on
every root's sub-problem under ``jax.vmap``. A cluster larger than the cap is never truncated
in silence: the result's ``ok`` is False and :func:`cluster_sizes` reports the sizes.
"""

from __future__ import annotations

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


def solve_by_cluster(solve, log_weights, valid_tracks, max_cluster_tracks: int):
    """Run ``solve(L_sub, valid_sub) -> (beta_sub, log_Z_sub, ok_sub)`` on every cluster.

    **Arguments:**

    - ``solve``: the exact method on a ``(K, 1 + M)`` sub-problem (``K = max_cluster_tracks``).
    - ``log_weights`` ``(T, 1 + M)``, ``valid_tracks`` ``(T,)``.
    - ``max_cluster_tracks``: ``K``, the static cap on a cluster's size.

    **Returns:** ``(beta (T, 1 + M), log_Z (), ok (), largest ())``: the marginals scattered back
    to the tracks' rows, the sum of the clusters' log normalisers, False when a cluster exceeded
    the cap (or a sub-problem failed), and the largest cluster's size.
    """
    T = log_weights.shape[0]
    K = min(max_cluster_tracks, T)
    labels = track_clusters(log_weights, valid_tracks)
    sizes = cluster_sizes(labels)
    is_root = sizes > 0

    def one(root):
        members = jnp.nonzero(labels == root, size=K, fill_value=T)[0]
        present = members < T
        rows = jnp.minimum(members, T - 1)
        sub_valid = present & valid_tracks[rows]
        beta, log_z, ok = solve(log_weights[rows], sub_valid)
        return members, beta, log_z, ok

    members, beta_sub, log_z, ok_sub = jax.vmap(one)(jnp.arange(T))
    # Scatter each root's rows back; non-root sub-problems are discarded (their rows index T).
    members = jnp.where(is_root[:, None], members, T)
    beta = jnp.zeros((T + 1, log_weights.shape[1]), log_weights.dtype)
    beta = beta.at[members.reshape(-1)].set(beta_sub.reshape(-1, beta_sub.shape[-1]))[:T]
    log_Z = jnp.sum(jnp.where(is_root, log_z, 0.0))
    largest = jnp.max(sizes)
    ok = jnp.all(jnp.where(is_root, ok_sub, True)) & (largest <= K)
    return beta, log_Z, ok, largest

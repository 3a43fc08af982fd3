"""Soft association (``association._jpda``) and the PDA update (``association._pda_update``).

Oracles: brute-force enumeration of every joint event (numpy, itertools); Stone Soup's ``JPDA``,
``PDA`` and ``PDAUpdater`` with ``PDAHypothesiser`` on the same scenario (its own predictor,
updater, gate and probabilities; ``L`` is built here independently from the same ``P_D``,
``P_G`` and ``λ``); pyehm's ``EHM``/``EHM2`` on a 9-track problem; the plain Kalman update.
Every function is jitted once at module level and batched with ``vmap``.
"""

from __future__ import annotations

import functools
import itertools
from datetime import datetime, timedelta

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import chi2

from jaxtrack._validation import InputError
from jaxtrack.association._jpda import JPDA, PDA, LoopyBP
from jaxtrack.association._pda_update import pda_update
from jaxtrack.filters import ExtendedKalmanFilter, KalmanFilter
from jaxtrack.models import LinearGaussianModel, NonlinearGaussianModel

NINF = -np.inf
BP_ITERS = 50
BATCH = 50  # every vmapped call uses this batch size: one compilation per (T, M) per method

_jpda = jax.jit(jax.vmap(JPDA()))
_bp = jax.jit(jax.vmap(LoopyBP(num_iters=BP_ITERS)))
_pda = jax.jit(jax.vmap(PDA()))
_pda_update = jax.jit(pda_update, static_argnames="form")


@functools.cache
def _jit(method):
    """``method`` jitted once (one compilation per input shape)."""
    return jax.jit(lambda L, valid=None: method(L, valid))


def _numpy(assoc):
    return jax.tree.map(np.asarray, assoc)


# ---------------------------------------------------------------------------------------------
# Brute force: every joint event.


@functools.cache
def _events(T: int, M: int) -> np.ndarray:
    """All feasible joint events ``θ`` ``(E, T)``: column per track, no measurement twice."""
    rows = [
        th
        for th in itertools.product(range(M + 1), repeat=T)
        if len([j for j in th if j]) == len({j for j in th if j})
    ]
    return np.array(rows, dtype=np.int64).reshape(len(rows), T)


def brute_force(L: np.ndarray):
    """Exact marginals, clutter probabilities and ``log Z`` by enumeration."""
    T, M = L.shape[0], L.shape[1] - 1
    ev = _events(T, M)
    log_w = L[np.arange(T)[None, :], ev].sum(axis=1) if T else np.zeros(len(ev))
    c = log_w.max()
    w = np.exp(log_w - c)
    Z = w.sum()
    beta = np.stack([np.bincount(ev[:, t], weights=w, minlength=M + 1) for t in range(T)]) / Z
    beta = beta.reshape(T, M + 1)
    clutter = np.array([w[~(ev == j + 1).any(axis=1)].sum() for j in range(M)]) / Z
    return beta, clutter, np.log(Z) + c


def _random_problems(rng, n, T, M, *, gate_prob=0.6, pad=True):
    """``n`` random ``L`` ``(T, 1 + M)`` with random gates, padded tracks and padded columns."""
    L = rng.normal(1.0, 2.0, size=(n, T, 1 + M))
    pd_pg = rng.uniform(0.3, 0.98, size=(n, T))
    L[:, :, 0] = np.log1p(-pd_pg)
    L[:, :, 1:][rng.random((n, T, M)) > gate_prob] = NINF
    valid = np.ones((n, T), bool)
    if pad:
        valid = rng.random((n, T)) < 0.8
        num_meas = rng.integers(0, M + 1, size=n)  # measurements beyond are padding
        padded = np.arange(M)[None, None, :] >= num_meas[:, None, None]
        out = (rng.random((n, T)) < 0.15)[:, :, None]  # some rows gated out entirely
        L[:, :, 1:] = np.where(padded | out, NINF, L[:, :, 1:])
        # Padded tracks hold garbage: it must not matter.
        garbage = np.where(rng.random((n, T, 1 + M)) < 0.5, np.nan, 1e300)
        L = np.where(valid[:, :, None], L, garbage)
    return L, valid


@pytest.mark.parametrize("T, M", [(4, 6), (4, 3)], ids=["tracks<=meas", "tracks>meas"])
def test_jpda_equals_brute_force(T, M):
    """Exact JPDA marginals, clutter probabilities and log Z equal every-event enumeration."""
    rng = np.random.default_rng(10 + T * 10 + M)
    L, valid = _random_problems(rng, BATCH, T, M)
    got = _numpy(_jpda(jnp.asarray(L), jnp.asarray(valid)))
    assert got.ok.all()
    worst = 0.0
    for i in range(len(L)):
        beta, clutter, log_Z = brute_force(L[i][valid[i]])
        expect = np.zeros((T, M + 1))
        expect[valid[i]] = beta
        worst = max(
            worst,
            np.abs(got.association_probabilities[i] - expect).max(),
            np.abs(got.clutter_probabilities[i] - clutter).max(),
            abs(got.log_normalizer[i] - log_Z),
        )
    assert worst <= 1e-12, worst
    rows = got.association_probabilities.sum(axis=2)
    np.testing.assert_allclose(rows[valid], 1.0, atol=1e-13)
    assert (rows[~valid] == 0).all()


@pytest.mark.parametrize("T, M", [(3, 0), (0, 4), (2, 2)])
def test_jpda_small_and_empty(T, M):
    """Empty scans, no tracks, and all-gated-out rows: still exact and ok."""
    rng = np.random.default_rng(T * 7 + M)
    L = rng.normal(size=(T, 1 + M))
    if T and M:
        L[0, 1:] = NINF  # track 0 sees nothing
    beta, clutter, log_Z = brute_force(L) if T else (np.zeros((0, 1 + M)), np.ones(M), 0.0)
    for method in (JPDA(), LoopyBP(num_iters=10)):
        got = _numpy(_jit(method)(jnp.asarray(L)))
        assert got.ok
        assert got.association_probabilities.shape == (T, 1 + M)
        np.testing.assert_allclose(got.association_probabilities, beta, atol=1e-14)
        np.testing.assert_allclose(got.clutter_probabilities, clutter, atol=1e-14)
        np.testing.assert_allclose(got.log_normalizer, log_Z, atol=1e-14)


def _clustered_problem(rng, num_clusters=4, size=3, M_per=3):
    """``num_clusters`` independent blocks of ``size`` tracks x ``M_per`` measurements, shuffled;
    with the exact answer from brute force on each block (the events factor over blocks)."""
    T, M = num_clusters * size, num_clusters * M_per
    L = np.full((T, 1 + M), NINF)
    L[:, 0] = np.log(rng.uniform(0.05, 0.7, T))
    beta, log_Z = np.zeros((T, 1 + M)), 0.0
    for c in range(num_clusters):
        rows, cols = slice(c * size, (c + 1) * size), slice(1 + c * M_per, 1 + (c + 1) * M_per)
        block = rng.normal(1.0, 2.0, (size, M_per))
        block[rng.uniform(size=block.shape) < 0.3] = NINF
        L[rows, cols] = block
        b, _, z = brute_force(np.concatenate([L[rows, :1], block], axis=1))
        beta[rows, 0], beta[rows, cols], log_Z = b[:, 0], b[:, 1:], log_Z + z
    perm_t, perm_m = rng.permutation(T), np.r_[0, 1 + rng.permutation(M)]
    return L[perm_t][:, perm_m], beta[perm_t][:, perm_m], log_Z


def test_jpda_clusters_a_large_scan_exactly():
    """Above ``max_exact`` the scan is solved cluster by cluster (two tiers: clusters of <= 2
    tracks as small ones, the 4 largest others with up to 3): the marginals of brute force on
    each block (the joint events factor over the gating graph's components), and a cluster
    over a cap is reported (ok False), not truncated."""
    rng = np.random.default_rng(11)
    cases = [_clustered_problem(rng) for _ in range(BATCH)]
    L = jnp.asarray(np.stack([c[0] for c in cases]))  # (50, 12, 13)
    clustered = _numpy(jax.jit(jax.vmap(
        JPDA(max_exact=4, max_cluster_tracks=3, max_cluster_measurements=3, max_large_clusters=4)
    ))(L))
    assert clustered.ok.all()
    np.testing.assert_allclose(clustered.association_probabilities, np.stack([c[1] for c in cases]), atol=1e-13)
    np.testing.assert_allclose(clustered.log_normalizer, [c[2] for c in cases], atol=1e-12)
    np.testing.assert_allclose(clustered.clutter_probabilities,
                               1.0 - np.stack([c[1] for c in cases])[:, :, 1:].sum(axis=1), atol=1e-13)
    # Caps: a 3-track cluster over max_cluster_tracks=2, or 3 gated measurements over 2.
    for too_small in (JPDA(max_exact=4, max_cluster_tracks=2, max_cluster_measurements=3, max_large_clusters=4),
                      JPDA(max_exact=4, max_cluster_tracks=3, max_cluster_measurements=2, max_large_clusters=4)):
        assert not _numpy(jax.jit(jax.vmap(too_small))(L)).ok.any()


def test_jpda_options_are_checked():
    with pytest.raises(InputError, match="max_cluster_tracks"):
        JPDA(max_cluster_tracks=17)
    with pytest.raises(InputError, match="max_large_clusters"):
        JPDA(max_large_clusters=0)


def test_jpda_infeasible_is_not_ok():
    """A track that must be detected (missed weight 0) but gates nothing: no event, ok False."""
    L = np.array([[NINF, NINF, NINF], [0.0, 1.0, 2.0]])
    got = _jit(JPDA())(jnp.asarray(L))
    assert not bool(got.ok)
    assert not np.isfinite(float(got.log_normalizer))


# ---------------------------------------------------------------------------------------------
# Padding invariance.


def _embed(L, rows, cols, T_pad, M_pad, rng):
    """``L`` placed at ``rows``/``cols`` of a padded matrix: garbage rows, −inf columns."""
    big = np.where(rng.random((T_pad, 1 + M_pad)) < 0.5, np.nan, 7.0)
    valid = np.zeros(T_pad, bool)
    valid[rows] = True
    big[rows] = NINF
    big[np.ix_(rows, [0] + [c + 1 for c in cols])] = L
    return big, valid


@pytest.mark.parametrize("method", [JPDA(), LoopyBP(num_iters=BP_ITERS)], ids=["JPDA", "LoopyBP"])
def test_padding_invariance(method):
    """Extra −inf columns and invalid (garbage) tracks change nothing, to 1e-13; this also
    crosses the DP's orientation: (3 tracks, 2 measurements) is T > M, padded (6, 5) is T ≤ M.
    (The brute-force test checks padding at fixed shapes against enumeration as well.)"""
    rng = np.random.default_rng(3)
    for T, M, T_pad, M_pad in [(3, 2, 6, 5)]:
        L = rng.normal(0.5, 1.5, size=(T, 1 + M))
        L[:, 0] = np.log1p(-0.8)
        L[0, 2] = NINF
        rows = np.sort(rng.choice(T_pad, T, replace=False))
        cols = np.sort(rng.choice(M_pad, M, replace=False))
        big, valid = _embed(L, rows, cols, T_pad, M_pad, rng)
        ref = _numpy(_jit(method)(jnp.asarray(L)))
        got = _numpy(_jit(method)(jnp.asarray(big), jnp.asarray(valid)))
        assert got.ok and ref.ok
        np.testing.assert_allclose(
            got.association_probabilities[np.ix_(rows, [0] + [c + 1 for c in cols])],
            ref.association_probabilities, rtol=0, atol=1e-13,
        )
        assert (got.association_probabilities[~valid] == 0).all()
        pad_cols = np.setdiff1d(np.arange(M_pad), cols)
        assert (got.association_probabilities[:, pad_cols + 1] == 0).all()
        np.testing.assert_allclose(got.clutter_probabilities[cols], ref.clutter_probabilities, atol=1e-13)
        np.testing.assert_allclose(got.clutter_probabilities[pad_cols], 1.0, atol=0)
        np.testing.assert_allclose(got.log_normalizer, ref.log_normalizer, rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------------------------
# Stone Soup's JPDA and pyehm.


def _stonesoup_scenario(
    seed, num_tracks, num_dets, *, prob_detect, prob_gate, clutter, include_all, spread=2.0
):
    """Tracks, detections and a PDAHypothesiser; and ``L`` computed here from the same numbers."""
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    rng = np.random.default_rng(seed)
    t0 = datetime(2024, 1, 1)
    t1 = t0 + timedelta(seconds=1)
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.5), ConstantVelocity(0.5)])
    measurement = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag([1.0, 2.0]))
    # Stone Soup's order [x, vx, y, vy]; tracks a few metres apart so that gates overlap.
    means = [np.array([3.0 * i, 1.0, 1.5 * (i % 2), -0.5]) for i in range(num_tracks)]
    covs = [np.diag(rng.uniform(0.5, 2.0, 4)) for _ in range(num_tracks)]
    tracks = [Track([GaussianState(m[:, None], P, timestamp=t0)]) for m, P in zip(means, covs)]
    F = transition.matrix(time_interval=t1 - t0)
    Q = transition.covar(time_interval=t1 - t0)
    H, R = measurement.matrix(), measurement.covar()
    centres = [H @ F @ m for m in means]
    zs = [centres[i % num_tracks] + rng.normal(0.0, spread, 2) for i in range(num_dets)]
    detections = [Detection(z[:, None], timestamp=t1, measurement_model=measurement) for z in zs]
    hypothesiser = PDAHypothesiser(
        KalmanPredictor(transition), KalmanUpdater(measurement), clutter_spatial_density=clutter,
        prob_detect=prob_detect, prob_gate=prob_gate, include_all=include_all,
    )
    # L from the same model, independently of Stone Soup's arithmetic.
    L = np.full((num_tracks, 1 + num_dets), NINF)
    L[:, 0] = np.log(1.0 - prob_detect * prob_gate)
    threshold = chi2.ppf(prob_gate, 2)
    for t, (m, P) in enumerate(zip(means, covs)):
        x, Pp = F @ m, F @ P @ F.T + Q
        S = H @ Pp @ H.T + R
        for j, z in enumerate(zs):
            nu = z - H @ x
            d2 = nu @ np.linalg.solve(S, nu)
            loglik = -0.5 * (d2 + np.log(np.linalg.det(2 * np.pi * S)))
            if include_all or d2 <= threshold:
                L[t, 1 + j] = np.log(prob_detect) + loglik - np.log(clutter)
    return tracks, detections, hypothesiser, t1, L


def _stonesoup_matrix(assignment, tracks, detections):
    """Stone Soup's ``{track: MultipleHypothesis}`` as a ``(T, 1 + M)`` matrix (by identity)."""
    out = np.zeros((len(tracks), 1 + len(detections)))
    for t, track in enumerate(tracks):
        for hyp in assignment[track]:
            if not hyp:
                out[t, 0] = float(hyp.probability)
            else:
                j = next(j for j, d in enumerate(detections) if d is hyp.measurement)
                out[t, 1 + j] = float(hyp.probability)
    return out


STONESOUP_SCENARIOS = [
    dict(seed=1, num_tracks=3, num_dets=5, prob_detect=0.9, prob_gate=0.99, clutter=1e-3, include_all=False),
    dict(seed=2, num_tracks=4, num_dets=6, prob_detect=0.8, prob_gate=0.95, clutter=1e-2, include_all=False),
    dict(seed=3, num_tracks=4, num_dets=3, prob_detect=0.95, prob_gate=0.999, clutter=5e-3, include_all=True),
    dict(seed=4, num_tracks=2, num_dets=6, prob_detect=0.7, prob_gate=0.9, clutter=2e-2, include_all=True),
]


@pytest.mark.parametrize("scenario", STONESOUP_SCENARIOS, ids=lambda s: f"seed{s['seed']}")
def test_jpda_equals_stonesoup(scenario):
    """Our JPDA on our ``L`` equals Stone Soup's JPDA with PDAHypothesiser on the same scene."""
    from stonesoup.dataassociator.probability import JPDA as SSJPDA

    tracks, detections, hypothesiser, t1, L = _stonesoup_scenario(**scenario)
    expect = _stonesoup_matrix(SSJPDA(hypothesiser).associate(set(tracks), detections, t1), tracks, detections)
    T, M = L.shape[0], L.shape[1] - 1
    # Padded to 4 tracks × 6 measurements (one compilation for every scenario; padding changes
    # nothing, test_padding_invariance).
    padded = np.full((4, 7), NINF)
    padded[:T, : M + 1] = L
    got = _numpy(_jit(JPDA())(jnp.asarray(padded), jnp.arange(4) < T))
    assert got.ok
    # The scenario is not trivial: some measurement is contested by two tracks.
    assert (np.isfinite(L[:, 1:]).sum(axis=0) >= 2).any()
    np.testing.assert_allclose(got.association_probabilities[:T, : M + 1], expect, rtol=0, atol=1e-10)


def test_jpda_equals_pyehm_nine_tracks():
    """Exact marginals on 9 tracks × 10 measurements (sparse gates) equal pyehm's EHM and EHM2."""
    from pyehm.core import EHM, EHM2

    rng = np.random.default_rng(9)
    T, M = 9, 10
    L = rng.normal(1.0, 1.5, size=(T, 1 + M))
    L[:, 0] = np.log1p(-rng.uniform(0.5, 0.95, T))
    L[:, 1:][rng.random((T, M)) > 0.3] = NINF
    validation = np.isfinite(L).astype(int)
    likelihood = np.where(np.isfinite(L), np.exp(L), 0.0)
    got = _numpy(_jit(JPDA())(jnp.asarray(L)))
    assert got.ok
    for ehm in (EHM(), EHM2()):
        expect = ehm.run(validation, likelihood)
        np.testing.assert_allclose(got.association_probabilities, expect, rtol=0, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# The sparse path (``_jpda_sparse``): private measurements folded in, a subset DP per cluster.


def _cluster_sizes(L):
    """The largest cluster (tracks linked by a measurement both gate) of ``L``, by union-find."""
    T = L.shape[0]
    parent = list(range(T))

    def find(a):
        while parent[a] != a:
            a = parent[a]
        return a

    gated = L[:, 1:] > NINF
    for j in np.nonzero(gated.sum(axis=0) >= 2)[0]:
        rows = np.nonzero(gated[:, j])[0]
        for r in rows[1:]:
            parent[find(r)] = find(rows[0])
    roots = [find(t) for t in range(T) if gated[t, gated.sum(axis=0) >= 2].any()]
    return max(np.bincount(roots)) if roots else 0


@functools.cache
def _sparse(bits):
    from jaxtrack.association._jpda_sparse import sparse_marginals

    return jax.jit(jax.vmap(lambda L: sparse_marginals(L, bits)))


@pytest.mark.parametrize("T, M, bits", [(8, 16, 3), (8, 16, 8)], ids=["clusters", "one-row"])
def test_sparse_path_equals_the_subset_dp(T, M, bits):
    """The sparse path equals the log-space subset DP to 1e-12 wherever it answers, with padded
    and garbage tracks, padded (all −inf) columns and gated-out rows; it declines (``fallback``)
    exactly when a cluster has more than ``bits`` tracks, never truncating one."""
    from jaxtrack.association._jpda import _prepare, _subset_exact

    rng = np.random.default_rng(40 + T + bits)
    L, valid = _random_problems(rng, BATCH, T, M, gate_prob=2.5 / M)
    L = np.stack([np.asarray(_prepare(jnp.asarray(x), jnp.asarray(v))[0]) for x, v in zip(L, valid)])
    beta, log_Z, fallback = (np.asarray(a) for a in _sparse(bits)(jnp.asarray(L)))
    beta_dp, log_Z_dp = (np.asarray(a) for a in jax.jit(jax.vmap(_subset_exact))(jnp.asarray(L)))
    sizes = np.array([_cluster_sizes(x) for x in L])
    np.testing.assert_array_equal(fallback, sizes > bits)
    answered = ~fallback
    assert answered.mean() > 0.5 and (sizes[answered] >= 2).any()  # real clusters, mostly answered
    np.testing.assert_allclose(beta[answered], beta_dp[answered], rtol=0, atol=1e-12)
    np.testing.assert_allclose(log_Z[answered], log_Z_dp[answered], rtol=0, atol=1e-12)
    # A measurement outside every gate is clutter; a padded track is certainly missed.
    assert (beta[:, :, 1:][np.broadcast_to(~np.isfinite(L[:, :, 1:]), beta[:, :, 1:].shape)] == 0).all()


def test_sparse_path_declines_what_it_cannot_answer():
    """``fallback`` for a cluster over ``bits``, more shared measurements than ``HISTORY``, a
    normaliser out of linear range (missed weights of 0, detections of weight e^-450), NaN and
    +inf; JPDA() then answers as the log-space DP does, and the other scans of the vmapped
    batch keep their (equal) sparse answers."""
    from jaxtrack.association._jpda import _subset_exact
    from jaxtrack.association._jpda_sparse import HISTORY

    M = HISTORY + 8
    cases = np.full((7, 5, 1 + M), NINF)
    cases[:, :, 0] = -1.0
    cases[0, :, 1] = 0.5  # 5 tracks sharing measurement 1: a cluster of 5 > bits = 4
    cases[1, :2, 1:] = 0.1  # 2 tracks sharing all M > HISTORY measurements
    cases[2, :2, 0], cases[2, :2, 1:3] = NINF, -450.0  # must-detect tracks, events of e^-900
    cases[3, 0, 1], cases[3, 1, 1] = np.nan, 1.0
    cases[4, 0, 1], cases[4, 1, 1] = np.inf, 1.0
    for i in (5, 6):  # ordinary sparse scans
        cases[i, 0, 1:3], cases[i, 1, 2:4], cases[i, 3, 5] = [1.0, 0.0], [0.5, -1.0], 2.0
    cases[6, 2, 3] = 0.3
    _, _, fallback = _sparse(4)(jnp.asarray(cases))
    assert np.asarray(fallback).tolist() == [True] * 5 + [False] * 2
    got = _numpy(jax.jit(jax.vmap(JPDA()))(jnp.asarray(cases)))
    beta_dp, log_Z_dp = (np.asarray(a) for a in jax.jit(jax.vmap(_subset_exact))(jnp.asarray(cases)))
    answered = [0, 1, 2, 5, 6]
    assert got.ok[answered].all()
    # NaN and +inf in a valid row are flagged (tests/test_silent_answers.py), not answered.
    assert not got.ok[[3, 4]].any()
    np.testing.assert_allclose(got.association_probabilities[answered], beta_dp[answered], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.log_normalizer[answered], log_Z_dp[answered], rtol=0, atol=1e-12)
    assert np.isclose(got.log_normalizer[2], -900.0 + np.log(2.0) - 3.0, rtol=0, atol=1e-12)  # 3 tracks missed


def test_batch_helpers():
    """``batch_any``/``batch_max``: the value itself, and under (nested) vmap the unbatched
    reduction over the whole batch."""
    from jaxtrack.association._jpda_sparse import batch_any, batch_max

    x = jnp.asarray([[1, 5, 2], [0, 3, 4]])
    assert int(batch_max(x[0, 1])) == 5 and bool(batch_any(x[1, 0] > 0)) is False
    out = jax.vmap(jax.vmap(lambda v: jnp.stack([batch_max(v), batch_any(v > 4).astype(v.dtype), v])))(x)
    np.testing.assert_array_equal(out[..., 0], 5)
    np.testing.assert_array_equal(out[..., 1], 1)
    np.testing.assert_array_equal(out[..., 2], x)


def test_jpda_equals_pyehm_on_tracker_scans():
    """Realistic sparse scans (8 tracks in a 60 x 60 region, detections with P_D 0.9 and
    uniform clutter up to 40 measurements, χ² gates at P_G 0.99), solved by clusters: JPDA()
    equals pyehm's EHM2 on every scan."""
    from pyehm.core import EHM2

    rng = np.random.default_rng(12)
    T, M, side, p_d = 8, 40, 60.0, 0.9
    scans = []
    for _ in range(BATCH):
        centres = rng.uniform(0.0, side, (T, 2))
        S = np.diag(rng.uniform(2.0, 8.0, 2))
        z = [c + rng.normal(0.0, np.sqrt(np.diag(S))) for c in centres if rng.random() < p_d]
        z = np.array(z + list(rng.uniform(0.0, side, (M - len(z), 2))))[rng.permutation(M)]
        d2 = (((z[None, :, :] - centres[:, None, :]) ** 2) / np.diag(S)).sum(axis=2)
        L = np.where(d2 <= chi2.ppf(0.99, 2), np.log(p_d) - 0.5 * d2 - np.log(2 * np.pi * np.sqrt(np.prod(np.diag(S))))
                     - np.log((M - T * p_d) / side**2), NINF)
        scans.append(np.concatenate([np.full((T, 1), np.log1p(-p_d * 0.99)), L], axis=1))
    scans = np.stack(scans)
    got = _numpy(_jpda(jnp.asarray(scans), jnp.ones((BATCH, T), bool)))
    assert got.ok.all()
    shared = (np.isfinite(scans[:, :, 1:]).sum(axis=1) >= 2).sum(axis=1)
    assert shared.max() >= 3 and max(_cluster_sizes(x) for x in scans) >= 3  # contested scans
    ehm = EHM2()
    for i in range(BATCH):
        expect = ehm.run(np.isfinite(scans[i]).astype(np.int32), np.where(np.isfinite(scans[i]), np.exp(scans[i]), 0.0))
        np.testing.assert_allclose(got.association_probabilities[i], expect, rtol=0, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# PDA.


def test_pda_is_the_row_softmax():
    rng = np.random.default_rng(5)
    L, valid = _random_problems(rng, 20, 3, 4)
    got = _numpy(_pda(jnp.asarray(L), jnp.asarray(valid)))
    assert got.ok.all()
    Lv = np.where(valid[:, :, None], L, NINF)
    with np.errstate(invalid="ignore"):  # padded rows: −inf − (−inf)
        expect = np.exp(Lv - np.logaddexp.reduce(Lv, axis=2, keepdims=True))
    expect = np.where(valid[:, :, None], expect, 0.0)
    np.testing.assert_allclose(got.association_probabilities, expect, rtol=0, atol=1e-14)
    np.testing.assert_allclose(got.clutter_probabilities, 1 - expect[:, :, 1:].sum(axis=1), rtol=0, atol=1e-14)
    rows = np.where(valid, np.logaddexp.reduce(Lv, axis=2), 0.0)
    np.testing.assert_allclose(got.log_normalizer, rows.sum(axis=1), rtol=1e-14)


# ---------------------------------------------------------------------------------------------
# Loopy BP.


def _random_forest_problems(rng, n, T, M):
    """``L`` whose gating graph (tracks, measurements, gated pairs) is a forest: every node
    joins at most one earlier node of the other kind, so no cycle can form."""
    L = np.full((n, T, 1 + M), NINF)
    L[:, :, 0] = np.log1p(-rng.uniform(0.3, 0.98, size=(n, T)))
    for i in range(n):
        nodes = [("t", t) for t in range(T)] + [("z", j) for j in range(M)]
        order = rng.permutation(len(nodes))
        seen = []
        for k in order:
            kind, idx = nodes[k]
            partners = [p for p in seen if p[0] != kind]
            if partners and rng.random() < 0.85:
                other = partners[rng.integers(len(partners))]
                t, j = (idx, other[1]) if kind == "t" else (other[1], idx)
                L[i, t, 1 + j] = rng.normal(1.0, 2.0)
            seen.append((kind, idx))
    return L


def test_loopy_bp_exact_on_trees():
    """On forests (chains t₁–z₁–t₂–z₂…, stars, disjoint tracks) BP and its Bethe log Z are exact."""
    rng = np.random.default_rng(11)
    for T, M in [(4, 6), (4, 3)]:
        L = _random_forest_problems(rng, BATCH, T, M)
        exact = _numpy(_jpda(jnp.asarray(L), jnp.ones((BATCH, T), bool)))
        got = _numpy(_bp(jnp.asarray(L), jnp.ones((BATCH, T), bool)))
        assert got.ok.all()
        shared = (np.isfinite(L[:, :, 1:]).sum(axis=1) >= 2).any(axis=1)
        assert shared.mean() > 0.5  # most cases have contested measurements
        np.testing.assert_allclose(got.association_probabilities, exact.association_probabilities, rtol=0, atol=1e-10)
        np.testing.assert_allclose(got.clutter_probabilities, exact.clutter_probabilities, rtol=0, atol=1e-10)
        np.testing.assert_allclose(got.log_normalizer, exact.log_normalizer, rtol=0, atol=1e-10)
        assert got.residual.max() < 1e-12


# Measured on these 200 cases (4 tracks, 6 measurements, 70 % of pairs gated in, L ~ N(1, 2)):
# max |β_BP − β| = 0.1046, median over cases 0.0231; max |log Z_Bethe − log Z| = 0.233;
# the residual after 50 iterations ≤ 3e-13 (converged: the error is the approximation's).
LOOPY_BETA_MAX, LOOPY_BETA_MEDIAN, LOOPY_LOGZ_MAX = 0.15, 0.035, 0.35


def test_loopy_bp_error_on_graphs_with_cycles():
    rng = np.random.default_rng(7)
    L, _ = _random_problems(rng, 4 * BATCH, 4, 6, gate_prob=0.7, pad=False)
    valid = jnp.ones((BATCH, 4), bool)
    chunks = [jnp.asarray(c) for c in np.split(L, 4)]
    exact = jax.tree.map(lambda *a: np.concatenate(a), *[_numpy(_jpda(c, valid)) for c in chunks])
    got = jax.tree.map(lambda *a: np.concatenate(a), *[_numpy(_bp(c, valid)) for c in chunks])
    assert got.ok.all()
    err = np.abs(got.association_probabilities - exact.association_probabilities).max(axis=(1, 2))
    assert err.max() <= LOOPY_BETA_MAX, err.max()
    assert np.median(err) <= LOOPY_BETA_MEDIAN, np.median(err)
    assert np.abs(got.log_normalizer - exact.log_normalizer).max() <= LOOPY_LOGZ_MAX
    assert got.residual.max() < 1e-10
    np.testing.assert_allclose(got.association_probabilities.sum(axis=2), 1.0, atol=1e-13)


# ---------------------------------------------------------------------------------------------
# Gradients against central differences.


def _central_differences(f, x, h):
    """``(f(x + h e_i) − f(x − h e_i)) / 2h`` for every entry, evaluated as one vmapped batch."""
    eye = np.eye(x.size).reshape((x.size,) + x.shape) * h
    plus = jax.vmap(f)(jnp.asarray(x[None] + eye))
    minus = jax.vmap(f)(jnp.asarray(x[None] - eye))
    return np.asarray((plus - minus) / (2 * h)).reshape(x.shape)


def _scalar(method, weights):
    def f(L):
        a = method(L)
        return jnp.sum(a.association_probabilities * weights) + 0.3 * a.log_normalizer

    return f


@pytest.mark.parametrize("method", [JPDA(), LoopyBP(num_iters=BP_ITERS)], ids=["JPDA", "LoopyBP"])
def test_gradients_match_central_differences(method):
    """d/dL and d/d(P_D, λ) of Σ β·w + 0.3 log Z equal central differences (relative 1e-6).

    One function of ``(A, p)``: ``L = A + [log(1 − P_D P_G), log(P_D/λ), …]`` on the gated
    entries (``A`` holds the Gaussian log-densities, 0 in column 0), ``−inf`` elsewhere; so
    ``∂/∂A`` is the gradient with respect to ``L`` and ``∂/∂p`` the one through the physical
    parameters. BP's is that of ``num_iters`` iterations, which differences see too.
    """
    rng = np.random.default_rng(21)
    T, M = 3, 4
    gated = np.ones((T, 1 + M), bool)
    gated[0, 3] = gated[2, 1] = False
    A = np.where(gated, rng.normal(-3.0, 1.5, size=(T, 1 + M)), 0.0)
    A[:, 0] = 0.0
    w = jnp.asarray(rng.normal(size=(T, 1 + M)))
    prob_gate = 0.99

    @jax.jit
    def f(A, p):
        prob_detect, clutter = p[0], p[1]
        physical = jnp.concatenate(
            [
                jnp.full((T, 1), jnp.log1p(-prob_detect * prob_gate)),
                jnp.full((T, M), jnp.log(prob_detect) - jnp.log(clutter)),
            ],
            axis=1,
        )
        a = method(jnp.where(jnp.asarray(gated), A + physical, -jnp.inf))
        return jnp.sum(a.association_probabilities * w) + 0.3 * a.log_normalizer

    p = np.array([0.8, 2e-3])
    g_A, g_p = (np.asarray(g) for g in jax.jit(jax.grad(f, argnums=(0, 1)))(jnp.asarray(A), jnp.asarray(p)))
    assert np.isfinite(g_A).all() and (g_A[~gated] == 0).all()
    h = 1e-5
    fd_A = np.zeros_like(A)
    for idx in zip(*np.nonzero(gated)):
        e = np.zeros_like(A)
        e[idx] = h
        fd_A[idx] = (f(jnp.asarray(A + e), jnp.asarray(p)) - f(jnp.asarray(A - e), jnp.asarray(p))) / (2 * h)
    err_A = np.abs(g_A - fd_A).max() / np.abs(g_A).max()
    assert err_A <= 1e-6, err_A
    fd_p = np.array([
        (f(jnp.asarray(A), jnp.asarray(p + d)) - f(jnp.asarray(A), jnp.asarray(p - d))) / (2 * d[i])
        for i, d in enumerate(np.diag(p * 1e-6))
    ])
    np.testing.assert_allclose(g_p, fd_p, rtol=1e-6)


# ---------------------------------------------------------------------------------------------
# The PDA update.


def _linear_model():
    dt = 1.0
    F = np.kron(np.array([[1.0, dt], [0.0, 1.0]]), np.eye(2))  # [x, y, vx, vy]
    Q = 0.3 * np.kron(np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), np.eye(2))
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    R = np.array([[1.0, 0.2], [0.2, 1.5]])
    return LinearGaussianModel(F, Q, H, R, np.zeros(4), 4.0 * np.eye(4))


def _range_bearing(x, k):
    return jnp.stack([jnp.hypot(x[0], x[1]), jnp.arctan2(x[1], x[0])])


def _constant_velocity(x, k):
    return jnp.concatenate([x[:2] + x[2:], x[2:]])


def _nonlinear_model():
    Q = 0.1 * np.eye(4)
    R = np.diag([0.5**2, 0.01**2])
    return NonlinearGaussianModel(_constant_velocity, _range_bearing, Q, R, np.zeros(4), np.eye(4))


@functools.partial(jax.jit, static_argnums=0)
def _conditioned(filt, model, x, P, zs):
    k = jnp.zeros((), jnp.int32)
    obs = jnp.ones(zs.shape[1], bool)
    return jax.vmap(lambda z: filt.update(model, x, P, z, obs, k))(jnp.asarray(zs))


def _with_garbage(cond, rows):
    """``cond`` with NaN/huge values in the moments of ``rows`` (padding)."""
    def spoil(a):
        a = np.array(a)
        a[rows] = np.where(np.arange(a[rows].size).reshape(a[rows].shape) % 2, np.nan, 1e200)
        return jnp.asarray(a)

    return jax.tree.map(spoil, cond)


@pytest.mark.parametrize("which", ["kalman", "ekf"])
def test_pda_update_forms_agree_and_ignore_padding(which):
    """Mixture and innovation forms agree to 1e-12 (common gain); padded entries never leak."""
    rng = np.random.default_rng(31)
    if which == "kalman":
        model, filt = _linear_model(), KalmanFilter()
        x, P = jnp.asarray([1.0, -2.0, 0.5, 0.3]), jnp.asarray(np.diag([4.0, 3.0, 1.0, 1.0]))
        zs = np.asarray(x[:2]) + rng.normal(0, 2.0, (6, 2))
    else:
        model, filt = _nonlinear_model(), ExtendedKalmanFilter()
        x, P = jnp.asarray([30.0, 40.0, 1.0, -1.0]), jnp.asarray(np.diag([4.0, 4.0, 1.0, 1.0]))
        zs = np.asarray(_range_bearing(x, 0)) + rng.normal(0, 1.0, (6, 2)) * np.array([0.7, 0.02])
    cond = _conditioned(filt, model, x, P, zs)
    beta = np.array([0.15, 0.3, 0.0, 0.25, 0.2, 0.0, 0.1])  # measurements 1 and 4 padded
    cond_bad = _with_garbage(cond, [1, 4])
    for c in (cond, cond_bad):
        mix = _pda_update(c, jnp.asarray(beta), x, P)
        inn = _pda_update(c, jnp.asarray(beta), x, P, form="innovation")
        assert all(np.isfinite(np.asarray(a)).all() for a in mix + inn)
        for a, b in zip(mix, inn):
            assert np.abs(np.asarray(a - b)).max() <= 1e-12 * np.abs(np.asarray(a)).max()
    # Dropping the padded measurements altogether gives the same answer.
    keep = [0, 2, 3, 5]
    small = jax.tree.map(lambda a: a[np.array(keep)], cond)
    ref = _pda_update(small, jnp.asarray(beta[[0] + [k + 1 for k in keep]]), x, P)
    for a, b in zip(_pda_update(cond_bad, jnp.asarray(beta), x, P), ref):
        np.testing.assert_allclose(a, b, rtol=1e-14, atol=1e-14)
    # A padded track (β all zero) keeps its prediction.
    kept = _pda_update(cond_bad, jnp.zeros(7), x, P)
    np.testing.assert_array_equal(kept[0], x)
    np.testing.assert_array_equal(kept[1], P)


def test_pda_update_single_measurement_is_the_kalman_update():
    model, filt = _linear_model(), KalmanFilter()
    x, P = jnp.asarray([1.0, -2.0, 0.5, 0.3]), jnp.asarray(np.diag([4.0, 3.0, 1.0, 1.0]))
    cond = _conditioned(filt, model, x, P, np.array([[2.0, -1.0]]))
    for form in ("mixture", "innovation"):
        mean, cov = _pda_update(cond, jnp.asarray([0.0, 1.0]), x, P, form=form)
        np.testing.assert_allclose(mean, cond.mean[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(cov, cond.cov[0], rtol=0, atol=1e-12)


def test_pda_update_equals_stonesoup_pda_updater():
    """Stone Soup's PDA (association) and PDAUpdater (both of its forms) on one track, five
    detections; our PDA on our L and pda_update on the Kalman filter's updates."""
    from stonesoup.dataassociator.probability import PDA as SSPDA
    from stonesoup.updater.probability import PDAUpdater

    tracks, detections, hypothesiser, t1, L = _stonesoup_scenario(
        5, 1, 5, prob_detect=0.9, prob_gate=0.99, clutter=2e-2, include_all=False, spread=4.0
    )
    track = tracks[0]
    hyps = SSPDA(hypothesiser).associate({track}, detections, t1)[track]
    beta_ss = _stonesoup_matrix({track: hyps}, tracks, detections)[0]
    beta = np.asarray(_jit(PDA())(jnp.asarray(L)).association_probabilities[0])
    np.testing.assert_allclose(beta, beta_ss, rtol=0, atol=1e-12)
    assert (beta[1:] > 0).sum() >= 2 and (beta[1:] == 0).any()  # some inside, some outside the gate

    transition = hypothesiser.predictor.transition_model
    measurement = detections[0].measurement_model
    F = transition.matrix(time_interval=timedelta(seconds=1))
    Q = transition.covar(time_interval=timedelta(seconds=1))
    model = LinearGaussianModel(F, Q, measurement.matrix(), measurement.covar(), np.zeros(4), np.eye(4))
    filt = KalmanFilter()
    prior = track.state
    k = jnp.ones((), jnp.int32)
    x, P = filt.predict(model, jnp.asarray(prior.state_vector[:, 0]), jnp.asarray(prior.covar), k)
    zs = np.stack([np.asarray(d.state_vector[:, 0], float) for d in detections])
    cond = _conditioned(filt, model, x, P, zs)
    for gm_method, form in [(True, "mixture"), (False, "innovation"), (False, "mixture")]:
        post = PDAUpdater(measurement).update(hyps, gm_method=gm_method)
        mean, cov = _pda_update(cond, jnp.asarray(beta), x, P, form=form)
        np.testing.assert_allclose(mean, np.asarray(post.state_vector[:, 0], float), rtol=0, atol=1e-10)
        np.testing.assert_allclose(cov, np.asarray(post.covar, float), rtol=0, atol=1e-10)

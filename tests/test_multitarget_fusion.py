"""The two-sensor track-fusion tracker (jaxtrack.multitarget.TrackFusionTracker) and the track-to-track
association under it (jaxtrack.association.track_to_track_assignment).

Oracles: SciPy's ``linear_sum_assignment`` on the gated d² matrix (brute force), the fusion rules
of :mod:`jaxtrack.fusion` applied by hand to the local tracks, χ² bounds on the Monte Carlo NEES,
central finite differences for the derivative in the CI weight.

Cost: every test shares one tracker layout (2 local JPDA trackers of 4 slots, 3 target slots, 8
measurement slots, 10 scans), so that the Monte Carlo program (:func:`_batch`, 1,000 vmapped runs
of simulate + fused run + scoring) compiles once for the consistency, GOSPA and fusion-equality
tests; scenarios differ only in array leaves (initial states, clutter rate, a target never born).
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
import scipy.stats

from jaxtrack import InputError, fusion
from jaxtrack.association import JPDA, track_to_track_assignment
from jaxtrack.filters import KalmanFilter
from jaxtrack.models import LinearGaussianModel
from jaxtrack.multitarget import (
    CapacityWarning,
    OnePointInitiator,
    Scenario,
    Tracker,
    TrackFusionTracker,
    TrackManagement,
    TwoSensorScenario,
    multitarget_monte_carlo,
    run_multitarget,
    score_tracks,
    simulate_scenario,
    simulate_two_sensors,
)
from jaxtrack.multitarget._base import scan_method

NUM_RUNS, NUM_SCANS = 1000, 10
N_STATE = 4
LAYOUT = ("x", "y", "vx", "vy")
# Nearly-constant velocity in the plane, 1 s scans, q = 1 m²/s³; two position sensors, one precise
# in x and coarse in y, the other the other way round (neither local covariance bounds the other:
# the optimal CI weight lies inside (0, 1)).
_F = np.kron(np.array([[1.0, 1.0], [0.0, 1.0]]), np.eye(2))
_Q = np.kron(np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]]), np.eye(2))
_H = np.hstack([np.eye(2), np.zeros((2, 2))])
_R1, _R2 = np.diag([1.0, 16.0]), np.diag([16.0, 1.0])
_PRIOR = (np.zeros(4), np.diag([100.0, 100.0, 25.0, 25.0]))
SENSOR1 = LinearGaussianModel(_F, _Q, _H, _R1, *_PRIOR, state_layout=LAYOUT)
SENSOR2 = LinearGaussianModel(_F, _Q, _H, _R2, *_PRIOR, state_layout=LAYOUT)
REGION = [[-1000.0, 1000.0], [-1000.0, 1000.0]]
CUTOFF = 20.0
SEPARATED = np.array([[0.0, 0.0, 5.0, 0.0], [500.0, 500.0, 0.0, -5.0], [-500.0, 300.0, 3.0, 3.0]])
# Three targets crossing near the origin at scan 5, 2-4 m apart there.
CROSSING = np.array([[-25.0, -10.0, 5.0, 2.0], [27.0, -10.0, -5.0, 2.0], [0.0, -22.0, 0.0, 4.0]])


def scenarios(initial_states, *, clutter_rate=0.0, death=(NUM_SCANS,) * 3, birth=(0, 0, 0)):
    """The two sensors' Scenarios of the same 3 target slots (P_D 1; clutter uniform over 2 km²)."""
    def one(model):
        return Scenario(model, initial_states, list(birth), list(death), detection_probability=1.0,
                        clutter_rate=clutter_rate, clutter_region=REGION, max_measurements=8, num_steps=NUM_SCANS)
    return one(SENSOR1), one(SENSOR2)


def local_tracker(model, capacity=4):
    # A new track is confirmed at once (1-of-1), so that every target is tracked by both sensors
    # from scan 0; the one-point initiator's velocity prior (5 m/s per axis) covers the targets'.
    initiator = OnePointInitiator(np.zeros(4), np.diag([1e6, 1e6, 25.0, 25.0]))
    return Tracker(KalmanFilter(), model, JPDA(), initiator, prob_detect=0.99, clutter_density=1e-6,
                   prob_gate=0.9999, capacity=capacity, management=TrackManagement(1, 1, 3))


LOCAL1, LOCAL2 = local_tracker(SENSOR1), local_tracker(SENSOR2)
TRACKER = TrackFusionTracker(LOCAL1, LOCAL2)  # CI, trace-optimal weight; capacity 4 + 4


def _record(method, state, info):
    return (method.estimates(state), method.local1.estimates(state.local1), method.local2.estimates(state.local2),
            info.ok)


def _gospa(traj, est):
    g, _ = score_tracks(traj.states[..., :2], traj.alive, est.states[..., :2], est.mask, est.ids, cutoff=CUTOFF)
    return jnp.mean(g.distance)


def _nearest_nees(truth, alive, means, covs, mask):
    """Each alive target's NEES against the nearest reported track (NaN when none is within 30 m)."""
    d = jnp.linalg.norm(truth[:, None, :2] - means[None, :, :2], axis=-1)
    d = jnp.where(mask[None, :], d, jnp.inf)
    j = jnp.argmin(d, axis=1)
    e = truth - means[j]
    nees = jnp.einsum("ti,ti->t", e, jnp.linalg.solve(covs[j], e[..., None])[..., 0])
    return jnp.where(alive & (jnp.min(d, axis=1) < 30.0), nees, jnp.nan)


# Runs per compiled call (one compilation per block size). 800 or more runs in one vmap stopped
# XLA:CPU with every thread idle (no result after 10 min, while 700 ran in 3 s) until the CI weight's
# criterion stopped calling LAPACK (jaxtrack/fusion/_rules.py): the module fixture's one block of
# 1,000 runs is that regression test (with the former criterion it hangs); the other tests run
# blocks of 250.
BLOCK = 250


def _batch(tracker, scenario, key, num_runs=NUM_RUNS, block=BLOCK):
    """NUM_RUNS runs (run i from fold_in(key, i)): the fused tracker's final state, the final-scan NEES
    of CI (the tracker's) and of naive independent fusion of the same local pairs, the mean GOSPA of
    the fused and of each local tracker, and every scan's ok; in blocks of ``block`` runs."""
    blocks = [_block(tracker, scenario, key, jnp.asarray(start), block) for start in range(0, num_runs, block)]
    return jax.tree.map(lambda *a: np.concatenate([np.asarray(x) for x in a]), *blocks)


@eqx.filter_jit
def _block(tracker, scenario, key, start, size):

    def one(i):
        traj = scenario.sample(jax.random.fold_in(key, i))
        final, (fused, est1, est2, ok) = scan_method(tracker, traj.scans.measurements, traj.scans.valid, _record)
        f, t1, t2 = final.fused, final.local1, final.local2
        nees_ci = _nearest_nees(traj.states[-1], traj.alive[-1], f.mean, f.cov, f.live)
        # Naive fusion of the same local tracks, paired as the tracker pairs them.
        pair = track_to_track_assignment(t1.mean, t1.cov, t1.confirmed, t2.mean, t2.cov, t2.confirmed,
                                         tracker.gate).pair
        partner = jnp.maximum(pair, 0)
        naive = jax.vmap(fusion.independent_fusion)(t1.mean, t1.cov, t2.mean[partner], t2.cov[partner])
        nees_naive = _nearest_nees(traj.states[-1], traj.alive[-1], naive.mean, naive.cov, pair >= 0)
        return final, nees_ci, nees_naive, (_gospa(traj, fused), _gospa(traj, est1), _gospa(traj, est2)), ok

    return jax.vmap(one)(start + jnp.arange(size))


@pytest.fixture(scope="module")
def separated():
    return _batch(TRACKER, TwoSensorScenario(*scenarios(SEPARATED)), jax.random.key(7), block=NUM_RUNS)


# --- (a) track-to-track association against brute force -------------------------------------


_t2t = jax.jit(track_to_track_assignment, static_argnames="gate")


def test_track_to_track_assignment_equals_brute_force_on_the_gated_distance():
    rng = np.random.default_rng(0)
    gate = scipy.stats.chi2.ppf(0.99, N_STATE)
    seen_gated = seen_masked = 0
    for case in range(30):
        N1, N2 = (5, 4) if case % 2 else (3, 6)
        x1, x2 = rng.normal(size=(N1, N_STATE)) * 3, rng.normal(size=(N2, N_STATE)) * 3
        A, B = rng.normal(size=(N1, N_STATE, N_STATE)), rng.normal(size=(N2, N_STATE, N_STATE))
        P1 = A @ A.transpose(0, 2, 1) + np.eye(N_STATE)
        P2 = B @ B.transpose(0, 2, 1) + np.eye(N_STATE)
        m1, m2 = rng.uniform(size=N1) < 0.8, rng.uniform(size=N2) < 0.8
        out = _t2t(x1, P1, m1, x2, P2, m2, gate=gate)
        d2 = np.array([[(x1[i] - x2[j]) @ np.linalg.solve(P1[i] + P2[j], x1[i] - x2[j]) for j in range(N2)]
                       for i in range(N1)])
        allowed = m1[:, None] & m2[None, :] & (d2 <= gate)
        # Brute force: SciPy on the gated matrix (a forbidden pair costs more than all allowed ones
        # together, so the most pairs win first), forbidden pairs then dropped.
        cost = np.where(allowed, d2, 1e6)
        rows, cols = scipy.optimize.linear_sum_assignment(cost)
        expected = np.full(N1, -1)
        for i, j in zip(rows, cols):
            if allowed[i, j]:
                expected[i] = j
        np.testing.assert_array_equal(np.asarray(out.pair), expected, err_msg=f"case {case}")
        np.testing.assert_allclose(np.asarray(out.distance_sq)[m1[:, None] & m2[None, :]],
                                   d2[m1[:, None] & m2[None, :]], rtol=1e-12)
        assert float(out.total_cost) == pytest.approx(float(np.sum(d2[expected >= 0, expected[expected >= 0]])),
                                                      rel=1e-12)
        seen_gated += int(np.sum(m1[:, None] & m2[None, :] & ~allowed) > 0)
        seen_masked += int((~m1).any() or (~m2).any())
    assert seen_gated >= 10 and seen_masked >= 10  # the gate and the masks were exercised


# --- (b) fused estimates are the rule on the local tracks -----------------------------------


def test_fused_tracks_are_ci_of_their_local_pairs(separated):
    """Every fused track made of a local pair equals fusion.covariance_intersection (trace-optimal)
    of the two local tracks (found by the ids the fused table records); unpaired tracks are the
    local track itself."""
    final = jax.tree.map(lambda a: np.asarray(a[:5]), separated[0])
    pairs = 0
    for r in range(5):
        f, t1, t2 = (jax.tree.map(lambda a, r=r: a[r], s) for s in (final.fused, final.local1, final.local2))
        for k in np.flatnonzero(f.live):
            i1 = np.flatnonzero(t1.confirmed & (t1.track_id == f.local_id1[k]))
            i2 = np.flatnonzero(t2.confirmed & (t2.track_id == f.local_id2[k]))
            if i1.size and i2.size:
                ref = fusion.covariance_intersection(t1.mean[i1[0]], t1.cov[i1[0]], t2.mean[i2[0]], t2.cov[i2[0]])
                np.testing.assert_allclose(f.mean[k], ref.mean, rtol=1e-12, atol=1e-12 * np.abs(ref.mean).max())
                np.testing.assert_allclose(f.cov[k], ref.cov, rtol=1e-12, atol=1e-12 * np.abs(ref.cov).max())
                assert float(f.weight[k]) == pytest.approx(float(ref.weight), abs=1e-12)
                pairs += 1
            else:
                t, i = (t1, i1) if i1.size else (t2, i2)
                np.testing.assert_array_equal(f.mean[k], t.mean[i[0]])
    assert pairs >= 14  # 5 runs x 3 targets, (nearly) all paired


ONE_TARGET = TwoSensorScenario(*scenarios(SEPARATED, birth=(0, NUM_SCANS, NUM_SCANS), death=(NUM_SCANS, NUM_SCANS + 1, NUM_SCANS + 1)))


def _one_target_run(omega, scans):
    tracker = TrackFusionTracker(LOCAL1, LOCAL2, fusion.CovarianceIntersection(omega))
    final, (fused, _, _, ok) = scan_method(tracker, scans.measurements, scans.valid, _record)
    return final, fused, ok


@jax.jit
def _loss_and_grad(omega, scans, truth):
    """A scalar of the fused run with a fixed CI weight: the mean squared fused error over the
    scans plus the final fused covariance's trace (m²), and its derivative in ω."""

    def loss(w):
        final, fused, ok = _one_target_run(w, scans)
        err = jnp.sum(jnp.where(fused.mask[..., None], fused.states - truth[:, None, :], 0.0) ** 2)
        trace = jnp.sum(jnp.where(final.fused.live, jnp.trace(final.fused.cov, axis1=1, axis2=2), 0.0))
        return err / NUM_SCANS + trace, (final, fused, ok)

    return jax.value_and_grad(loss, has_aux=True)(omega)


def test_one_target_fusion_is_ci_of_the_local_tracks_and_differentiable_in_the_weight():
    traj = simulate_two_sensors(ONE_TARGET.sensor1, ONE_TARGET.sensor2, 3)
    truth = traj.states[:, 0]
    (_, (final, fused, ok)), grad = _loss_and_grad(0.37, traj.scans, truth)
    assert bool(np.all(ok)) and np.all(np.asarray(fused.mask).sum(axis=1) == 1)
    # Perfect association: one local track each, one fused track all along, the same fused id.
    t1, t2, f = final.local1, final.local2, final.fused
    i1, i2, k = (int(np.flatnonzero(np.asarray(m))[0]) for m in (t1.confirmed, t2.confirmed, f.live))
    assert np.asarray(fused.ids)[fused.mask].tolist() == [0] * NUM_SCANS
    ref = fusion.covariance_intersection(t1.mean[i1], t1.cov[i1], t2.mean[i2], t2.cov[i2], 0.37)
    np.testing.assert_allclose(f.mean[k], ref.mean, rtol=0, atol=1e-12 * float(np.abs(ref.mean).max()))
    np.testing.assert_allclose(f.cov[k], ref.cov, rtol=0, atol=1e-12 * float(np.abs(ref.cov).max()))
    # d loss / dω against central differences (the same compiled program at ω ± h).
    h = 1e-5
    fd = (float(_loss_and_grad(0.37 + h, traj.scans, truth)[0][0])
          - float(_loss_and_grad(0.37 - h, traj.scans, truth)[0][0])) / (2 * h)
    assert abs(float(grad) - fd) <= 1e-6 * abs(fd), (float(grad), fd)
    assert abs(float(grad)) > 1.0  # the weight matters


def test_fused_ids_persist_while_their_local_pairs_persist():
    """Targets born at scans 0, 3 and 6: each gets the next fused id when both sensors first
    report it and keeps it at every later scan (the nearest fused track to each alive target
    carries that id), while the others' ids stay as they were."""
    staggered = TwoSensorScenario(*scenarios(SEPARATED, birth=(0, 3, 6)))
    traj = simulate_two_sensors(staggered.sensor1, staggered.sensor2, 4)
    (_, (_, fused, ok)), _ = _loss_and_grad(0.5, traj.scans, traj.states[:, 0])
    assert bool(np.all(ok))
    states, mask, ids = (np.asarray(a) for a in fused)
    truth, alive = np.asarray(traj.states), np.asarray(traj.alive)
    for k in range(NUM_SCANS):
        assert sorted(ids[k][mask[k]].tolist()) == list(range(int(alive[k].sum()))), (k, ids[k])
        for j in np.flatnonzero(alive[k]):
            d = np.where(mask[k], np.linalg.norm(states[k, :, :2] - truth[k, j, :2], axis=1), np.inf)
            assert ids[k, np.argmin(d)] == j and d.min() < 20.0, (k, j, ids[k])


def test_a_fused_id_survives_the_second_sensor_starting_and_stopping_to_see_its_target():
    """One target; sensor 2's scans are blanked before scan 3 and from scan 7 on. Sensor 1's track
    is reported alone (fused id 0), then paired with sensor 2's new track at scan 3, then alone again
    once sensor 2's track ends: one fused track with id 0 at every scan. (Keyed by the exact local
    pair, the pairing would have issued id 1 at scan 3 and id 2 at the unpairing.)"""
    traj = simulate_two_sensors(ONE_TARGET.sensor1, ONE_TARGET.sensor2, 5)
    k = np.arange(NUM_SCANS)
    sensor2_sees = (k >= 3) & (k < 7)
    valid = np.asarray(traj.scans.valid).copy()
    valid[:, 1] &= sensor2_sees[:, None]
    scans = eqx.tree_at(lambda s: s.valid, traj.scans, jnp.asarray(valid))
    (_, (final, fused, ok)), _ = _loss_and_grad(0.5, scans, traj.states[:, 0])
    assert bool(np.all(ok))
    mask, ids = np.asarray(fused.mask), np.asarray(fused.ids)
    assert mask.sum(axis=1).tolist() == [1] * NUM_SCANS, mask.sum(axis=1)
    assert ids[mask].tolist() == [0] * NUM_SCANS, ids[mask]
    # It was a pair while sensor 2 saw the target, and sensor 1's track alone before.
    assert int(np.asarray(final.fused.next_id)) == 1


# --- (c) consistency with unknown correlation; (d) GOSPA ----------------------------------


def test_ci_fused_nees_is_within_the_chi2_bound_and_naive_fusion_is_not(separated):
    """1,000 runs, 3 separated targets, 10 scans: the local trackers' errors share the targets'
    process noise (and the initiators' common velocity prior), a correlation the fusion centre
    does not know. Each final-scan NEES of a consistent estimate is χ²(4); the mean of the K
    NEES values lies below χ²⁻¹(0.995; 4K)/K with probability 0.995 (one-sided, 99.5%). CI must
    lie below it, naive independent fusion of the same pairs above it (the test discriminates)."""
    _, nees_ci, nees_naive, _, ok = separated
    nees_ci, nees_naive = np.asarray(nees_ci).ravel(), np.asarray(nees_naive).ravel()
    assert bool(np.all(ok))
    assert np.mean(np.isfinite(nees_ci)) >= 0.995 and np.mean(np.isfinite(nees_naive)) >= 0.995
    K = int(np.sum(np.isfinite(nees_ci)))
    upper = scipy.stats.chi2.ppf(0.995, N_STATE * K) / K
    ci, naive = float(np.nanmean(nees_ci)), float(np.nanmean(nees_naive))
    print(f"K={K} upper={upper:.3f} CI={ci:.3f} naive={naive:.3f}")
    assert ci <= upper, (ci, upper)
    assert naive > upper, (naive, upper)


@pytest.mark.slow
def test_ci_nees_bound_holds_over_10000_runs():
    """The consistency test at 10,000 runs (40 blocks of the same compiled program, ~1 min)."""
    _, nees_ci, nees_naive, _, ok = _batch(TRACKER, TwoSensorScenario(*scenarios(SEPARATED)), jax.random.key(9),
                                           num_runs=10_000)
    nees_ci, nees_naive = np.asarray(nees_ci).ravel(), np.asarray(nees_naive).ravel()
    K = int(np.sum(np.isfinite(nees_ci)))
    upper = scipy.stats.chi2.ppf(0.995, N_STATE * K) / K
    assert bool(np.all(ok)) and K >= 29_850
    assert float(np.nanmean(nees_ci)) <= upper < float(np.nanmean(nees_naive))


def test_fused_gospa_is_no_worse_than_the_worse_local_tracker_on_crossing_targets():
    """Three targets crossing near the origin at scan 5 (2-4 m apart there), no clutter: the fused
    tracker's mean GOSPA (c = 20 m, over 1,000 runs and 10 scans) is at most the worse local
    tracker's (measured: fused 2.35 m, local 5.29 and 5.42 m). With clutter see the next test."""
    scen = TwoSensorScenario(*scenarios(CROSSING))
    _, _, _, (fused, local1, local2), ok = _batch(TRACKER, scen, jax.random.key(8))
    assert bool(np.all(ok))
    fused, local1, local2 = (float(np.mean(g)) for g in (fused, local1, local2))
    print(f"mean GOSPA: fused {fused:.3f}, local1 {local1:.3f}, local2 {local2:.3f}")
    assert fused <= max(local1, local2), (fused, local1, local2)


def test_in_clutter_the_fused_pairs_alone_beat_the_local_trackers():
    """The same crossing targets with 2 clutter points a scan per sensor: with these 1-of-1
    confirming local trackers every clutter point becomes a confirmed local track. Reporting
    unpaired tracks (the default) passes both sensors' false tracks through, worse than either
    local tracker (measured over 1,000 runs: fused 19.52 m, local 14.71 and 14.73 m); `unpaired=False`
    reports the pairs only, and the two sensors' clutter rarely pairs (measured: fused 2.34 m)."""
    scen = TwoSensorScenario(*scenarios(CROSSING, clutter_rate=2.0))
    # One block of 250 runs (the margins are wide); `unpaired` is an array leaf, so the second
    # tracker reuses the first's compiled block.
    _, _, _, (with_unpaired, local1, local2), ok = _batch(TRACKER, scen, jax.random.key(8), BLOCK)
    _, _, _, (pairs_only, _, _), ok2 = _batch(TrackFusionTracker(LOCAL1, LOCAL2, unpaired=False), scen,
                                             jax.random.key(8), BLOCK)
    assert bool(np.all(ok)) and bool(np.all(ok2))
    with_unpaired, pairs_only, local1, local2 = (float(np.mean(g)) for g in (with_unpaired, pairs_only, local1, local2))
    print(f"mean GOSPA in clutter: fused {with_unpaired:.3f} (pairs only {pairs_only:.3f}), local {local1:.3f}, "
          f"{local2:.3f}")
    assert with_unpaired > max(local1, local2)
    assert pairs_only <= 0.25 * min(local1, local2)


# --- the one scan and the one Monte Carlo -------------------------------------------------


def test_two_sensor_scans_share_the_truth_and_sensor1_is_simulate_scenario():
    s1, s2 = scenarios(SEPARATED)
    traj = simulate_two_sensors(s1, s2, 5)
    alone = simulate_scenario(s1, 5)
    np.testing.assert_array_equal(np.asarray(traj.sensor1.scans.measurements), np.asarray(alone.scans.measurements))
    np.testing.assert_array_equal(np.asarray(traj.sensor2.states), np.asarray(alone.states))
    z = np.asarray(traj.scans.measurements)
    assert z.shape == (NUM_SCANS, 2, 8, 2)
    # Sensor 2's noise is its own: its detections differ from sensor 1's.
    assert np.all(np.abs(z[:, 0, :3] - z[:, 1, :3]) > 0)


# --- (e) errors, eager and traced; (f) capacity -------------------------------------------


def test_bad_inputs_raise_input_errors_naming_the_argument():
    traj = simulate_two_sensors(*scenarios(SEPARATED), 1)
    z, v = traj.scans.measurements, traj.scans.valid
    with pytest.raises(InputError, match="`measurements` must be \\(T, 2, M, m\\)"):
        run_multitarget(TRACKER, z[:, 0], v[:, 0])  # one sensor's scans
    with pytest.raises(InputError, match="`valid`"):
        run_multitarget(TRACKER, z, v[:, :, :4])
    with pytest.raises(InputError, match="`measurements` hold 1 non-finite"):
        run_multitarget(TRACKER, z.at[2, 1, 0, 0].set(jnp.nan), v)
    with pytest.raises(InputError, match="`measurements`"):
        TRACKER.step(TRACKER.init(), z[0, 0], v[0, 0])
    for bad in (0.0, -1.0, float("nan"), "9"):
        with pytest.raises(InputError, match="`gate`"):
            TrackFusionTracker(LOCAL1, LOCAL2, gate=bad)
        with pytest.raises(InputError, match="`gate`"):
            track_to_track_assignment(np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1)), np.ones(2, bool),
                                      np.zeros((1, 4)), np.eye(4)[None], np.ones(1, bool), bad)
    with pytest.raises(InputError, match="`covs2`"):
        track_to_track_assignment(np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1)), np.ones(2, bool),
                                  np.zeros((1, 4)), np.eye(3)[None], np.ones(1, bool), 9.0)
    model3 = LinearGaussianModel(np.eye(3), np.eye(3), np.eye(2, 3), np.eye(2), np.zeros(3), np.eye(3))
    three = Tracker(KalmanFilter(), model3, JPDA(), OnePointInitiator(np.zeros(3), np.eye(3)), prob_detect=0.9,
                    clutter_density=1e-4, capacity=4)
    with pytest.raises(InputError, match="`local2` tracks 3 states"):
        TrackFusionTracker(LOCAL1, three)
    with pytest.raises(InputError, match="`rule`"):
        TrackFusionTracker(LOCAL1, LOCAL2, fusion.BarShalomCampo())
    with pytest.raises(InputError, match="`capacity`"):
        TrackFusionTracker(LOCAL1, LOCAL2, capacity=0)
    with pytest.raises(InputError, match="`unpaired`"):
        TrackFusionTracker(LOCAL1, LOCAL2, unpaired="no")
    with pytest.raises(InputError, match="`local1`"):
        TrackFusionTracker(TRACKER, LOCAL2)  # a two-sensor method is not a local tracker
    s1, s2 = scenarios(SEPARATED)
    with pytest.raises(InputError, match="`sensor2`'s `initial_states`"):
        TwoSensorScenario(s1, scenarios(CROSSING)[1])
    with pytest.raises(InputError, match="sensor axes"):
        multitarget_monte_carlo(LOCAL1, TwoSensorScenario(s1, s2), 0, 2, cutoff=CUTOFF)


def test_traced_nan_is_not_ok_and_capacity_overflow_warns_and_counts():
    """A NaN marked valid under jit (no host check possible) gives ok False from that scan on,
    not an exception; a fused table of 2 slots for 3 targets refuses one fused track every scan,
    counts it, and the Monte Carlo warns (CapacityWarning naming `capacity`)."""
    small = TrackFusionTracker(LOCAL1, LOCAL2, capacity=2)
    scen = TwoSensorScenario(*scenarios(SEPARATED))
    with pytest.warns(CapacityWarning, match="raise `capacity`"):
        mc = multitarget_monte_carlo(small, scen, 4, 4, cutoff=CUTOFF, block_size=4)
    # 3 targets tracked by both sensors from scan 0: 1 refusal per scan and run.
    assert mc.capacity_events == 4 * NUM_SCANS, mc.capacity_events
    assert np.all(mc.num_tracks == 2) and mc.scans_not_ok == 0
    traj = simulate_two_sensors(*scenarios(SEPARATED), 1)
    z = traj.scans.measurements.at[4, 0, 1, 0].set(jnp.nan)

    @jax.jit
    def oks(z):
        return run_multitarget(small, z, traj.scans.valid, warn=False).ok

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ok = np.asarray(oks(z))
    assert ok[:4].all() and not ok[4]

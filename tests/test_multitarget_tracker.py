"""The multi-target trackers against Stone Soup's, and their track management.

Oracle: Stone Soup's ``MultiTargetMixtureTracker`` with ``JPDA(PDAHypothesiser)``, a
``SinglePointInitiator`` and an ``UpdateTimeStepsDeleter``: the same detections, the same P_D,
clutter density and gate, over a 100-scan scenario with four crossing targets and Poisson clutter.
The scenario is drawn here with NumPy (not with jaxtrack's simulator), so the oracle and the
tracker share nothing but the detections.
"""

from __future__ import annotations

import datetime

import jax
import numpy as np
import pytest

from jaxtrack.association import GNN, JPDA
from jaxtrack.filters import KalmanFilter
from jaxtrack.models import constant_velocity
from jaxtrack.multitarget import (
    CONFIRMED,
    CapacityWarning,
    IntegratedExistence,
    OnePointInitiator,
    Tracker,
    TrackManagement,
    run_tracker,
)

Q, SIGMA, P_D, CLUTTER_RATE, P_G = 0.05, 1.0, 0.9, 2.0, 0.99
REGION = np.array([[0.0, 200.0], [0.0, 200.0]])
DENSITY = CLUTTER_RATE / np.prod(REGION[:, 1] - REGION[:, 0])
NUM_STEPS, MAX_MEAS = 100, 16
PRIOR_MEAN = np.array([100.0, 100.0, 0.0, 0.0])
PRIOR_COV = np.diag([1e4, 1e4, 4.0, 4.0])


def _scenario(seed=3, num_steps=NUM_STEPS):
    """Four targets crossing near the centre; detections with P_D and Poisson clutter (NumPy)."""
    rng = np.random.default_rng(seed)
    F = np.kron(np.array([[1.0, 1.0], [0.0, 1.0]]), np.eye(2))
    Q1 = Q * np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]])
    Qm = np.kron(Q1, np.eye(2))
    x = np.array([[40.0, 40.0, 1.2, 1.2], [40.0, 160.0, 1.2, -1.2], [160.0, 40.0, -1.2, 1.2],
                  [100.0, 30.0, 0.0, 1.4]])
    LQ = np.linalg.cholesky(Qm)
    scans = []
    for _ in range(num_steps):
        dets = [xi[:2] + SIGMA * rng.standard_normal(2) for xi in x if rng.uniform() < P_D]
        num_clutter = rng.poisson(CLUTTER_RATE)
        clutter = REGION[:, 0] + (REGION[:, 1] - REGION[:, 0]) * rng.uniform(size=(num_clutter, 2))
        scans.append(np.array(dets + list(clutter)).reshape(-1, 2))
        x = x @ F.T + rng.standard_normal(x.shape) @ LQ.T
    z = np.full((num_steps, MAX_MEAS, 2), np.nan)
    valid = np.zeros((num_steps, MAX_MEAS), bool)
    for k, s in enumerate(scans):
        assert len(s) <= MAX_MEAS
        z[k, : len(s)] = s
        valid[k, : len(s)] = True
    return z, valid


def _model():
    return constant_velocity(1.0, dim=2, accel_psd=Q, measurement_std=SIGMA,
                             initial_mean=PRIOR_MEAN, initial_cov=PRIOR_COV)


def _tracker(association, delete_after=3, capacity=24, **kwargs):
    return Tracker(
        KalmanFilter(), _model(), association, OnePointInitiator(PRIOR_MEAN, PRIOR_COV),
        prob_detect=P_D, clutter_density=DENSITY, prob_gate=P_G, capacity=capacity,
        management=kwargs.pop("management", TrackManagement(1, 1, delete_after)), **kwargs,
    )


def _stonesoup_jpda_tracks(z, valid, delete_after=3):
    """Stone Soup's JPDA tracker on the same detections: {(birth step, birth detection): states}."""
    from stonesoup.dataassociator.probability import JPDA as SSJPDA
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import SinglePointInitiator
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.tracker.simple import MultiTargetMixtureTracker
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater

    perm = [0, 2, 1, 3]  # Stone Soup orders [x, vx, y, vy]
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(Q), ConstantVelocity(Q)])
    meas_model = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=SIGMA**2 * np.eye(2))
    predictor = KalmanPredictor(transition)
    updater = KalmanUpdater(meas_model)
    hypothesiser = PDAHypothesiser(predictor, updater, clutter_spatial_density=DENSITY,
                                   prob_detect=P_D, prob_gate=P_G, include_all=False)
    t0 = datetime.datetime(2026, 1, 1)
    times = [t0 + datetime.timedelta(seconds=k) for k in range(len(z))]
    prior = GaussianState(PRIOR_MEAN[perm][:, None], PRIOR_COV[np.ix_(perm, perm)], timestamp=t0)
    detections = [
        {Detection(z[k, j][:, None], timestamp=times[k], measurement_model=meas_model,
                   metadata={"index": (k, j)})
         for j in np.flatnonzero(valid[k])}
        for k in range(len(z))
    ]

    class Reader:
        def __iter__(self):
            return iter(zip(times, detections, strict=True))

    tracker = MultiTargetMixtureTracker(
        initiator=SinglePointInitiator(prior, meas_model), deleter=UpdateTimeStepsDeleter(delete_after),
        detector=Reader(), data_associator=SSJPDA(hypothesiser), updater=updater,
    )
    inverse = np.argsort(perm)
    history = {}
    for k, (_, tracks) in enumerate(tracker):
        for track in tracks:
            first = track.states[0]
            key = first.hypothesis.measurement.metadata["index"]
            history.setdefault(key, {})[k] = (np.asarray(track.state_vector, float).ravel()[inverse],
                                             np.asarray(track.covar, float)[np.ix_(inverse, inverse)])
    return history


@pytest.fixture(scope="module")
def scenario():
    return _scenario()


@pytest.fixture(scope="module")
def jpda_run(scenario):
    z, valid = scenario
    return run_tracker(_tracker(JPDA()), z, valid, save_cov=True)


def _tracks_of(result, z, valid):
    """{(birth step, birth measurement index): {step: (mean, cov)}} of a jaxtrack run."""
    mean, cov = np.asarray(result.mean), np.asarray(result.cov)
    status, ids = np.asarray(result.status), np.asarray(result.track_id)
    births = {}
    history = {}
    for k in range(mean.shape[0]):
        for s in np.flatnonzero(status[k] > 0):
            tid = int(ids[k, s])
            if tid not in births:
                # A track is born at its first step, at the measurement its mean was made from.
                births[tid] = k
            history.setdefault(tid, {})[k] = (mean[k, s], cov[k, s])
    return births, history


def test_jpda_tracker_equals_stone_soup_over_100_scans(scenario, jpda_run):
    """Every track, every scan: the same tracks are born and deleted, means and covariances agree."""
    z, valid = scenario
    ours_births, ours = _tracks_of(jpda_run, z, valid)
    theirs = _stonesoup_jpda_tracks(z, valid)
    # Identify each of our tracks by the detection it was born at: the initiated state's position
    # is the KF update of the broad prior on that detection, nearest to it.
    mapped = {}
    for tid, k in ours_births.items():
        m0 = ours[tid][k][0][:2]
        j = int(np.nanargmin(np.where(valid[k], np.linalg.norm(z[k] - m0, axis=1), np.inf)))
        mapped[(k, j)] = ours[tid]
    assert set(mapped) == set(theirs), (len(mapped), len(theirs))
    worst = 0.0
    for key, steps in theirs.items():
        assert set(mapped[key]) == set(steps), key
        for k, (m, P) in steps.items():
            worst = max(worst, np.max(np.abs(mapped[key][k][0] - m)), np.max(np.abs(mapped[key][k][1] - P)))
    assert worst <= 1e-9, worst
    assert len(theirs) >= 4  # the targets, plus clutter-born tracks


def test_the_targets_are_held_through_the_crossing(scenario, jpda_run):
    """After the crossing, four confirmed tracks sit within 5 sigma of where the targets go."""
    status = np.asarray(jpda_run.status)
    long_lived = np.asarray(jpda_run.track_id)[-1][status[-1] == CONFIRMED]
    assert len(long_lived) >= 4


def test_gnn_tracker_runs_the_same_step(scenario):
    z, valid = scenario
    result = run_tracker(_tracker(GNN()), z[:30], valid[:30])
    beta = np.asarray(result.association_probabilities)[1:]
    live = np.asarray(result.status)[:-1] > 0  # the tracks that entered scan k (from scan k-1)
    rows = beta[live]
    assert len(rows) > 50
    # GNN rows are one-hot; every live track's row sums to 1.
    np.testing.assert_allclose(rows.sum(-1), 1.0, atol=1e-12)
    assert np.all(np.isin(rows, [0.0, 1.0]))


def test_jipda_existence_confirms_targets_and_drops_clutter_tracks(scenario):
    z, valid = scenario
    management = TrackManagement(confirm_hits=3, confirm_window=3, delete_after_misses=5,
                                 confirm_existence=0.9, delete_existence=0.05)
    result = run_tracker(
        _tracker(JPDA(), management=management, existence=IntegratedExistence(0.99)), z[:40], valid[:40]
    )
    r = np.asarray(result.existence)[-1]
    status = np.asarray(result.status)[-1]
    assert np.all((r >= 0) & (r <= 1))
    assert np.sum(status == CONFIRMED) >= 4
    assert np.all(r[status == CONFIRMED] > 0.5)


def test_a_full_table_refuses_births_loudly(scenario):
    z, valid = scenario
    with pytest.warns(CapacityWarning, match="capacity"):
        result = run_tracker(_tracker(JPDA(), capacity=2), z[:5], valid[:5])
    assert bool(result.overflow)
    assert int(result.final.num_dropped_births) > 0


def test_score_tracks_counts_switches_breaks_and_false_tracks():
    """A hand-made run: two targets, tracks 7 and 8 swap them at scan 2, target 1 loses its track
    at scan 3, and track 9 (confirmed at scans 1-2) is never near a target."""
    from jaxtrack.multitarget import score_tracks

    T = 4
    x = np.zeros((T, 2, 2))
    x[:, 1, 0] = 100.0  # target 0 at the origin, target 1 at (100, 0)
    alive = np.ones((T, 2), bool)
    y = np.full((T, 3, 2), 500.0)
    ids = np.array([[7, 8, -1], [7, 8, 9], [7, 8, 9], [7, 8, -1]])
    conf = ids >= 0
    y[:, 0] = [[0, 1], [0, 1], [100, 1], [100, 1]]  # track 7: target 0, then target 1
    y[:, 1] = [[100, 1], [100, 1], [0, 1], [300, 0]]  # track 8: target 1, then target 0, then lost
    g, s = jax.jit(lambda *a: score_tracks(*a, cutoff=20.0))(x, alive, y, conf, ids)
    assert int(s.num_confirmed) == 3 and int(s.num_false) == 1
    assert int(s.num_switches) == 2  # both targets change track at scan 2
    assert int(s.num_breaks) == 1  # target 0 has no track at scan 3
    np.testing.assert_array_equal(np.asarray(g.num_assigned), [2, 2, 2, 1])
    np.testing.assert_allclose(np.asarray(g.false)[1], 20.0**2 / 2)  # track 9 at scan 1


def test_tracker_monte_carlo_is_the_runs_it_says():
    """Run i of the Monte Carlo is simulate_scenario(fold_in(key, i)) tracked and scored."""
    from jaxtrack.multitarget import Scenario, multitarget_monte_carlo, score_tracks, simulate_scenario

    model = _model()
    scenario = Scenario(
        model, np.array([[40.0, 40.0, 1.2, 1.2], [160.0, 40.0, -1.2, 1.2]]), [0, 2], [15, 15],
        detection_probability=P_D, clutter_rate=CLUTTER_RATE, clutter_region=REGION,
        max_measurements=MAX_MEAS, num_steps=15,
    )
    tracker = _tracker(GNN())
    key = jax.random.key(5)
    mc = multitarget_monte_carlo(tracker, scenario, key, 3, cutoff=10.0, block_size=4)
    score = jax.jit(lambda *a: score_tracks(*a, cutoff=10.0))
    per_run = []
    for i in range(3):
        truth = simulate_scenario(scenario, jax.random.fold_in(key, i))
        r = run_tracker(tracker, truth.scans.measurements, truth.scans.valid)
        g, s = score(truth.states[..., :2], truth.alive, r.mean[..., :2], r.status == CONFIRMED, r.track_id)
        per_run.append((np.asarray(g.distance), np.asarray(g.false), int(s.num_confirmed)))
    np.testing.assert_allclose(mc.gospa, np.mean([p[0] for p in per_run], axis=0), rtol=1e-12)
    np.testing.assert_allclose(mc.false, np.mean([p[1] for p in per_run], axis=0), rtol=1e-12)
    np.testing.assert_allclose(float(mc.scores.num_confirmed), np.mean([p[2] for p in per_run]))
    assert np.all(mc.gospa_interval[:, 0] <= mc.gospa) and np.all(mc.gospa <= mc.gospa_interval[:, 1])

"""monte_carlo with an IMM filter (mode probabilities streamed) and with scored components.

Oracle: each run replayed alone — ``simulate(truth, fold_in(key, i), T)`` filtered by
``run_imm`` / ``run_filter`` — and the statistics averaged in NumPy.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import (
    ExtendedKalmanFilter,
    InteractingMultipleModel,
    KalmanFilter,
    SquareRootKalmanFilter,
    run_filter,
    run_imm,
)
from jaxtrack.models import (
    ConstantVelocity,
    CoordinatedTurn,
    LinearGaussianModel,
    NearlyConstantTurn,
    RangeBearing,
    TrackingModel,
)
from jaxtrack.montecarlo import monte_carlo, simulate

T, TAU, RUNS = 40, 1.0, 6
X0 = np.array([2000.0, 1000.0, -15.0, 10.0])
P0 = np.diag([400.0, 400.0, 25.0, 25.0])
SENSOR = RangeBearing(np.array([10.0, 0.004]))
OMEGA = np.where((np.arange(T) >= 12) & (np.arange(T) < 28), 0.06, 0.0)


def _truth():
    return TrackingModel(CoordinatedTurn(TAU, turn_rate=OMEGA, noise_intensity=0.05), SENSOR, X0, P0)


def _imm():
    x5, p5 = np.append(X0, 0.0), np.diag(np.append(np.diag(P0), 0.01))
    members = [
        (ExtendedKalmanFilter(), TrackingModel(ConstantVelocity(TAU, noise_intensity=0.05), SENSOR, X0, P0)),
        (ExtendedKalmanFilter(), TrackingModel(NearlyConstantTurn(TAU, noise_intensity=0.05,
                                                                  turn_rate_intensity=1e-4), SENSOR, x5, p5)),
    ]
    return InteractingMultipleModel(members, np.array([[0.9, 0.1], [0.1, 0.9]]))


def _nees(e, P):
    return float(e @ np.linalg.solve(P, e))


def test_imm_monte_carlo_equals_replayed_runs():
    """MSE, NEES (on the 4 kinematic components of the 5-state IMM) and mean mode probabilities
    equal the average over runs replayed one by one with run_imm, to 1e-9."""
    truth, imm, key = _truth(), _imm(), jax.random.key(3)
    res = monte_carlo(truth, key, RUNS, filter=imm, filter_components=(0, 1, 2, 3), progress=False)
    sq, nees, mu = np.zeros((T, 4)), np.zeros(T), np.zeros((T, 2))
    for i in range(RUNS):
        tr = simulate(truth, jax.random.fold_in(key, i), T)
        out = run_imm(imm, tr.measurements)
        e = np.asarray(tr.states) - np.asarray(out.filtered_mean)[:, :4]
        sq += e**2
        nees += [_nees(e[k], np.asarray(out.filtered_cov)[k, :4, :4]) for k in range(T)]
        mu += np.asarray(out.mode_probs)
    np.testing.assert_allclose(res.mse, sq / RUNS, rtol=1e-9)
    np.testing.assert_allclose(res.nees, nees / RUNS, rtol=1e-9)
    np.testing.assert_allclose(res.mode_probs, mu / RUNS, rtol=1e-9, atol=1e-12)
    assert res.mode_probs.shape == (T, 2) and res.components == (0, 1, 2, 3)
    np.testing.assert_allclose(np.asarray(res.mode_probs).sum(axis=1), 1.0, atol=1e-12)
    # The turn is seen: the turn mode's probability in the turn's second half is above its
    # probability on the first leg (measured 0.5x vs 0.1x on this seed).
    assert float(np.mean(res.mode_probs[20:28, 1])) > float(np.mean(res.mode_probs[4:12, 1])) + 0.2
    assert float(np.max(np.abs(res.nis))) == 0.0 and float(np.max(res.nis_dof)) == 0.0


def test_single_filter_has_no_mode_probs_and_cv_filter_scores_on_subset():
    """A 4-state CV EKF on the turning truth (same size: no components needed) has
    mode_probs None; a 5-state NCT EKF scored on its first 4 components equals its replay."""
    truth, key = _truth(), jax.random.key(4)
    cv = TrackingModel(ConstantVelocity(TAU, noise_intensity=0.05), SENSOR, X0, P0)
    res_cv = monte_carlo(truth, key, RUNS, filter=ExtendedKalmanFilter(), filter_model=cv, progress=False)
    assert res_cv.mode_probs is None and res_cv.components is None
    x5, p5 = np.append(X0, 0.0), np.diag(np.append(np.diag(P0), 0.01))
    nct = TrackingModel(NearlyConstantTurn(TAU, noise_intensity=0.05, turn_rate_intensity=1e-4), SENSOR, x5, p5)
    res = monte_carlo(truth, key, RUNS, filter=ExtendedKalmanFilter(), filter_model=nct,
                      filter_components=(0, 1, 2, 3), num_steps=T, progress=False)
    sq, nees = np.zeros((T, 4)), np.zeros(T)
    for i in range(RUNS):
        tr = simulate(truth, jax.random.fold_in(key, i), T)
        out = run_filter(ExtendedKalmanFilter(), nct, tr.measurements)
        e = np.asarray(tr.states) - np.asarray(out.filtered_mean)[:, :4]
        sq += e**2
        nees += [_nees(e[k], np.asarray(out.filtered_cov)[k, :4, :4]) for k in range(T)]
    np.testing.assert_allclose(res.mse, sq / RUNS, rtol=1e-9)
    np.testing.assert_allclose(res.nees, nees / RUNS, rtol=1e-9)
    # the turn filter beats the CV filter on position in the turn (measured ~2x)
    assert float(np.mean(res.rmse((0, 1))[15:28])) < float(np.mean(res_cv.rmse((0, 1))[15:28]))


def _linear(n_extra=0):
    cv = ConstantVelocity(TAU, noise_intensity=0.5)
    F, Q = np.asarray(cv.transition_matrix(0)), np.asarray(cv.noise_cov(0))
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    return LinearGaussianModel(F, Q, H, np.diag([25.0, 16.0]), X0, P0)


@pytest.mark.parametrize("covariance", ["shared", "per_run"])
def test_components_on_linear_paths_and_square_root(covariance):
    """Scoring (vx, x) only — correlated, not a prefix: MSE = the full run's columns, and NEES the
    marginal 2-D NEES, on the shared path, the per-run path and (factor + QR) the square-root filter."""
    model, key = _linear(), jax.random.key(5)
    full = monte_carlo(model, key, 64, num_steps=T, covariance=covariance, progress=False)
    sub = monte_carlo(model, key, 64, num_steps=T, covariance=covariance, progress=False,
                      truth_components=(2, 0), filter_components=(2, 0))
    np.testing.assert_allclose(sub.mse, full.mse[:, [2, 0]], rtol=1e-12)
    sqrt = monte_carlo(model, key, 64, num_steps=T, filter=SquareRootKalmanFilter(), progress=False,
                       truth_components=(2, 0), filter_components=(2, 0))
    np.testing.assert_allclose(sqrt.nees, sub.nees, rtol=1e-9)
    # replay: the 2-D marginal NEES
    nees = np.zeros(T)
    for i in range(64):
        tr = simulate(model, jax.random.fold_in(key, i), T)
        out = run_filter(KalmanFilter(), model, tr.measurements)
        idx = np.array([2, 0])
        e = np.asarray(tr.states)[:, idx] - np.asarray(out.filtered_mean)[:, idx]
        nees += [_nees(e[k], np.asarray(out.filtered_cov)[k][np.ix_(idx, idx)]) for k in range(T)]
    np.testing.assert_allclose(sub.nees, nees / 64, rtol=1e-9)
    # consistent matched filter: 2-D ANEES inside its bounds (chi2(64*2) / 128 per step, 95%)
    assert sub.anees_bounds[0] < sub.anees < sub.anees_bounds[1] * 1.05


def test_input_errors_name_the_argument():
    truth, imm = _truth(), _imm()
    key = jax.random.key(0)
    cv = TrackingModel(ConstantVelocity(TAU, noise_intensity=0.05), SENSOR, X0, P0)
    with pytest.raises(InputError, match="filter_model"):
        monte_carlo(truth, key, 4, filter=imm, filter_model=cv, progress=False)
    with pytest.raises(InputError, match="covariance='shared'"):
        monte_carlo(truth, key, 4, filter=imm, covariance="shared", filter_components=(0, 1, 2, 3), progress=False)
    with pytest.raises(InputError, match="truth_components"):
        monte_carlo(truth, key, 4, filter=imm, progress=False)  # 5 vs 4 states, no mapping
    with pytest.raises(InputError, match="filter_components"):
        monte_carlo(truth, key, 4, filter=imm, filter_components=(0, 1, 5), progress=False)
    with pytest.raises(InputError, match="truth_components"):
        monte_carlo(truth, key, 4, filter=imm, truth_components=(0, 0), filter_components=(0, 1), progress=False)
    with pytest.raises(InputError, match="scored filter components"):
        monte_carlo(truth, key, 4, filter=imm, truth_components=(0, 1), filter_components=(0, 1, 2), progress=False)

"""Monte Carlo harness: consistency statistics against chi-square theory, chunking, replay."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

import jaxtrack
from jaxtrack.filters import KalmanFilter, run_filter
from jaxtrack.models import LinearGaussianModel
from jaxtrack.montecarlo import chi2_mean_bounds, monte_carlo, simulate

NUM_STEPS = 40


def cv_model(q=1.0, r=25.0, tau=1.0, prior=(100.0, 100.0, 10.0, 10.0)):
    """2-D constant velocity, state [x, y, vx, vy], CWNA plant noise of density q (m²/s³)."""
    F1 = np.array([[1.0, tau], [0.0, 1.0]])
    Q1 = q * np.array([[tau**3 / 3, tau**2 / 2], [tau**2 / 2, tau]])
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    return LinearGaussianModel(
        np.kron(F1, np.eye(2)), np.kron(Q1, np.eye(2)), H, r * np.eye(2), np.zeros(4), np.diag(prior)
    )


@pytest.fixture(scope="module")
def matched():
    return monte_carlo(cv_model(), jax.random.key(1), 2000, num_steps=NUM_STEPS, chunk_size=500, progress=False)


def test_chi2_bounds_match_scipy():
    lo, hi = chi2_mean_bounds(4, 2000)
    assert lo == pytest.approx(scipy.stats.chi2.ppf(0.025, 8000) / 2000, rel=1e-12)
    assert hi == pytest.approx(scipy.stats.chi2.ppf(0.975, 8000) / 2000, rel=1e-12)
    # Two-sided 95% bounds around n = 4, roughly 4 ± 1.96·sqrt(2·4/2000).
    assert lo == pytest.approx(4 - 1.96 * np.sqrt(8 / 2000), abs=0.01)
    np.testing.assert_array_equal(chi2_mean_bounds(np.array([0, 2]), 10)[0], [0.0, 0.0])


def test_matched_filter_is_consistent(matched):
    """M = 2000: ANEES inside its 95% bounds, ~95% of per-step NEES and NIS inside theirs."""
    lo, hi = np.asarray(matched.anees_bounds)
    assert lo < float(matched.anees) < hi, (float(matched.anees), lo, hi)
    assert hi - lo < 0.07  # the bounds are tight enough to mean something: ±3% at M = 2000
    # Per step, each inside with probability 0.95; over 40 steps, ≥ 33 inside has probability
    # > 0.99 under the binomial(40, 0.95) if steps were independent.
    assert float(matched.fraction_nees_inside()) >= 33 / 40
    nis_inside = (matched.nis >= matched.nis_bounds[:, 0]) & (matched.nis <= matched.nis_bounds[:, 1])
    assert int(jnp.sum(nis_inside)) >= 33
    assert matched.num_runs == 2000 and matched.num_failed == 0


def test_small_q_filter_is_inconsistent():
    """A filter whose Q is 10x too small is overconfident: ANEES far above its upper bound."""
    truth = cv_model(q=1.0)
    wrong = cv_model(q=0.1)
    res = monte_carlo(truth, jax.random.key(1), 2000, num_steps=NUM_STEPS, filter_model=wrong, progress=False)
    assert float(res.anees) > 1.5 * float(res.anees_bounds[1])


def test_rmse_matches_filter_covariance(matched):
    """For a matched linear filter, M·MSE_i / P_ii at the last step is chi-square with M dof."""
    model = cv_model()
    P = run_filter(KalmanFilter(), model, jnp.zeros((NUM_STEPS, 2))).filtered_cov[-1]
    ratio = np.asarray(matched.mse[-1]) / np.diag(np.asarray(P))
    lo, hi = chi2_mean_bounds(1, 2000, confidence=0.999)
    assert np.all((ratio > lo) & (ratio < hi)), ratio


def test_chunk_size_does_not_change_results(matched):
    other = monte_carlo(cv_model(), jax.random.key(1), 2000, num_steps=NUM_STEPS, chunk_size=333, progress=False)
    # Same per-run draws (fold_in by run index); only the summation order differs.
    for name in ("mse", "nees", "nis", "nees_std"):
        np.testing.assert_allclose(getattr(other, name), getattr(matched, name), rtol=1e-12, err_msg=name)
    assert other.anees == pytest.approx(float(matched.anees), rel=1e-13)


def test_run_replays_with_simulate_and_run_filter():
    """Run i of the harness is exactly simulate(fold_in(key, i)) followed by run_filter."""
    model = cv_model()
    key = jax.random.key(7)
    res = monte_carlo(model, key, 1, num_steps=12, progress=False)
    traj = simulate(model, jax.random.fold_in(key, 0), 12)
    filt = run_filter(KalmanFilter(), model, traj.measurements)
    err = traj.states - filt.filtered_mean
    np.testing.assert_allclose(res.mse, err**2, rtol=1e-12)
    nees = jnp.einsum("ti,tij,tj->t", err, jnp.linalg.inv(filt.filtered_cov), err)
    np.testing.assert_allclose(res.nees, nees, rtol=1e-9)


def test_simulate_statistics():
    """Simulated measurement noise and plant noise have the model's covariances (M = 4000)."""
    model = cv_model(q=2.0, r=9.0)
    keys = jax.random.split(jax.random.key(3), 4000)
    traj = jax.vmap(lambda k: simulate(model, k, 3))(keys)
    resid = traj.measurements - traj.states[..., :2]
    var = np.var(np.asarray(resid[:, 1, 0]))
    lo, hi = chi2_mean_bounds(1, 4000, confidence=0.999)
    assert lo < var / 9.0 < hi
    # x_1 − F x_0 is the plant noise w_1 ~ N(0, Q).
    F = np.asarray(model.F)
    w = np.asarray(traj.states[:, 1] - traj.states[:, 0] @ F.T)
    emp = np.cov(w.T)
    np.testing.assert_allclose(emp, np.asarray(model.Q), atol=4 * np.sqrt(2.0 / 4000) * 2.0)


def test_masked_steps_reduce_nis_dof():
    model = cv_model()
    mask = np.ones((NUM_STEPS, 2), bool)
    mask[5] = False
    mask[6, 1] = False
    res = monte_carlo(model, jax.random.key(2), 200, num_steps=NUM_STEPS, mask=mask, progress=False)
    assert float(res.nis_dof[5]) == 0 and float(res.nis_dof[6]) == 1 and float(res.nis_dof[7]) == 2
    assert float(res.nis[5]) == 0.0
    np.testing.assert_array_equal(np.asarray(res.nis_bounds[5]), [0.0, 0.0])


def test_nan_runs_are_excluded_and_reported():
    """A model whose plant noise blows up makes runs non-finite: they are counted, not averaged."""
    bad = LinearGaussianModel(
        np.array([[1e200]]), np.eye(1), np.eye(1), np.eye(1), np.zeros(1), np.eye(1)
    )
    with pytest.raises(FloatingPointError, match="every run"):
        with pytest.warns(RuntimeWarning, match="non-finite"):
            monte_carlo(bad, jax.random.key(0), 4, num_steps=5, progress=False)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"num_runs": 0}, "num_runs"),
        ({"chunk_size": 0}, "chunk_size"),
        ({"mask": np.ones(3, bool)}, "mask"),
        ({"mask": np.ones(NUM_STEPS, int)}, "mask"),
        ({"first_step": "later"}, "first_step"),
        ({"filter_model": LinearGaussianModel(np.eye(2), np.eye(2), np.eye(1, 2), np.eye(1), np.zeros(2), np.eye(2))}, "filter_model"),
    ],
)
def test_bad_arguments_name_themselves(kwargs, name):
    args = {"num_runs": 10, "num_steps": NUM_STEPS, "progress": False} | kwargs
    num_runs = args.pop("num_runs")
    with pytest.raises(jaxtrack.InputError, match=name):
        monte_carlo(cv_model(), jax.random.key(0), num_runs, **args)

"""The consider (Schmidt–Kalman) filter: jaxtrack.filters.ConsiderKalmanFilter.

Oracles: a NumPy transcription of the textbook Schmidt–Kalman equations (block form, written
here independently of the library), jaxtrack's own Kalman filter when nothing is considered,
and a Monte Carlo of the filter's own errors against its covariance with χ² bounds.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import (
    ConsiderKalmanFilter,
    KalmanFilter,
    consider_gain,
    consider_model,
    covariance_pass,
    run_filter,
)
from jaxtrack.models import LinearGaussianModel
from jaxtrack.montecarlo import chi2_mean_bounds, monte_carlo_map, normalized_squared_error, simulate

N_X, N_C, N_Z, STEPS = 3, 2, 2, 12


def spd(rng, k, scale=1.0):
    g = rng.normal(size=(k, k))
    return scale * (g @ g.T / k + 0.3 * np.eye(k))


def random_problem(seed=0):
    rng = np.random.default_rng(seed)
    return dict(
        F=0.9 * np.eye(N_X) + 0.2 * rng.normal(size=(N_X, N_X)), Q=spd(rng, N_X, 0.5),
        H=rng.normal(size=(N_Z, N_X)), R=spd(rng, N_Z), x0=rng.normal(size=N_X), P0=spd(rng, N_X, 10.0),
        G=rng.normal(size=(N_Z, N_C)), c0=rng.normal(size=N_C), C=spd(rng, N_C, 4.0),
    )


def build(p, C=None):
    return consider_model(p["F"], p["Q"], p["H"], p["R"], p["x0"], p["P0"], consider_matrix=p["G"],
                          consider_mean=p["c0"], consider_cov=p["C"] if C is None else C)


def numpy_schmidt_kalman(p, zs, gains=None):
    """Schmidt–Kalman filter in block form (Brown & Hwang; Bierman), prior one step before z_0."""
    F, Q, Hx, Hc, R = p["F"], p["Q"], p["H"], p["G"], p["R"]
    x, c = p["x0"].copy(), p["c0"].copy()
    Pxx, Pxc, Pcc = p["P0"].copy(), np.zeros((N_X, N_C)), p["C"].copy()
    I = np.eye(N_X)
    means, covs = [], []
    for k, z in enumerate(zs):
        x = F @ x
        Pxx = F @ Pxx @ F.T + Q
        Pxc = F @ Pxc
        S = Hx @ Pxx @ Hx.T + Hx @ Pxc @ Hc.T + Hc @ Pxc.T @ Hx.T + Hc @ Pcc @ Hc.T + R
        K = (Pxx @ Hx.T + Pxc @ Hc.T) @ np.linalg.inv(S) if gains is None else gains[k]
        x = x + K @ (z - Hx @ x - Hc @ c)
        A = I - K @ Hx
        Pxx_new = (A @ Pxx @ A.T + K @ R @ K.T - A @ Pxc @ Hc.T @ K.T - K @ Hc @ Pxc.T @ A.T
                   + K @ Hc @ Pcc @ Hc.T @ K.T)
        Pxc = A @ Pxc - K @ Hc @ Pcc
        Pxx = Pxx_new
        means.append(x.copy())
        covs.append(np.block([[Pxx, Pxc], [Pxc.T, Pcc]]))
    return np.array(means), np.array(covs)


@pytest.fixture(scope="module")
def problem():
    p = random_problem()
    zs = np.asarray(simulate(build(p), jax.random.key(1), STEPS, first_step="predict").measurements)
    return p, zs


def test_matches_numpy_schmidt_kalman(problem):
    p, zs = problem
    res = run_filter(ConsiderKalmanFilter(N_X), build(p), zs, first_step="predict")
    means, covs = numpy_schmidt_kalman(p, zs)
    np.testing.assert_allclose(np.asarray(res.filtered_mean[:, :N_X]), means, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(res.filtered_cov), covs, rtol=1e-12, atol=1e-12)
    # The considered parameters are carried, never estimated.
    np.testing.assert_array_equal(np.asarray(res.filtered_mean[:, N_X:]), np.broadcast_to(p["c0"], (STEPS, N_C)))


def test_fixed_gain_matches_numpy(problem):
    p, zs = problem
    gains = 0.3 * np.random.default_rng(4).normal(size=(STEPS, N_X, N_Z))
    res = run_filter(ConsiderKalmanFilter(N_X, gains), build(p), zs, first_step="predict")
    means, covs = numpy_schmidt_kalman(p, zs, gains)
    np.testing.assert_allclose(np.asarray(res.filtered_mean[:, :N_X]), means, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(res.filtered_cov), covs, rtol=1e-12, atol=1e-12)


def test_gain_minimises_the_trace_of_the_estimated_block(problem):
    p, _ = problem
    model = build(p)
    pred = covariance_pass(ConsiderKalmanFilter(N_X), model, jnp.ones((3, N_Z), bool), "predict")[0][2]
    H, R = model.H, model.R
    K = consider_gain(pred, H, R, N_X)

    def trace(k):
        W = jnp.concatenate([k, jnp.zeros((N_C, N_Z))])
        A = jnp.eye(N_X + N_C) - W @ H
        return jnp.trace((A @ pred @ A.T + W @ R @ W.T)[:N_X, :N_X])

    assert float(jnp.abs(jax.grad(trace)(K)).max()) < 1e-10 * float(trace(K))


def test_nothing_considered_is_the_kalman_filter(problem):
    p, zs = problem
    plain = LinearGaussianModel(p["F"], p["Q"], p["H"], p["R"], p["x0"], p["P0"])
    kf = run_filter(KalmanFilter(), plain, zs, first_step="predict")
    ck = run_filter(ConsiderKalmanFilter(N_X), plain, zs, first_step="predict")
    np.testing.assert_allclose(np.asarray(ck.filtered_mean), np.asarray(kf.filtered_mean), rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(np.asarray(ck.filtered_cov), np.asarray(kf.filtered_cov), rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(float(ck.log_likelihood), float(kf.log_likelihood), rtol=1e-14)
    # A zero considered covariance: the estimated block is the Kalman filter's too.
    zero = run_filter(ConsiderKalmanFilter(N_X), build(p, C=np.zeros((N_C, N_C))), zs, first_step="predict")
    shifted = zs - p["G"] @ p["c0"]  # the known parameter's contribution
    kf2 = run_filter(KalmanFilter(), plain, shifted, first_step="predict")
    np.testing.assert_allclose(np.asarray(zero.filtered_mean[:, :N_X]), np.asarray(kf2.filtered_mean), rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(np.asarray(zero.filtered_cov[:, :N_X, :N_X]), np.asarray(kf2.filtered_cov), rtol=1e-11)


def test_estimating_everything_beats_considering(problem):
    """The full (augmented) Kalman filter has a smaller estimated-block covariance than the consider one."""
    p, zs = problem
    model = build(p)
    full = run_filter(KalmanFilter(), model, zs, first_step="predict")
    ck = run_filter(ConsiderKalmanFilter(N_X), model, zs, first_step="predict")
    diff = np.asarray(ck.filtered_cov[-1, :N_X, :N_X] - full.filtered_cov[-1, :N_X, :N_X])
    assert np.linalg.eigvalsh(diff).min() > -1e-10


def _nees_run(key, args):
    """One run: the NEES of [ε; Δc] against the consider filter's covariance, at every step."""
    model, filt = args
    traj = simulate(model, key, filt.gain.shape[0], first_step="predict")
    est = run_filter(filt, model, traj.measurements, first_step="predict", throw=False)
    err = traj.states - est.filtered_mean
    full = jax.vmap(normalized_squared_error)(err, est.filtered_cov)
    naive = jax.vmap(normalized_squared_error)(err[:, :N_X], est.filtered_cov[:, :N_X, :N_X] * 0.5)
    return full, naive


def test_covariance_is_the_monte_carlo_error_covariance(problem):
    """Average NEES over 2,000 runs lies in its χ² bounds (99.9 %) at every step: the covariance
    is the actual error covariance of the filter's own estimates (including the unestimated c)."""
    p, _ = problem
    model = build(p)
    gains = covariance_pass(ConsiderKalmanFilter(N_X), model, jnp.ones((STEPS, N_Z), bool), "predict")[2][:, :N_X]
    num_runs = 2000
    full, naive = monte_carlo_map(_nees_run, jax.random.key(7), num_runs,
                                  args=(model, ConsiderKalmanFilter(N_X, gains)), block_size=256)
    bounds = chi2_mean_bounds(N_X + N_C, num_runs, confidence=0.999)
    anees = np.asarray(full) / num_runs
    assert np.all((anees > bounds[0]) & (anees < bounds[1])), (anees, bounds)
    # The test has power: a covariance half the true one is rejected at every step.
    naive_bounds = chi2_mean_bounds(N_X, num_runs, confidence=0.999)
    assert np.all(np.asarray(naive) / num_runs > naive_bounds[1])


def test_input_errors(problem):
    p, zs = problem
    with pytest.raises(InputError, match="num_estimated"):
        ConsiderKalmanFilter(0)
    with pytest.raises(InputError, match="gain"):
        ConsiderKalmanFilter(2, np.ones((3, 1)))
    with pytest.raises(InputError, match="num_estimated"):
        run_filter(ConsiderKalmanFilter(N_X + N_C + 1), build(p), zs)
    with pytest.raises(InputError, match="consider_cov"):
        build(p, C=-np.eye(N_C))
    with pytest.raises(InputError, match="consider_matrix"):
        consider_model(p["F"], p["Q"], p["H"], p["R"], p["x0"], p["P0"], consider_matrix=np.ones((3, N_C)),
                       consider_mean=p["c0"], consider_cov=p["C"])


def test_dtype_follows_inputs(problem):
    p, _ = problem
    model = build({k: np.asarray(v, np.float32) for k, v in p.items()})
    assert model.initial_cov.dtype == jnp.float32

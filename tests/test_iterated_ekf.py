"""Iterated EKF (issue 19): one iteration is the EKF bit for bit; N iterations equal Stone Soup's
IteratedKalmanUpdater run for N linearisations; on a strongly nonlinear update the IEKF mean is
closer to the exact MAP estimate than the EKF's."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

from jaxtrack import InputError
from jaxtrack.filters import ExtendedKalmanFilter, IteratedExtendedKalmanFilter, run_filter
from jaxtrack.models import NonlinearGaussianModel, wrap_angle
from jaxtrack.montecarlo import simulate

TAU = 1.0


def _coordinated_turn(x, k):
    w = 0.05  # known turn rate, rad/s
    s, c = jnp.sin(w * TAU), jnp.cos(w * TAU)
    px, py, vx, vy = x
    return jnp.stack([px + (s * vx - (1 - c) * vy) / w, py + ((1 - c) * vx + s * vy) / w,
                      c * vx - s * vy, s * vx + c * vy])


def _bearing_range(x, k):
    # Stone Soup's CartesianToBearingRange order: (bearing from +x towards +y, range).
    return jnp.stack([jnp.arctan2(x[1], x[0]), jnp.hypot(x[0], x[1])])


def _model(m0, P0, R=np.diag([0.02**2, 1.0**2])):
    Q = 0.1 * np.kron(np.array([[TAU**3 / 3, TAU**2 / 2], [TAU**2 / 2, TAU]]), np.eye(2))
    return NonlinearGaussianModel(_coordinated_turn, _bearing_range, Q, R, m0, P0, angle_components=(0,))


def test_one_iteration_is_the_ekf_exactly():
    # Near the sensor, passing behind it (bearing wraps through ±π), with missing components.
    model = _model(np.array([-30.0, 5.0, 0.0, -3.0]), np.diag([25.0, 25.0, 4.0, 4.0]))
    T = 200
    zs = simulate(model, jax.random.key(0), T).measurements
    mask = np.random.default_rng(0).uniform(size=(T, 2)) > 0.2
    ekf = run_filter(ExtendedKalmanFilter(), model, zs, mask=mask)
    iekf = run_filter(IteratedExtendedKalmanFilter(num_iterations=1), model, zs, mask=mask)
    for name in ("filtered_mean", "filtered_cov", "innovation", "innovation_cov", "log_likelihood"):
        a, b = np.asarray(getattr(iekf, name)), np.asarray(getattr(ekf, name))
        assert np.max(np.abs(a - b)) <= 1e-14 * np.max(np.abs(b)), name  # measured: 0 (identical)
    # More iterations change the estimates (the test above is not vacuous).
    iekf3 = run_filter(IteratedExtendedKalmanFilter(num_iterations=3), model, zs, mask=mask)
    assert np.max(np.abs(np.asarray(iekf3.filtered_mean - ekf.filtered_mean))) > 1e-3


def _stonesoup_iterated(m, P, z, R, num_iterations):
    """Stone Soup's IteratedKalmanUpdater for exactly `num_iterations` linearisations.

    Its loop (stonesoup/updater/kalman.py, IteratedKalmanUpdater.update) does one EKF update,
    then relinearises about the latest posterior while `measure > tolerance`, breaking (with a
    warning) once its counter exceeds `max_iterations`. With tolerance −1 the measure never
    stops it, so it makes 1 + (max_iterations + 1) linearisations: a fixed count.
    """
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.types.angle import Bearing
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.prediction import GaussianStatePrediction
    from stonesoup.types.state import StateVector
    from stonesoup.updater.kalman import IteratedKalmanUpdater

    class ExactJacobian(CartesianToBearingRange):
        # Stone Soup's default Jacobian is a finite difference (agreeing to ~1e-8 only); the
        # analytic one makes the comparison one of the iteration itself.
        def jacobian(self, state, **kwargs):
            x, y = float(state.state_vector[0, 0]), float(state.state_vector[2, 0])
            r2 = x * x + y * y
            J = np.zeros((2, 4))
            J[0, 0], J[0, 2] = -y / r2, x / r2
            J[1, 0], J[1, 2] = x / np.sqrt(r2), y / np.sqrt(r2)
            return J

    perm = [0, 2, 1, 3]  # Stone Soup [x, vx, y, vy] from jaxtrack [x, y, vx, vy]
    mm = ExactJacobian(ndim_state=4, mapping=(0, 2), noise_covar=R)
    prediction = GaussianStatePrediction(StateVector(m[perm]), P[np.ix_(perm, perm)])
    detection = Detection(StateVector([Bearing(z[0]), z[1]]), measurement_model=mm)
    if num_iterations == 1:
        from stonesoup.updater.kalman import ExtendedKalmanUpdater

        updater = ExtendedKalmanUpdater(measurement_model=mm)
    else:
        updater = IteratedKalmanUpdater(measurement_model=mm, tolerance=-1.0, max_iterations=num_iterations - 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "did not converge": the fixed count we asked for
        post = updater.update(SingleHypothesis(prediction, detection))
    inv = np.argsort(perm)
    mean = np.asarray(post.state_vector, dtype=np.float64).ravel()[inv]
    return mean, np.asarray(post.covar, dtype=np.float64)[np.ix_(inv, inv)]


@pytest.mark.parametrize("num_iterations", [1, 2, 3, 6])
def test_matches_stonesoup_iterated_kalman_updater(num_iterations):
    R = np.diag([0.05**2, 0.5**2])
    rng = np.random.default_rng(num_iterations)
    update = jax.jit(lambda m, P, z: IteratedExtendedKalmanFilter(num_iterations).update(
        _model(m, P, R), m, P, z, jnp.ones(2, bool), jnp.int32(0)))
    for trial in range(3):
        m = np.array([40.0, 25.0, 1.0, -2.0]) + rng.normal(size=4)
        A = rng.normal(size=(4, 4))
        P = np.diag([200.0, 150.0, 4.0, 4.0]) + 10.0 * A @ A.T
        truth = m + np.array([12.0, -9.0, 0.0, 0.0])
        z = np.asarray(_bearing_range(jnp.asarray(truth), 0)) + np.array([0.01, -0.3])
        ref_mean, ref_cov = _stonesoup_iterated(m, P, z, R, num_iterations)
        post = update(jnp.asarray(m), jnp.asarray(P), jnp.asarray(z))
        np.testing.assert_allclose(post.mean, ref_mean, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref_mean)))
        np.testing.assert_allclose(post.cov, ref_cov, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref_cov)))


def test_iterated_mean_is_closer_to_the_map_than_the_ekf():
    # A single update with the target close to the sensor and a large prior: the posterior is
    # far from Gaussian-linear, the EKF's one linearisation at the prior mean is poor.
    R = np.diag([0.01**2, 0.1**2])
    m = np.array([6.0, 4.0, 0.0, 0.0])
    P = np.diag([16.0, 16.0, 1.0, 1.0])
    truth = np.array([2.0, 7.0, 0.0, 0.0])
    z = np.asarray(_bearing_range(jnp.asarray(truth), 0))
    model = _model(m, P, R)
    observed = jnp.ones(2, bool)

    def posterior_mean(filter):
        return np.asarray(filter.update(model, jnp.asarray(m), jnp.asarray(P), jnp.asarray(z), observed, 0).mean)

    P_inv, R_inv = np.linalg.inv(P), np.linalg.inv(R)

    def neg_log_posterior(x):
        r = np.asarray(_bearing_range(jnp.asarray(x), 0))
        r = z - r
        r[0] = float(wrap_angle(r[0]))
        d = x - m
        return 0.5 * d @ P_inv @ d + 0.5 * r @ R_inv @ r

    opt = scipy.optimize.minimize(neg_log_posterior, truth + 0.1, method="BFGS", options={"gtol": 1e-10})
    x_map = opt.x
    err_ekf = np.linalg.norm(posterior_mean(ExtendedKalmanFilter()) - x_map)
    err_iekf = np.linalg.norm(posterior_mean(IteratedExtendedKalmanFilter(num_iterations=10)) - x_map)
    # Measured: EKF 1.77 m from the MAP, IEKF (10 iterations) 1.6e-8 m.
    assert err_iekf < 1e-4 and err_ekf > 1e3 * err_iekf, (err_ekf, err_iekf)


def test_differentiable_and_jittable():
    # d(log-likelihood)/d(measurement-noise scale) through the fixed-count iteration, against
    # central finite differences.
    model0 = _model(np.array([-30.0, 5.0, 0.0, -3.0]), np.diag([25.0, 25.0, 4.0, 4.0]))
    zs = simulate(model0, jax.random.key(2), 20).measurements

    def loglik(scale):
        model = NonlinearGaussianModel(_coordinated_turn, _bearing_range, model0.Q, model0.R * scale,
                                       model0.initial_mean, model0.initial_cov, angle_components=(0,))
        return run_filter(IteratedExtendedKalmanFilter(num_iterations=4), model, zs, save="final").log_likelihood

    g = jax.jit(jax.grad(loglik))(1.5)
    h = 1e-5
    fd = (loglik(1.5 + h) - loglik(1.5 - h)) / (2 * h)
    assert np.isfinite(g) and abs(g - fd) < 1e-6 * max(1.0, abs(fd))


def test_num_iterations_must_be_a_positive_int():
    for bad in (0, -1):  # (a float or bool is refused too; the suite's type checker answers first)
        with pytest.raises(InputError, match="num_iterations"):
            IteratedExtendedKalmanFilter(num_iterations=bad)

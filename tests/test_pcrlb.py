"""The posterior Cramér–Rao bound (jaxtrack.bounds): against the Kalman filter (linear-Gaussian),
against the inverse of the full-trajectory Fisher information built independently by autodiff of
the joint log density (nonlinear), and against Stone Soup's PCRBMetric (one given truth)."""

from __future__ import annotations

import datetime

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.scipy.stats import multivariate_normal

from jaxtrack import InputError
from jaxtrack.bounds import PosteriorCRB, efficiency, pcrlb, pcrlb_along
from jaxtrack.filters import KalmanFilter, run_filter
from jaxtrack.models import (
    ConstantVelocity,
    LinearGaussianModel,
    NonlinearGaussianModel,
    RangeBearing,
    TrackingModel,
    constant_velocity,
)
from jaxtrack.montecarlo import monte_carlo, simulate

P0_CV = np.diag([100.0, 100.0, 10.0, 10.0])


def _rel(a, b):
    """max |a − b| over the largest |b| of the same step: a relative difference per step, maximised."""
    a, b = np.asarray(a), np.asarray(b)
    scale = np.max(np.abs(b), axis=(-2, -1), keepdims=True)
    return float(np.max(np.abs(a - b) / scale))


# ----------------------------------------------------------------------------------------------
# (a) linear-Gaussian: the bound is the Kalman filter's filtered covariance


@pytest.mark.parametrize("first_step", ["update", "predict"])
@pytest.mark.parametrize("case", ["uniform", "nonuniform_tau", "missing_steps"])
def test_linear_gaussian_bound_is_kalman_covariance(case, first_step):
    T = 25
    taus = 1.0 if case != "nonuniform_tau" else np.linspace(0.2, 3.0, T)
    model = constant_velocity(jnp.asarray(taus), accel_psd=0.5, measurement_std=3.0, initial_cov=P0_CV)
    mask = None
    if case == "missing_steps":
        mask = np.ones(T, bool)
        mask[[0, 4, 5, 6, 17]] = False
    key = jax.random.key(1)
    bound = pcrlb(model, key, 1, T, mask=mask, first_step=first_step)
    z = simulate(model, key, T, first_step=first_step).measurements
    kf = run_filter(KalmanFilter(), model, z, mask=mask, first_step=first_step)
    assert isinstance(bound, PosteriorCRB) and bound.bound.shape == (T, 4, 4)
    assert _rel(bound.bound, kf.filtered_cov) < 1e-10
    # information is the inverse of the bound
    eye = np.broadcast_to(np.eye(4), (T, 4, 4))
    assert _rel(np.asarray(bound.information) @ np.asarray(bound.bound), eye) < 1e-9
    # the RMSE bound of the positions is the root of the trace of the position block
    np.testing.assert_allclose(bound.rmse_bound((0, 1)),
                               np.sqrt(kf.filtered_cov[:, 0, 0] + kf.filtered_cov[:, 1, 1]), rtol=1e-10)


def test_singular_process_noise_static_parameter():
    """Q = 0 on a static bias: the bound is still the Kalman covariance (no Q⁻¹ is formed)."""
    T = 12
    model = LinearGaussianModel(np.eye(2), np.diag([0.5, 0.0]), np.array([[1.0, 1.0], [1.0, 0.0]]),
                                np.diag([1.0, 4.0]), np.zeros(2), np.diag([10.0, 3.0]))
    bound = pcrlb(model, jax.random.key(0), 1, T)
    kf = run_filter(KalmanFilter(), model, simulate(model, jax.random.key(0), T).measurements)
    assert _rel(bound.bound, kf.filtered_cov) < 1e-10


def _null_space_transition(x, k):
    # the second (noise-free) component moves with sin of the first: its Jacobian row varies
    return jnp.stack([x[0], x[1] + 0.3 * jnp.sin(x[0])])


def _first_component(x, k):
    return x[:1]


def test_singular_q_with_varying_jacobian_in_its_null_space_raises():
    model = NonlinearGaussianModel(_null_space_transition, _first_component, np.diag([1.0, 0.0]),
                                   np.eye(1), np.zeros(2), np.eye(2))
    with pytest.raises(InputError, match="NonlinearGaussianModel.*singular"):
        pcrlb(model, jax.random.key(0), 8, 5)


# ----------------------------------------------------------------------------------------------
# (b) nonlinear: the bound is the last block of the inverse of the full-trajectory Fisher
# information E[−∇²_X log p(X, Z)], computed here by jax.hessian of the joint log density.


def _joint_log_density(model, X, Z):
    """log p(X, Z) = log N(x_0; m_0, P_0) + Σ_{k≥1} log N(x_k; f(x_{k−1}), Q_k) + Σ_k log N(z_k; h(x_k), R_k)."""
    ks = jnp.arange(X.shape[0])
    transition = jax.vmap(lambda x_prev, x, k: multivariate_normal.logpdf(
        x, model.transition(x_prev, k), model.process_noise_cov(k)))
    measurement = jax.vmap(lambda x, z, k: multivariate_normal.logpdf(
        z, model.measurement(x, k), model.measurement_noise_cov(k)))
    return (multivariate_normal.logpdf(X[0], model.initial_mean, model.initial_cov)
            + jnp.sum(transition(X[:-1], X[1:], ks[1:])) + jnp.sum(measurement(X, Z, ks)))


@jax.jit
def _mean_trajectory_fisher(model, X, Z=None):
    """The average over draws of −∇²_X log p(X, Z) (flattened trajectory), ``(T·n, T·n)``; X ``(N, T, n)``.

    ``Z=None``: at Z = h(X), the conditional expectation of the Hessian over the measurement noise.
    """
    _, T, n = X.shape
    if Z is None:
        Z = jax.vmap(jax.vmap(model.measurement))(X, jnp.broadcast_to(jnp.arange(T), X.shape[:2]))

    def neg_hess(x, z):
        return -jax.hessian(lambda v: _joint_log_density(model, v.reshape(T, n), z))(x.reshape(-1))

    return jnp.mean(jax.vmap(neg_hess)(X, Z), axis=0)


def _last_block_of_inverse(fisher, n):
    return np.linalg.inv(np.asarray(fisher))[-n:, -n:]


@eqx.filter_jit
def _draws(model, key, num_runs, T):
    """Run i of a study: simulate(model, fold_in(key, i), T), for i < num_runs."""
    trajs = jax.vmap(lambda i: simulate(model, jax.random.fold_in(key, i), T))(jnp.arange(num_runs))
    return trajs.states, trajs.measurements


def test_nonlinear_bound_is_block_of_inverse_trajectory_fisher_same_draws():
    """2-D CV observed by a range–bearing sensor, T = 6, 300 draws (two blocks of pcrlb's harness).

    The measurement term of −∇² log p is affine in Z (H̃ᵀR⁻¹H̃ − Σ_j ∇²h_j [R⁻¹(z − h)]_j), so
    its
    expectation over Z given X is its value at Z = h(X), and the transition is linear: with the same
    true trajectories the two constructions differ only algebraically (tolerance 1e-8).
    """
    T, N = 6, 300
    model = TrackingModel(ConstantVelocity(1.0, noise_intensity=0.5, dim=2),
                          RangeBearing(noise_std=(2.0, 0.02), sensor_position=(-100.0, 50.0)),
                          np.array([50.0, 80.0, 2.0, -1.0]), np.diag([100.0, 100.0, 4.0, 4.0]))
    key = jax.random.key(7)
    bound = pcrlb(model, key, N, T)
    X, _ = _draws(model, key, N, T)
    expected = _last_block_of_inverse(_mean_trajectory_fisher(model, X), 4)
    assert _rel(bound.bound[-1], expected) < 1e-8
    # and the bound is not the trivial prior-only one: the measurement information matters
    assert np.trace(np.asarray(bound.bound[-1])[:2, :2]) < 0.5 * (100.0 + 100.0)


def _growth(x, k):
    # univariate nonstationary growth model (Kitagawa 1987; Tichavský et al. 1998 Sec. V)
    return 0.5 * x + 25.0 * x / (1.0 + x**2) + 8.0 * jnp.cos(1.2 * k)


def _square_over_20(x, k):
    return x**2 / 20.0


def _sine_drift(x, k):
    # a nonlinear transition whose Jacobian 1 + 0.8 cos x varies over [0.2, 1.8] across trajectories
    return x + 0.8 * jnp.sin(x)


def _identity(x, k):
    return x


def test_nonlinear_transition_bound_matches_trajectory_fisher_within_monte_carlo_error():
    """Scalar x_k = x_{k−1} + 0.8 sin x_{k−1} + w_k, z_k = x_k + v_k, T = 4: the transition is
    nonlinear and its Jacobian's spread over trajectories (S_k = E[(F̃ − E F̃)²]/Q) matters.

    Here the Hessian of the transition term has the zero-mean part −f''(x_{k−1}) Q⁻¹ w_k, which
    the recursion's expectation removes exactly and the per-draw Hessians only on average. Eight
    independent groups (keys) of 250 runs each, same draws within a group for both constructions:
    the group differences d_g are i.i.d.; we require |mean d| ≤ 4 standard errors (Student t with
    7 degrees of freedom: two-sided ≈ 99.5 % confidence) and each |d_g| below 1 % of the bound.
    At T = 4 the bound without S_k (Jacobian spread dropped, D¹¹ = E[F̃]ᵀQ⁻¹E[F̃]) is 0.120 against
    0.065 (later steps approach Q whatever S_k).
    """
    T, N, G = 4, 250, 8
    model = NonlinearGaussianModel(_sine_drift, _identity, np.array([[0.05]]), np.array([[1.0]]),
                                   np.array([0.3]), np.array([[4.0]]))
    diffs, bounds = [], []
    for g in range(G):
        key = jax.random.key(100 + g)
        b = float(pcrlb(model, key, N, T).bound[-1, 0, 0])
        X, Z = _draws(model, key, N, T)
        h = float(_last_block_of_inverse(_mean_trajectory_fisher(model, X, Z), 1)[0, 0])
        diffs.append(h - b)
        bounds.append(b)
    diffs, bounds = np.asarray(diffs), np.asarray(bounds)
    mean, se = diffs.mean(), diffs.std(ddof=1) / np.sqrt(G)
    assert abs(mean) <= 4.0 * se + 1e-12, (mean, se)
    assert np.max(np.abs(diffs)) < 1e-2 * bounds.mean(), (diffs, bounds)


def test_pcrlb_of_one_run_is_pcrlb_along_that_runs_truth():
    """Run 0 of pcrlb is simulate(model, fold_in(key, 0), T): the same truth as a study's run 0."""
    T = 7
    model = NonlinearGaussianModel(_growth, _square_over_20, np.array([[10.0]]), np.array([[1.0]]),
                                   np.array([0.1]), np.array([[2.0]]))
    key = jax.random.key(3)
    truth = simulate(model, jax.random.fold_in(key, 0), T).states
    one = pcrlb(model, key, 1, T)
    along = pcrlb_along(model, truth)
    np.testing.assert_allclose(one.bound, along.bound, rtol=1e-12)
    np.testing.assert_allclose(one.information, along.information, rtol=1e-12)


# ----------------------------------------------------------------------------------------------
# (c) against Stone Soup's PCRBMetric on one given truth


def _stonesoup_inverse_j(X, taus, m0, P0, q, measurement_model, sensor, irf):
    from stonesoup.metricgenerator.pcrbmetric import PCRBMetric
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel
    from stonesoup.models.transition.linear import ConstantVelocity as StoneSoupCV
    from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
    from stonesoup.types.state import GaussianState

    perm = [0, 2, 1, 3]  # Stone Soup orders [x, vx, y, vy]; jaxtrack [x, y, vx, vy]
    t0 = datetime.datetime(2024, 1, 1)
    # Timestamps carry microseconds: the periods are multiples of 0.25 s so that dt is exact.
    elapsed = np.concatenate([[0.0], np.cumsum(taus[1:])])
    times = [t0 + datetime.timedelta(seconds=float(s)) for s in elapsed]
    path = GroundTruthPath([GroundTruthState(np.asarray(x)[perm].reshape(-1, 1), timestamp=t)
                            for x, t in zip(X, times)])
    transition = CombinedLinearGaussianTransitionModel([StoneSoupCV(q), StoneSoupCV(q)])
    prior = GaussianState(m0[perm].reshape(-1, 1), P0[np.ix_(perm, perm)], timestamp=times[0])
    # PCRBMetric indexes sensor_locations[:, i] and stores it as translation_offset, which the
    # bearing–range model indexes [0, 0]: a (2, 1, num_sensors) array gives it the (2, 1) column.
    locations = None if sensor is None else np.asarray(sensor, float).reshape(2, 1, 1)
    if locations is None:
        locations = np.zeros((2, 1))
    out = PCRBMetric._compute_pcrb_single(prior, transition, measurement_model, path, locations, irf,
                                          (0, 2), (1, 3))
    return out["inverse_j"][:, perm][:, :, perm], out["position_RMSE"]


def _analytic_bearing_range():
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange

    class AnalyticBearingRange(CartesianToBearingRange):
        """Stone Soup's bearing–range model with its analytic Jacobian (the stock one differences
        numerically, ~1e-6 relative), so that the comparison is of the recursion at 1e-8."""

        def jacobian(self, state, **kwargs):
            x = state.state_vector
            dx = float(x[0, 0] - self.translation_offset[0, 0])
            dy = float(x[2, 0] - self.translation_offset[1, 0])
            r2 = dx * dx + dy * dy
            r = np.sqrt(r2)
            return np.array([[-dy / r2, 0.0, dx / r2, 0.0], [dx / r, 0.0, dy / r, 0.0]])

    return AnalyticBearingRange


_SS_T, _SS_Q = 15, 0.3
_SS_TAUS = 0.25 * (1 + np.arange(_SS_T) % 6)
_SS_M0 = np.array([100.0, 50.0, 3.0, -2.0])
_SS_P0 = np.diag([400.0, 400.0, 4.0, 4.0])


@pytest.mark.parametrize("irf", [1.0, 0.6])
def test_pcrlb_along_matches_stonesoup_pcrb_metric_range_bearing(irf):
    pytest.importorskip("stonesoup")
    sigma_r, sigma_phi, sensor = 5.0, 0.02, np.array([-200.0, 150.0])
    model = TrackingModel(ConstantVelocity(_SS_TAUS, noise_intensity=_SS_Q, dim=2),
                          RangeBearing(noise_std=(sigma_r, sigma_phi), sensor_position=sensor), _SS_M0, _SS_P0)
    X = np.asarray(simulate(model, jax.random.key(3), _SS_T).states)
    measurement = _analytic_bearing_range()(ndim_state=4, mapping=(0, 2),
                                            noise_covar=np.diag([sigma_phi**2, sigma_r**2]))
    expected, pos_rmse = _stonesoup_inverse_j(X, _SS_TAUS, _SS_M0, _SS_P0, _SS_Q, measurement, sensor, irf)
    # Stone Soup's PCRB has no measurement at the first truth state (J_0 = P_0⁻¹); its irf
    # multiplies the measurement information as detection_probability does.
    mask = np.ones(_SS_T, bool)
    mask[0] = False
    bound = pcrlb_along(model, X, mask=mask, detection_probability=irf)
    assert _rel(bound.bound, expected) < 1e-8
    np.testing.assert_allclose(bound.rmse_bound((0, 1)), pos_rmse, rtol=1e-8)


def test_pcrlb_along_matches_stonesoup_pcrb_metric_linear_unmodified():
    """Stone Soup unmodified (a linear position sensor: its Jacobian is exact)."""
    pytest.importorskip("stonesoup")
    from stonesoup.models.measurement.linear import LinearGaussian

    model = constant_velocity(jnp.asarray(_SS_TAUS), accel_psd=_SS_Q, measurement_std=4.0,
                              initial_mean=_SS_M0, initial_cov=_SS_P0)
    X = np.asarray(simulate(model, jax.random.key(5), _SS_T).states)
    measurement = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag([16.0, 16.0]))
    expected, _ = _stonesoup_inverse_j(X, _SS_TAUS, _SS_M0, _SS_P0, _SS_Q, measurement, None, 1.0)
    mask = np.ones(_SS_T, bool)
    mask[0] = False
    assert _rel(pcrlb_along(model, X, mask=mask).bound, expected) < 1e-8


# ----------------------------------------------------------------------------------------------
# efficiency and input checks


def test_efficiency_of_the_kalman_filter_is_one_within_monte_carlo_error():
    """KF on its own linear model: MSE_k = bound_k. With M runs, the relative standard deviation of
    the Monte Carlo MSE of a group of Gaussian components is sqrt(2 tr(P²))/tr(P) ≤ sqrt(2/M);
    4 of those (per step) keeps every step inside at ≈ 99.99 % each."""
    T, M = 20, 2000
    model = constant_velocity(jnp.asarray(1.0), accel_psd=0.5, measurement_std=3.0, initial_cov=P0_CV)
    key = jax.random.key(11)
    result = monte_carlo(model, key, M, num_steps=T, progress=False)
    bound = pcrlb(model, key, 1, T)
    eff = np.asarray(efficiency(result, bound, (0, 1)))
    assert eff.shape == (T,)
    assert np.all(np.abs(eff**2 - 1.0) < 4.0 * np.sqrt(2.0 / M)), eff


def test_input_errors():
    model = constant_velocity(jnp.asarray(1.0), accel_psd=0.5, measurement_std=3.0, initial_cov=P0_CV)
    key = jax.random.key(0)
    with pytest.raises(InputError, match="`num_runs`"):
        pcrlb(model, key, 0, 5)
    with pytest.raises(InputError, match="`num_steps`"):
        pcrlb(model, key, 1)
    with pytest.raises(InputError, match="`mask`"):
        pcrlb(model, key, 1, 5, mask=np.ones(4, bool))
    with pytest.raises(InputError, match="`mask`"):
        pcrlb(model, key, 1, 5, mask=np.ones(5))
    with pytest.raises(InputError, match="`first_step`"):
        pcrlb(model, key, 1, 5, first_step="smooth")
    with pytest.raises(InputError, match="`detection_probability`"):
        pcrlb(model, key, 1, 5, detection_probability=1.5)
    with pytest.raises(InputError, match="`truth_states`"):
        pcrlb_along(model, np.zeros((5, 3)))
    # InputError without the suite's runtime type checking; its TypeError (beartype) with it.
    with pytest.raises((InputError, TypeError), match="model"):
        pcrlb("not a model", key, 1, 5)
    bound = pcrlb(model, key, 1, 5)
    with pytest.raises(InputError, match="`components`"):
        bound.rmse_bound((4,))

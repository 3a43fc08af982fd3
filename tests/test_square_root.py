"""Square-root Kalman filter and square-root UKF (issue 19).

float64: equal to the Joseph-form KalmanFilter to 1e-12 / the UKF to 1e-10 over 1,000 steps (means,
covariances, S, log-likelihood). float32, ill-conditioned (a 2-D constant-velocity target, prior
σ 1 km, position measured to 1 mm): the Joseph filter's covariance turns singular at the second
update and its ANEES leaves the 95% bounds by six orders of magnitude, while both square-root
filters stay positive definite with ANEES inside the bounds over 1,000 runs.
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import (
    KalmanFilter,
    SquareRootKalmanFilter,
    SquareRootUnscentedKalmanFilter,
    UnscentedKalmanFilter,
    run_filter,
)
from jaxtrack.models import LinearGaussianModel, NonlinearGaussianModel
from jaxtrack.montecarlo import chi2_mean_bounds, monte_carlo, simulate

from helpers import assert_close, random_linear_model, simulate_linear


def _contracting(model: LinearGaussianModel, radius: float = 0.99) -> LinearGaussianModel:
    """The random model with its transitions scaled to spectral radius ``radius`` (if larger).

    A random ``expm(A τ)`` may grow (seed 0: |λ| 1.045, the states reach 9e18 in 1,000 steps):
    the innovations are then differences of 1e18-sized numbers, their last bits depend on how
    XLA fuses the mean arithmetic, not on the filter, and the comparison tests nothing. Scaled,
    the states stay O(1) and every field is compared where its digits mean something."""
    F = np.asarray(model.F)
    rho = np.max(np.abs(np.linalg.eigvals(F)), axis=-1, keepdims=True)[..., None]
    F = F * np.minimum(1.0, radius / rho)
    return LinearGaussianModel(F, model.Q, model.H, model.R, model.initial_mean, model.initial_cov)


FIELDS = ("filtered_mean", "filtered_cov", "predicted_mean", "predicted_cov", "innovation",
          "innovation_cov", "log_likelihood", "final_cov")


def _assert_results_close(actual, desired, rtol):
    for name in FIELDS:
        assert_close(getattr(actual, name), getattr(desired, name), rtol, err_msg=name)


def _assert_factors(res):
    # The factors are lower triangular with a positive diagonal and square to the covariances.
    for L, P in ((res.filtered_cov_factor, res.filtered_cov), (res.predicted_cov_factor, res.predicted_cov),
                 (res.innovation_cov_factor, res.innovation_cov)):
        L = np.asarray(L)
        assert np.all(np.triu(L, 1) == 0) and np.all(np.diagonal(L, axis1=-2, axis2=-1) > 0)
        assert_close(L @ np.swapaxes(L, -1, -2), P, 1e-14)


@pytest.mark.parametrize("first_step", ["update", "predict"])
def test_square_root_kf_equals_joseph_kf_over_1000_steps(first_step):
    T = 1000
    rng = np.random.default_rng(0)
    model = _contracting(random_linear_model(rng, 4, 2, T, nonuniform_tau=False))
    _, zs = simulate_linear(rng, model, T, first_step)
    mask = rng.uniform(size=(T, 2)) > 0.2
    ref = run_filter(KalmanFilter(), model, zs, mask=mask, first_step=first_step)
    res = run_filter(SquareRootKalmanFilter(), model, zs, mask=mask, first_step=first_step)
    assert bool(res.ok)
    # Measured (either XLA:CPU emitter): 5e-16 of each field's magnitude (means, covariances,
    # innovations, log-likelihood).
    _assert_results_close(res, ref, 1e-12)
    _assert_factors(res)
    assert ref.filtered_cov_factor is None  # covariance filters keep their outputs unchanged


def test_square_root_kf_singular_process_noise_and_per_step_matrices():
    # Q = 0 (its factor is the semidefinite Cholesky factor 0) and per-step F, H, R.
    T = 200
    rng = np.random.default_rng(1)
    base = _contracting(random_linear_model(rng, 3, 2, T, per_step_measurement=True))
    model = LinearGaussianModel(base.F, np.zeros((3, 3)), base.H, base.R, base.initial_mean, base.initial_cov)
    _, zs = simulate_linear(rng, model, T)
    ref = run_filter(KalmanFilter(), model, zs)
    res = run_filter(SquareRootKalmanFilter(), model, zs)
    _assert_results_close(res, ref, 1e-12)


TAU = 1.0


def _coordinated_turn(x, k):
    w = 0.02  # known turn rate, rad/s
    s, c = jnp.sin(w * TAU), jnp.cos(w * TAU)
    px, py, vx, vy = x
    return jnp.stack([px + (s * vx - (1 - c) * vy) / w, py + ((1 - c) * vx + s * vy) / w,
                      c * vx - s * vy, s * vx + c * vy])


def _range_bearing(x, k):
    return jnp.stack([jnp.arctan2(x[1], x[0]), jnp.hypot(x[0], x[1])])


def _nonlinear_model():
    Q = 0.05 * np.kron(np.array([[TAU**3 / 3, TAU**2 / 2], [TAU**2 / 2, TAU]]), np.eye(2))
    R = np.diag([0.01**2, 5.0**2])
    return NonlinearGaussianModel(_coordinated_turn, _range_bearing, Q, R, np.array([1000.0, 500.0, 10.0, -5.0]),
                                  np.diag([100.0, 100.0, 4.0, 4.0]), angle_components=(0,))


@pytest.mark.parametrize(
    "alpha, beta, kappa",
    [(1.0, 0.0, 0.0),  # cubature: w0c = 0 (QR only)
     (1.0, 2.0, 1.0),  # w0c > 0: the zeroth point joins the QR pre-array
     (0.5, 2.0, 0.0)],  # w0c = −0.25 < 0: Cholesky downdate
)
def test_square_root_ukf_equals_ukf_over_1000_steps(alpha, beta, kappa):
    model = _nonlinear_model()
    T = 1000
    zs = simulate(model, jax.random.key(0), T).measurements
    mask = np.random.default_rng(1).uniform(size=(T, 2)) > 0.2
    ref = run_filter(UnscentedKalmanFilter(alpha, beta, kappa), model, zs, mask=mask)
    res = run_filter(SquareRootUnscentedKalmanFilter(alpha, beta, kappa), model, zs, mask=mask)
    assert bool(res.ok)
    _assert_results_close(res, ref, 1e-10)  # measured: 1e-13 (covariances), 1e-15 (means)
    _assert_factors(res)


def test_consistency_hook_uses_the_factors():
    # NEES and NIS from the factors equal the covariance filters' (formed from P and S).
    model = _nonlinear_model()
    zs = simulate(model, jax.random.key(1), 5).measurements
    error = jnp.array([3.0, -2.0, 0.5, 0.1])

    @jax.jit
    def scores(zs):
        def one(filter):
            state = filter.init(model)
            out = []
            for k in range(zs.shape[0]):
                state, step = filter.step(model, state, zs[k])
                out.append(jnp.stack(filter.consistency(step.conditioned, error)))
            return jnp.stack(out)

        return one(SquareRootUnscentedKalmanFilter()), one(UnscentedKalmanFilter())

    from_factors, from_covariances = scores(zs)
    assert_close(from_factors, from_covariances, 1e-10)


def test_gradient_through_the_square_root_kf_equals_the_kalman_filter():
    T = 20
    rng = np.random.default_rng(4)
    model = random_linear_model(rng, 3, 2, T, nonuniform_tau=False)
    _, zs = simulate_linear(rng, model, T)

    def loglik(filter, scale):
        m = LinearGaussianModel(model.F, model.Q * scale, model.H, model.R * scale, model.initial_mean,
                                model.initial_cov)
        return run_filter(filter, m, zs, save="final").log_likelihood

    g_ref = jax.grad(lambda s: loglik(KalmanFilter(), s))(1.3)
    g = jax.grad(lambda s: loglik(SquareRootKalmanFilter(), s))(1.3)
    assert np.isfinite(g) and abs(g / g_ref - 1) < 1e-9


def test_input_errors():
    with pytest.raises(InputError, match="LinearGaussianModel"):
        run_filter(SquareRootKalmanFilter(), _nonlinear_model(), np.zeros((3, 2)))
    with pytest.raises(InputError, match="alpha"):
        SquareRootUnscentedKalmanFilter(alpha=0.0)
    with pytest.raises(InputError, match="kappa"):
        run_filter(SquareRootUnscentedKalmanFilter(alpha=1.0, kappa=-4.0), _nonlinear_model(), np.zeros((3, 2)))


# ---- float32: an ill-conditioned case ----------------------------------------------------------

STEPS, RUNS = 20, 1000


def _precise_position_cv(dtype):
    """2-D constant velocity, τ = 1 s, prior σ 1 km (10 m/s), position measured to σ = 1 mm,
    q = 1e-4 m²/s³: P⁻/R = 1e12 at the first update, beyond float32's 1/ε ≈ 1.7e7."""
    F = np.kron(np.array([[1.0, 1.0], [0.0, 1.0]]), np.eye(2))
    Q = 1e-4 * np.kron(np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]]), np.eye(2))
    H = np.kron(np.array([[1.0, 0.0]]), np.eye(2))
    arrays = (F, Q, H, 1e-6 * np.eye(2), np.zeros(4), np.diag([1e6, 1e6, 1e4, 1e4]))
    return LinearGaussianModel(*(jnp.asarray(a, dtype) for a in arrays))


def _monte_carlo(model, filter):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the float32 precision warning (Joseph)
        return monte_carlo(model, jax.random.key(0), RUNS, num_steps=STEPS, filter=filter,
                           covariance="per_run", progress=False)


def test_float32_joseph_loses_definiteness_square_root_filters_stay_consistent():
    model = _precise_position_cv(jnp.float32)
    # Bounds of one step's run-averaged NEES per state, as MonteCarloResult.anees_bounds (valid and
    # conservative for the average over correlated steps).
    lo, hi = chi2_mean_bounds(4, RUNS) / 4

    # Joseph form, float32: the filtered covariance after the second update is singular (true
    # smallest eigenvalue 9.7e-7 m², computed 0), and ANEES is ~3e6 against an upper bound 1.04.
    zs = simulate(model, jax.random.key(7), STEPS).measurements
    joseph = run_filter(KalmanFilter(), model, zs, throw=False)
    eig = np.linalg.eigvalsh(np.asarray(joseph.filtered_cov[1], np.float64))
    assert eig[0] <= 1e-8 * eig[-1]
    res = _monte_carlo(model, KalmanFilter())
    assert res.anees > 1e3 * hi

    # The reference: float64 Joseph covariance at the same step.
    exact = run_filter(KalmanFilter(), _precise_position_cv(jnp.float64), np.asarray(zs, np.float64))
    exact_eig = np.linalg.eigvalsh(np.asarray(exact.filtered_cov[1]))

    keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(0), i))(jnp.arange(RUNS))
    trajectories = jax.vmap(lambda k: simulate(model, k, STEPS))(keys)
    for filter in (SquareRootKalmanFilter(), SquareRootUnscentedKalmanFilter()):
        res = _monte_carlo(model, filter)
        assert res.num_failed == 0
        assert lo < float(res.anees) < hi, (type(filter).__name__, float(res.anees))  # 1.0047 (SR-KF)
        # Positive definite at every step of every run: the factors' diagonals are positive,
        # and the covariance they square to has the float64 filter's eigenvalues to 1e-2.
        runs = jax.vmap(lambda z: run_filter(filter, model, z, throw=False))(trajectories.measurements)
        assert bool(jnp.all(runs.ok))
        assert runs.filtered_cov_factor.dtype == jnp.float32
        assert float(jnp.min(jnp.diagonal(runs.filtered_cov_factor, axis1=-2, axis2=-1))) > 0
        L = np.asarray(runs.filtered_cov_factor[0, 1], np.float64)
        np.testing.assert_allclose(np.linalg.eigvalsh(L @ L.T), exact_eig, rtol=1e-2)

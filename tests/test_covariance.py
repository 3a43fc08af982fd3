"""Computed versus actual covariance (Ho 1968 §1.3, targets T36–T38 of specs/ho-sensitivity.md)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxtrack
from jaxtrack.covariance import (
    actual_covariance,
    covariance_recursion,
    predicted_error_mean,
    updated_error_mean,
)
from jaxtrack.filters import KalmanFilter, run_filter
from jaxtrack.models import NonlinearGaussianModel, ho_plant
from jaxtrack.montecarlo import chi2_mean_bounds, monte_carlo

# Long programs: compiled at XLA's default level (tests/conftest.py; alone, cold: 32.9 against 17.3
# CPU-s)
pytestmark = pytest.mark.xla_optimized

TAUS = jnp.full(50, 0.1)  # uniform 0.1 s, 50 samples (T36, T37)


def test_recursion_is_the_filters_covariance():
    """The data-free recursion runs the filter's own step: identical covariances, bit for bit."""
    model = ho_plant(TAUS, g=1.0)
    hist = covariance_recursion(model)
    res = run_filter(KalmanFilter(), model, jnp.zeros((50, 1)))
    np.testing.assert_array_equal(hist.filtered_cov, res.filtered_cov)
    np.testing.assert_array_equal(hist.predicted_cov, res.predicted_cov)
    assert float(hist.filtered_cov[-1, 0, 0]) == pytest.approx(876.2576, rel=1e-6)
    # Gains are the optimal ones, P_{k/k-1} Hᵀ S⁻¹.
    H = np.array([[1.0, 0.0]])
    W = np.einsum("tij,jk,tk->ti", hist.predicted_cov, H.T, 1 / hist.innovation_cov[:, :, 0])
    np.testing.assert_allclose(hist.gain[:, :, 0], W, rtol=1e-12)


@pytest.mark.parametrize(
    "filter_g, true_g, computed, actual_pos, actual_vel",
    [
        (1.0, 10.0, 876.26, 9799.15, 17362.95),  # T36: filter assumes 1 g, truth is 10 g
        (10.0, 1.0, 2249.39, 1757.44, None),  # T36: filter assumes 10 g, truth is 1 g
    ],
)
def test_actual_versus_computed_T36(filter_g, true_g, computed, actual_pos, actual_vel):
    # The spec prints two decimals: agree to half a unit in the last printed digit.
    comp, act = actual_covariance(ho_plant(TAUS, g=true_g), ho_plant(TAUS, g=filter_g))
    assert float(comp.filtered_cov[-1, 0, 0]) == pytest.approx(computed, abs=0.005)
    assert float(act.filtered_cov[-1, 0, 0]) == pytest.approx(actual_pos, abs=0.005)
    if actual_vel is not None:
        assert float(act.filtered_cov[-1, 1, 1]) == pytest.approx(actual_vel, abs=0.005)
    np.testing.assert_array_equal(act.gain, comp.gain)


def test_matched_actual_equals_computed():
    comp, act = actual_covariance(ho_plant(TAUS, g=1.0), ho_plant(TAUS, g=1.0))
    np.testing.assert_allclose(act.filtered_cov, comp.filtered_cov, rtol=1e-12)


def test_actual_covariance_refuses_a_different_transition():
    with pytest.raises(jaxtrack.InputError, match="share F"):
        actual_covariance(ho_plant(TAUS), ho_plant(jnp.full(50, 0.2)))


def test_actual_covariance_is_differentiable_in_true_noise():
    """∂(actual P_T)/∂g_true by jax.grad equals a central difference."""
    f = lambda g: actual_covariance(ho_plant(TAUS, g=g), ho_plant(TAUS, g=1.0))[1].filtered_cov[-1, 0, 0]  # noqa: E731
    grad = jax.grad(f)(3.0)
    h = 1e-4
    fd = (f(3.0 + h) - f(3.0 - h)) / (2 * h)
    assert float(grad) == pytest.approx(float(fd), rel=1e-7)


@pytest.mark.parametrize("filter_g, true_g", [(1.0, 1.0), (1.0, 10.0)])
def test_monte_carlo_terminal_variance_T37(filter_g, true_g):
    """T37: M = 2e5 vmapped runs; terminal position error variance against the actual covariance.

    M·MSE/P_actual is χ²(M) when the errors are zero-mean Gaussian with variance P_actual; the
    99.9% two-sided interval is about ±1.05% at M = 2e5. The mean error lies within 4σ of 0.
    """
    M = 200_000
    truth, filt = ho_plant(TAUS, g=true_g), ho_plant(TAUS, g=filter_g)
    _, act = actual_covariance(truth, filt)
    res = monte_carlo(truth, jax.random.key(37), M, filter_model=filt, chunk_size=50_000, progress=False)
    theory = float(act.filtered_cov[-1, 0, 0])
    lo, hi = chi2_mean_bounds(1, M, confidence=0.999)
    ratio = float(res.mse[-1, 0]) / theory
    assert lo < ratio < hi, (ratio, lo, hi)
    assert abs(float(res.mean_error[-1, 0])) < 4 * np.sqrt(theory / M)


def _quadratic_model(c, d):
    return NonlinearGaussianModel(
        lambda x, k: x + c * x**2,
        lambda x, k: x + d * x**2,
        0.04 * jnp.eye(1),
        0.09 * jnp.eye(1),
        jnp.zeros(1),
        jnp.eye(1),
    )


def test_ekf_error_means_T38():
    """(A.10) and (A.14) with the corrected signs are exact for quadratic f and h: sample means agree.

    x̃_{k-1/k-1} ~ N(ē, P); x_k = f(x̂ + x̃) + w; the prediction error x_k − f(x̂) has mean (A.10).
    The update error after W(z − h(x̂⁻)) has mean (A.14). Bound: 5 standard errors of the mean.
    """
    c, d, M = 0.3, -0.2, 400_000
    model = _quadratic_model(c, d)
    x_hat, e_bar, P = jnp.array([0.7]), jnp.array([0.15]), jnp.array([[0.2]])
    k1, k2, k3 = jax.random.split(jax.random.key(38), 3)
    e_prev = e_bar[None, :] + jnp.sqrt(P[0, 0]) * jax.random.normal(k1, (M, 1))
    x = x_hat[None, :] + e_prev
    x_next = x + c * x**2 + 0.2 * jax.random.normal(k2, (M, 1))
    x_pred = x_hat + c * x_hat**2
    err_pred = x_next - x_pred[None, :]
    expected = predicted_error_mean(model, e_bar, P, x_hat, 1)
    sem = float(jnp.std(err_pred)) / np.sqrt(M)
    assert abs(float(jnp.mean(err_pred)) - float(expected[0])) < 5 * sem
    # The naive first-order mean Φ ē misses the second-order term by many standard errors.
    assert abs(float(jnp.mean(err_pred)) - float((1 + 2 * c * x_hat[0]) * e_bar[0])) > 20 * sem

    # Update with a fixed gain W, prediction error distributed as simulated above.
    W = jnp.array([[0.5]])
    e_mean = jnp.mean(err_pred, axis=0)
    e_cov = jnp.cov(err_pred.T).reshape(1, 1)
    z = x_next + d * x_next**2 + 0.3 * jax.random.normal(k3, (M, 1))
    x_upd = x_pred[None, :] + W[0, 0] * (z - (x_pred + d * x_pred**2)[None, :])
    err_upd = x_next - x_upd
    expected_upd = updated_error_mean(model, e_mean, e_cov, x_pred, W, 1)
    sem_upd = float(jnp.std(err_upd)) / np.sqrt(M)
    # Sample mean/cov of the prediction error are themselves estimates: allow 8 SEM.
    assert abs(float(jnp.mean(err_upd)) - float(expected_upd[0])) < 8 * sem_upd


def test_this_module_compiles_at_the_default_level():
    """pytest.mark.xla_optimized reached XLA (the fixture in tests/conftest.py)."""
    from conftest import fast_compile

    assert not fast_compile()

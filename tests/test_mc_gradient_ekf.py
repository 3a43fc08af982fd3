"""jax.grad through differentiable_monte_carlo on the per-run covariance path (ExtendedKalmanFilter,
every run carries its own covariance): same statistics as monte_carlo, gradient of the
time-averaged position MSE against central differences with common random numbers."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxtrack.filters import ExtendedKalmanFilter
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import differentiable_monte_carlo, monte_carlo

P0 = jnp.diag(jnp.array([100.0, 100.0, 25.0, 25.0]))
TRUTH = constant_velocity(1.0, accel_psd=1.0, measurement_std=10.0, initial_cov=P0)
KEY = jax.random.key(5)
NUM_RUNS, NUM_STEPS = 600, 20  # 600 runs: blocks of 512, the second one padded


def run(log_q, num_runs=NUM_RUNS):
    fm = constant_velocity(1.0, accel_psd=jnp.exp(log_q), measurement_std=20.0, initial_cov=P0)
    return differentiable_monte_carlo(TRUTH, KEY, num_runs, num_steps=NUM_STEPS, filter=ExtendedKalmanFilter(),
                                      filter_model=fm)


def position_mse(log_q):
    return jnp.mean(jnp.sum(run(log_q).mse[:, :2], axis=-1))


def test_equals_monte_carlo_per_run_path():
    fm = constant_velocity(1.0, accel_psd=jnp.exp(0.3), measurement_std=20.0, initial_cov=P0)
    a = monte_carlo(TRUTH, KEY, NUM_RUNS, num_steps=NUM_STEPS, filter=ExtendedKalmanFilter(), filter_model=fm,
                    progress=False)
    b = run(0.3)
    assert not a.shared_covariance and not b.shared_covariance
    for f in ("mse", "mean_error", "nees", "nees_std", "nees_bounds", "nis", "nis_dof", "nis_bounds", "anees"):
        np.testing.assert_allclose(np.asarray(getattr(b, f)), np.asarray(getattr(a, f)), rtol=1e-12, err_msg=f)
    assert a.num_runs == b.num_runs == NUM_RUNS


def test_ekf_gradient_matches_central_differences():
    """h = 1e-4 in log q: truncation h²J'''/6 and round-off ε|J|/h both < 1e-8 relative (checked by
    D(2h) − D(h) = 3·truncation). Measured agreement ~1e-10 relative."""
    f = jax.jit(position_mse)
    g = float(jax.jit(jax.grad(position_mse))(0.3))
    x, h = 0.3, 1e-4

    def central(h):
        return (float(f(x + h)) - float(f(x - h))) / (2 * h)

    d_h, d_2h = central(h), central(2 * h)
    assert abs(d_2h - d_h) / 3 < 1e-8 * abs(d_h)
    np.testing.assert_allclose(g, d_h, rtol=1e-6)
    assert g < 0

"""jax.grad through the blocked Monte Carlo harness (differentiable_monte_carlo), shared-covariance
path (KalmanFilter on a LinearGaussianModel): same statistics as monte_carlo, exact gradient of
Monte Carlo objectives against central differences with common random numbers.

The per-run covariance path (ExtendedKalmanFilter) is in test_mc_gradient_ekf.py and the memory
bound in test_mc_gradient_memory.py (split to keep each file's compilations under its time budget).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.filters import KalmanFilter
from jaxtrack.models import constant_velocity
from jaxtrack.montecarlo import differentiable_monte_carlo, monte_carlo

P0 = jnp.diag(jnp.array([100.0, 100.0, 25.0, 25.0]))
TRUTH = constant_velocity(1.0, accel_psd=1.0, measurement_std=10.0, initial_cov=P0)
KEY = jax.random.key(3)
NUM_RUNS, NUM_STEPS = 1100, 20  # 1100 = 4 full blocks of 256 + a padded one
FIELDS = ("mse", "mean_error", "nees", "nees_std", "nees_bounds", "nis", "nis_dof", "nis_bounds", "anees",
          "anees_bounds")


def filter_model(log_q):
    """The filter's CV model: wrong R (σ* = 20 m against the truth's 10 m) and q = exp(log_q)."""
    return constant_velocity(1.0, accel_psd=jnp.exp(log_q), measurement_std=20.0, initial_cov=P0)


def objectives(log_q, key=KEY):
    """[time-averaged position MSE (m²), NEES deviation (ANEES − 1)²] of the mismatched KF."""
    res = differentiable_monte_carlo(TRUTH, key, NUM_RUNS, num_steps=NUM_STEPS, filter=KalmanFilter(),
                                     filter_model=filter_model(log_q), block_size=256)
    return jnp.stack([jnp.mean(jnp.sum(res.mse[:, :2], axis=-1)), (res.anees - 1.0) ** 2])


@pytest.fixture(scope="module")
def compiled():
    x = jnp.asarray(0.3)
    return jax.jit(objectives).lower(x).compile(), jax.jit(jax.jacrev(objectives)).lower(x).compile()


def assert_same_result(a, b, rtol=1e-12):
    # atol 1e-15: a mean error near zero (8.7e-5 m from summands of ~0.1–1 m) differs by the
    # summation order at 1.6e-16 absolute, 1.8e-12 relative (seen with XLA's former CPU
    # emitters, tests/conftest.py).
    for f in FIELDS:
        np.testing.assert_allclose(np.asarray(getattr(b, f)), np.asarray(getattr(a, f)), rtol=rtol, atol=1e-15,
                                   err_msg=f)
    assert (a.num_runs, a.num_failed, a.shared_covariance) == (b.num_runs, b.num_failed, b.shared_covariance)
    np.testing.assert_array_equal(np.asarray(a.key), np.asarray(b.key))


def test_equals_monte_carlo_shared_path():
    """Same key and arguments → monte_carlo's MonteCarloResult to 1e-12 (the block size differs:
    256 here, 2048 there, so only the summation order of the runs differs)."""
    fm = filter_model(0.3)
    a = monte_carlo(TRUTH, KEY, NUM_RUNS, num_steps=NUM_STEPS, filter_model=fm, progress=False)
    b = differentiable_monte_carlo(TRUTH, KEY, NUM_RUNS, num_steps=NUM_STEPS, filter_model=fm, block_size=256)
    assert a.shared_covariance and b.shared_covariance
    assert_same_result(a, b)


def test_equals_monte_carlo_with_detections():
    """Per-run schedules (P_D = 0.8, per-run covariance path): NIS dof and bounds from the draws."""
    fm = filter_model(0.0)
    a = monte_carlo(TRUTH, KEY, 300, num_steps=NUM_STEPS, filter_model=fm, detection_probability=0.8,
                    progress=False)
    b = differentiable_monte_carlo(TRUTH, KEY, 300, num_steps=NUM_STEPS, filter_model=fm, detection_probability=0.8)
    assert not b.shared_covariance
    assert_same_result(a, b)


def test_gradient_matches_central_differences(compiled):
    """∂/∂log q of the time-averaged position MSE and of (ANEES − 1)², common random numbers.

    Central differences D(h) = (J(x+h) − J(x−h))/2h with the same key: truncation error
    h²J'''/6, round-off ~ ε|J|/h. h = 1e-4 (log q): J ~ 10², J' ~ 10, J''' ~ 10¹ → truncation
    ~ 2e-8 absolute (2e-9 relative), round-off ~ 2e-10 (2e-11 relative); both are checked below
    (D(2h) − D(h) = 3·truncation(h); D(h) − D(h/2) is dominated by round-off at this h).
    """
    forward, jac = compiled
    x = 0.3
    g = np.asarray(jac(jnp.asarray(x)))

    def central(h):
        return (np.asarray(forward(jnp.asarray(x + h))) - np.asarray(forward(jnp.asarray(x - h)))) / (2 * h)

    h = 1e-4
    d_h, d_2h = central(h), central(2 * h)
    truncation = np.abs(d_2h - d_h) / 3
    assert np.all(truncation < 1e-8 * np.abs(d_h)), (truncation, d_h)
    np.testing.assert_allclose(g, d_h, rtol=1e-6)
    # Measured (this file's problem): relative agreement ~1e-10 (MSE) and ~1e-9 (NEES deviation).
    assert np.all(np.abs(g) > 1e-3)  # a non-trivial gradient (the filter's q is wrong)


def test_gradient_depends_on_filter_parameter(compiled):
    """The MSE objective at log q = 0.3 decreases towards larger q (σ* too large → gain too low)."""
    forward, jac = compiled
    g = np.asarray(jac(jnp.asarray(0.3)))
    assert g[0] < 0


def test_truth_parameter_gradient():
    """The parameter may enter the truth (reparameterised draws x_k = F x_{k−1} + L_Q ε_k): ∂/∂log q_true
    of a fixed KF's time-averaged MSE against central differences (h = 1e-4, as above). A 1-D CV
    truth: its factors L_Q, L_R, L_P0 have distinct eigenvalues, so the draws are smooth in q and
    same-key central differences converge to the gradient (with repeated eigenvalues the gradient
    is the pathwise one with the basis held fixed: tests/test_psd_sqrt.py)."""
    fm = constant_velocity(1.0, dim=1, accel_psd=1.0, measurement_std=10.0,
                           initial_cov=jnp.diag(jnp.array([100.0, 25.0])))

    def mse(log_q):
        P = jnp.diag(jnp.array([100.0, 25.0]))
        truth = constant_velocity(1.0, dim=1, accel_psd=jnp.exp(log_q), measurement_std=10.0, initial_cov=P)
        res = differentiable_monte_carlo(truth, KEY, 200, num_steps=10, filter_model=fm)
        return jnp.mean(res.mse[:, 0])

    f = jax.jit(mse)
    g = float(jax.grad(mse)(0.5))
    h = 1e-4
    d = (float(f(0.5 + h)) - float(f(0.5 - h))) / (2 * h)
    assert g > 0  # more plant noise in the truth → larger error
    np.testing.assert_allclose(g, d, rtol=1e-6)


def test_input_errors():
    with pytest.raises(InputError, match="`block_size`"):
        differentiable_monte_carlo(TRUTH, KEY, 10, num_steps=5, block_size=0)
    with pytest.raises(InputError, match="`num_runs`"):
        differentiable_monte_carlo(TRUTH, KEY, 0, num_steps=5)
